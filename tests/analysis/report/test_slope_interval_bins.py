"""Step periods binned by the slopes' own intervals (`slope_bin_deg=None`, `rimless demo`'s default): within a
series, trials are pooled only while their 95 % slope intervals share a common slope, so the pooled-slope warning
(kept for reports binned by a width) has nothing to say. Hand-made comparisons, bins worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.inference.compare import Simulator, TrialComparison
from rimless.analysis.report.series import (
    interval_bins,
    pooled_slope_warnings,
    release_condition,
    series_name,
    series_trends,
    slope_bin_words,
)


def _tc(name: str, slope: float, periods: list[float]) -> TrialComparison:
    p = np.asarray(periods)
    return TrialComparison(
        name, name, slope, "estimated", "er", "ok", measured_period_s=p, sim_period_s=p + 0.01,
        release_theta_dot_rad_s=2.0,
    )  # fmt: skip


#: a at 1.30 [1.20, 1.45], b at 1.40 [1.35, 1.50], c at 1.42 given (no interval), d at 1.60 [1.55, 1.65]:
#: a, b and c share [1.42, 1.42]; d's interval starts above a's end. Rounded to 0.5 deg, all four are bin 1.5.
SLOPES = {"a": (1.30, (1.20, 1.45)), "b": (1.40, (1.35, 1.50)), "c": (1.42, None), "d": (1.60, (1.55, 1.65))}
COMPS = [_tc("d", 1.60, [0.50, 0.48]), _tc("a", 1.30, [0.70]), _tc("b", 1.40, [0.60, 0.58]), _tc("c", 1.42, [0.62])]


@pytest.fixture(scope="module")
def sim():
    return Simulator()


def test_interval_bins_pool_only_trials_whose_intervals_share_a_slope():
    assert [[c.name for c in b] for b in interval_bins(COMPS, SLOPES)] == [["a", "b", "c"], ["d"]]
    # a trial given outside the others' common part starts its own bin; no steps or no slope: left out
    extra = [*COMPS, _tc("e", 1.48, [0.6]), _tc("f", 1.40, []), _tc("g", float("nan"), [0.6])]
    slopes = SLOPES | {"e": (1.48, None)}
    assert [[c.name for c in b] for b in interval_bins(extra, slopes)] == [["a", "b", "c"], ["e"], ["d"]]


def test_series_trends_by_intervals_bin_at_their_mean_slope_and_raise_no_warning(sim):
    series = ["s"] * len(COMPS)
    by_width = series_trends(COMPS, series, sim, slope_bin_deg=0.5)
    assert [g.slope_deg for g in by_width] == [1.5]  # all four rounded together
    assert len(pooled_slope_warnings(by_width, SLOPES, 0.5)) == 1  # a and d differ beyond their intervals

    groups = series_trends(COMPS, series, sim, slope_bin_deg=None, slopes=SLOPES)
    assert [(g.series, g.slope_deg, sorted(g.trials)) for g in groups] == [
        ("s", round((1.30 + 1.40 + 1.42) / 3, 3), ["a", "b", "c"]),
        ("s", 1.60, ["d"]),
    ]
    np.testing.assert_allclose(groups[0].mean_period_s, [(0.70 + 0.60 + 0.62) / 3, 0.58])
    np.testing.assert_allclose(groups[0].sim_period_s, [(0.70 + 0.60 + 0.62) / 3 + 0.01, 0.59])
    assert list(groups[0].count) == [3, 1]
    assert pooled_slope_warnings(groups, SLOPES, None) == []
    assert "overlap" in slope_bin_words(None) and slope_bin_words(0.25) == "slopes rounded to 0.25 deg"


def test_two_series_at_the_same_slopes_stay_two_groups(sim):
    groups = series_trends(COMPS, ["s", "s", "t", "t"], sim, slope_bin_deg=None, slopes=SLOPES)
    assert [(g.series, sorted(g.trials)) for g in groups] == [("s", ["a"]), ("s", ["d"]), ("t", ["b", "c"])]


def test_trials_of_two_release_conditions_are_never_pooled(sim):
    """The bundled critical series' naming (``..._slope1.60deg_release1.9`` and ``..._release2.5``): one series, but
    a bin per release condition, with width bins and interval bins alike; runs of one condition are still pooled.
    On main both releases at one slope shared a bin: mean of 0.80 and 0.50 s, std 0.21 s (by hand)."""
    names = ["w_slope1.60deg_release1.9.csv", "w_slope1.60deg_release2.5.csv", "w_slope1.60deg_release2.5_run2.csv"]
    comps = [_tc(n, 1.60, p) for n, p in zip(names, ([0.80, 0.78], [0.50, 0.49], [0.52, 0.50]))]
    slopes = {n: (1.60, (1.55, 1.65)) for n in names}
    series = ["w"] * 3
    for bin_deg in (0.5, None):
        groups = series_trends(comps, series, sim, slope_bin_deg=bin_deg, slopes=slopes)
        assert [(g.series, g.release, sorted(g.trials)) for g in groups] == [
            ("w", "release1.9", [names[0]]),
            ("w", "release2.5", sorted(names[1:])),
        ]
        np.testing.assert_allclose(groups[1].mean_period_s, [0.51, 0.495])  # the two 2.5 rad/s runs, by hand
        assert all(r["release"] == g.release for g in groups for r in g.rows())
    assert release_condition("a/w_slope1.6deg_Release2.5_run1.csv") == "Release2.5"
    assert release_condition("w_slope1.6deg_run1.csv") == "" and series_name(names[0]) == "w"


def test_an_interval_bin_is_named_by_its_trials_slopes_not_a_mean_outside_a_members_interval(sim):
    """The demo's ``release1.9`` panel (session 21, noticed): a bin of 1.344, 1.356 and 1.596 deg trials labelled
    1.432 deg, outside the 1.596 trial's own interval. Here a, b, c share only the slope 1.42 (c given exactly): their
    mean 1.373 lies outside c's interval, so the bin is named by the range of its trials' slopes, 1.300-1.420 (by
    hand), which holds each trial's own slope; a bin of one trial by that slope. The mean stays ``slope_deg``."""
    from rimless.analysis.report.sections import periods_html

    groups = series_trends(COMPS, ["s"] * len(COMPS), sim, slope_bin_deg=None, slopes=SLOPES)
    mean = round((1.30 + 1.40 + 1.42) / 3, 3)
    assert not SLOPES["c"][0] - 1e-9 <= mean <= SLOPES["c"][0] + 1e-9  # the old label is outside c's interval
    assert [(g.slope_deg, g.slope_label, g.slope_range_deg) for g in groups] == [
        (mean, "1.300-1.420", (1.30, 1.42)),
        (1.60, "1.600", (1.60, 1.60)),
    ]
    rows = groups[0].rows()
    assert {(r["slope_bin_label_deg"], r["slope_min_deg"], r["slope_max_deg"], r["slope_deg"]) for r in rows} == {
        ("1.300-1.420", 1.30, 1.42, mean)
    }
    page = periods_html(groups, None)
    assert '<td class="n">1.300-1.420</td>' in page and f">{mean:g}<" not in page
    # bins of a width keep their rounded centre as their name (the rounding is stated in the heading)
    (wide,) = series_trends(COMPS, ["s"] * len(COMPS), sim, slope_bin_deg=0.5)
    assert wide.slope_label == "1.5" and wide.slope_range_deg == (1.30, 1.60)


def _legend_labels(figures, monkeypatch) -> list[str]:
    """The legend texts of every figure the report saves from now on (``figures.save_png`` spied on)."""
    labels: list[str] = []
    real = figures.save_png

    def spy(fig, path):
        labels.extend(t.get_text() for ax in fig.axes for t in (ax.get_legend().get_texts() if ax.get_legend() else []))
        return real(fig, path)

    monkeypatch.setattr(figures, "save_png", spy)
    return labels


def test_the_period_figure_legend_names_the_bin_by_its_range(sim, tmp_path, monkeypatch):
    from rimless.analysis.report import figures

    labels = _legend_labels(figures, monkeypatch)
    groups = series_trends(COMPS, ["s"] * len(COMPS), sim, slope_bin_deg=None, slopes=SLOPES)
    figures.period_figure(groups, tmp_path / "p.png")
    assert labels == ["measured 1.300-1.420 deg (n = 3)", "measured 1.600 deg (n = 1)"]


def test_trials_that_ended_differently_are_never_pooled(sim, tmp_path, monkeypatch):
    """The demo's ``release1.9`` panel (session 22, noticed): two trials that stalled after two steps and one that
    walked on, in one interval bin; after step 2 only the walker was drawn and the bin's std at steps 1-2 was the
    gap between a stall and a walk. Given the trials' outcomes, each outcome is binned on its own and named in the
    rows, the table and the legend; without them (None) the bins are as before (the tests above)."""
    from rimless.analysis.report import figures
    from rimless.analysis.report.sections import periods_html

    names = ["w_slope1.34deg_release1.9.csv", "w_slope1.36deg_release1.9.csv", "w_slope1.40deg_release1.9.csv"]
    periods = ([0.80, 0.90], [0.82, 0.93], [0.60, 0.58, 0.57, 0.57])
    comps = [_tc(n, s, p) for n, s, p in zip(names, (1.34, 1.36, 1.40), periods)]
    slopes = {n: (s, (1.30, 1.45)) for n, s in zip(names, (1.34, 1.36, 1.40))}  # one common slope: one bin
    series = ["w"] * 3
    (pooled,) = series_trends(comps, series, sim, slope_bin_deg=None, slopes=slopes)
    assert list(pooled.count) == [3, 3, 1, 1]  # what main drew: steps 3-4 the walker alone
    for bin_deg in (0.5, None):
        groups = series_trends(
            comps, series, sim, slope_bin_deg=bin_deg, slopes=slopes, outcomes=["stalled", "stalled", "walked"]
        )
        assert [(g.release, g.outcome, sorted(g.trials)) for g in groups] == [
            ("release1.9", "stalled", names[:2]),
            ("release1.9", "walked", names[2:]),
        ]
        np.testing.assert_allclose(groups[0].mean_period_s, [0.81, 0.915])  # the two stalls, by hand
        np.testing.assert_allclose(groups[1].mean_period_s, periods[2])
        assert {r["outcome"] for r in groups[0].rows()} == {"stalled"}
    page = periods_html(groups, None)
    assert "<th>ended</th>" in page and page.count("<td>stalled</td>") == 2 and page.count("<td>walked</td>") == 4
    labels = _legend_labels(figures, monkeypatch)
    figures.period_figure(groups, tmp_path / "p.png")
    assert labels == ["measured 1.340-1.360 deg, stalled (n = 2)", "measured 1.400 deg, walked (n = 1)"]
    with pytest.raises(ValueError, match="2 outcomes for 3"):
        series_trends(comps, series, sim, outcomes=["walked", "walked"])
