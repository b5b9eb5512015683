"""The calibration's output is numerically honest (issue 31, session 20): no interval below a parameter's bound,
no 0 that means "none" in the residual rows, a walk cache that stays within its bound, each slope pass's
held-exact probe named, and the carried parts' wording fitting each caller.

The audit case (4 light-legged trials, `--fit c --max-simulations 5000`) printed F_c's interval as
-1.864-3.783 N (value 0.9597 N, se 1.4 N, linearised across the c-F_c ridge), a trial whose simulated walk
stalled with "CoM 0.00 mm", and held about 2.4 GB: 257 recorded walks of 7-13 MB each (measured here, session 20).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rimless.analysis.inference import calibrate as cal
from rimless.analysis.inference.calibrate import CalibrationResult, ParamEstimate
from rimless.analysis.inference.held import _slope_ci, carry_bounded, carry_rows
from rimless.analysis.inference.walk_cache import WalkCache, walk_nbytes
from rimless.sim.model.params import WheelParams

Z95 = 1.959963984540054


def _audit_fc(**kw) -> ParamEstimate:
    """The audit's F_c: 0.9597 +- 1.4 N (1 sigma), not identifiable."""
    return ParamEstimate("guide_friction_n", "guide_friction_n", "N", 0.0, 0.9597, 1.4, False, **kw)


def test_the_audits_friction_interval_is_cut_at_zero_and_says_so() -> None:
    """By hand: 0.9597 - 1.96 * 1.4 = -1.7843 N < 0, so the interval is [0, 3.7037] N, flagged; the linearised
    one is kept under its own key."""
    e = _audit_fc()
    assert e.ci95_linear[0] == pytest.approx(0.9597 - Z95 * 1.4)
    assert e.ci95 == (0.0, pytest.approx(0.9597 + Z95 * 1.4))
    assert e.ci_at_bound
    d = e.as_dict()
    assert d["ci95"][0] == 0.0 and d["ci_at_bound"] is True and d["lower_bound"] == 0.0
    assert d["ci95_linear"][0] == pytest.approx(-1.7843, abs=1e-4)


def test_the_interval_with_the_held_parameters_is_cut_too() -> None:
    e = _audit_fc(se_held=0.5, held_shift=0.1)
    lo_lin = 0.9597 + 0.1 - Z95 * math.hypot(1.4, 0.5)
    assert e.ci95_with_held_linear[0] == pytest.approx(lo_lin) and lo_lin < 0
    assert e.ci95_with_held[0] == 0.0 and e.ci_with_held_at_bound
    d = e.as_dict()
    assert d["ci95_with_held"][0] == 0.0 and d["ci_with_held_at_bound"] is True
    assert d["ci95_with_held_linear"][0] == pytest.approx(lo_lin)


def test_an_interval_far_from_the_bound_is_untouched() -> None:
    e = ParamEstimate("c", "damping_ns_per_m", "N s/m", 8.0, 12.0, 1.0, True)
    assert e.ci95 == e.ci95_linear == (pytest.approx(12 - Z95), pytest.approx(12 + Z95))
    assert not e.ci_at_bound and not e.as_dict()["ci_at_bound"]


@settings(max_examples=200, deadline=None)
@given(
    value=st.floats(0.0, 1e4, allow_nan=False),
    se=st.floats(1e-9, 1e4, allow_nan=False),
    se_held=st.floats(0.0, 1e4, allow_nan=False),
    shift=st.floats(0.0, 1e3, allow_nan=False),
    name=st.sampled_from(sorted(cal.FIT_FIELDS)),
)
def test_no_interval_of_a_fitted_parameter_reaches_below_its_bound(value, se, se_held, shift, name) -> None:
    """Invariant: every fitted parameter is >= 0; neither interval, in the object or its JSON, goes below 0,
    and the upper ends are the linearised ones (a cut never narrows the interval from above)."""
    f, unit = cal.FIT_FIELDS[name]
    e = ParamEstimate(name, f, unit, 1.0, value, se, True, se_held=se_held, held_shift=shift)
    d = e.as_dict()
    for ci, lin in ((e.ci95, e.ci95_linear), (e.ci95_with_held, e.ci95_with_held_linear)):
        assert ci[0] >= 0.0 and ci[1] == lin[1] and ci[0] == max(lin[0], 0.0)
    assert d["ci95"][0] >= 0.0 and d["ci95_with_held"][0] >= 0.0
    assert d["ci_at_bound"] == (e.ci95_linear[0] < 0.0)


def _result(params: list[ParamEstimate], residuals: list[dict]) -> CalibrationResult:
    return CalibrationResult(params, np.eye(len(params)), {}, residuals, 1.0, 1e-3, WheelParams())


def _stalled_row() -> dict:
    d = cal._TrialData("series_slope3_release0.csv", 2.77, np.full(10, 0.4), np.linspace(0.02, 3.9, 50),
                       np.zeros(50), False)  # fmt: skip
    stalled = (1.3, math.nan, math.nan, 0)
    return cal._residual_rows([d], [stalled], [stalled], np.array([1.0]), np.array([1.0]), np.array([0.0]))[0]


def test_the_calibrate_printout_marks_the_cut_interval_and_the_missing_residuals(capsys) -> None:
    from rimless.analysis.cli.critical import _print_calibration

    c = ParamEstimate("c", "damping_ns_per_m", "N s/m", 8.0, 18.63, 7.0, False)
    out = _result([c, _audit_fc()], [_stalled_row()]).summary()
    _print_calibration(out)
    text = capsys.readouterr().out
    row = [ln for ln in text.splitlines() if ln.lstrip().startswith("guide_friction_n")][0]
    assert "0*-3.704" in row and "-1.7" not in row
    flat = " ".join(text.split())  # rich folds long lines
    assert (
        "guide_friction_n: its 95 % interval is cut at its bound, 0 N (the linearised interval reached -1.784" in flat
    )
    row = [ln for ln in text.splitlines() if ln.lstrip().startswith("series_slope3_release0 ")][0]
    assert "0.00" not in row and row.count("–") == 4
    assert (
        "series_slope3_release0: Table 1 and calibrated: the simulated walk stalled before the first of the 10" in flat
    )


def test_a_walk_that_stalls_has_no_com_error_not_a_zero() -> None:
    """A real walk released far too slowly (0.3 rad/s on 1 deg) stalls in its release step: no measured step
    is reached, so there is no simulated CoM curve; the RMS CoM error is NaN (JSON null) with its reason, where
    it was 0.00 mm."""
    d = cal._TrialData("slow.csv", 1.0, np.full(6, 0.45), np.linspace(0.02, 2.6, 40), np.full(40, 0.2), False)
    sim = cal._Sim("er", 1e-7, 8e-3)
    rows = cal._rms_rows(sim, [d], WheelParams(), np.array([0.3]), np.array([0.0]))
    assert rows[0][3] == 0 and math.isnan(rows[0][1]) and math.isnan(rows[0][2])
    res = cal._residual_rows([d], rows, rows, np.array([0.3]), np.array([0.3]), np.array([0.0]))[0]
    assert math.isnan(res["calibrated_rms_com_mm"]) and "stalled" in res["calibrated_note"]
    sig: dict[str, float] = {}
    cal._set_sigmas(sig, rows)
    assert "h" not in sig  # no CoM error to size the CoM block's sigma with


class _Walk:
    def __init__(self, rows: int, seg_rows: int = 0) -> None:
        self.table = {"t_s": np.zeros(rows), "com_height_normal_m": np.zeros(rows)}
        seg = SimpleNamespace(t=np.zeros(seg_rows), y=np.zeros((seg_rows, 10)))
        self.steps = [SimpleNamespace(segments=[seg] if seg_rows else None)]


def test_walk_nbytes_counts_the_table_the_segments_and_the_reserved_curve() -> None:
    assert walk_nbytes(_Walk(100)) == 100 * 16 + 100 * 25
    assert walk_nbytes(_Walk(100, 50)) == 100 * 16 + 100 * 25 + 50 * 8 * 11


@settings(max_examples=100, deadline=None)
@given(
    max_walks=st.integers(1, 8),
    max_kb=st.integers(1, 200),
    ops=st.lists(st.tuples(st.integers(0, 12), st.integers(0, 3000), st.booleans()), max_size=60),
)
def test_the_walk_cache_never_exceeds_its_bound(max_walks, max_kb, ops) -> None:
    """Invariant, whatever is stored and read: at most ``max_walks`` walks and ``max_bytes`` bytes, the byte
    count the sum of the kept walks', and the most recently stored or read walk kept (when it fits)."""
    cache = WalkCache(max_walks, max_kb * 1024)
    for key, rows, read in ops:
        if read:
            cache.get(key)
        else:
            w = _Walk(rows)
            cache.put(key, w)
            if walk_nbytes(w) <= cache.max_bytes:
                assert cache.get(key) is w
        assert len(cache) <= max_walks and cache.nbytes <= max_kb * 1024
        assert cache.nbytes == sum(size for _, size in cache._walks.values())


def test_the_walk_cache_drops_the_least_recently_used() -> None:
    cache = WalkCache(2, 10**9)
    a, b, c = _Walk(1), _Walk(1), _Walk(1)
    cache.put("a", a)
    cache.put("b", b)
    assert cache.get("a") is a  # a is now the most recently used
    cache.put("c", c)
    assert "b" not in cache and cache.get("a") is a and cache.get("c") is c


def test_the_calibrations_walks_are_cached_within_the_bound_without_their_segments() -> None:
    """`_Sim.walk` through a cache of 3 walks: 6 distinct walks keep the 3 last, none with its state segments
    (the table holds what the calibration reads); a repeated walk costs no simulation."""
    sim = cal._Sim("er", 1e-7, 8e-3, cache=WalkCache(3))
    p = WheelParams()
    for w in (1.6, 1.7, 1.8, 1.9, 2.0, 2.1):
        sim.walk(p, 2.0, w, 2, True)
        assert len(sim.cache) <= 3
    calls = sim.calls
    g = sim.walk(p, 2.0, 2.1, 2, True)
    assert sim.calls == calls and len(g.steps) == 2 and g.table["t_s"].size > 0
    assert all(s.segments is None for k in sim.cache._walks for s in sim.cache._walks[k][0].steps)


def test_carry_bounded_names_what_was_recomputed() -> None:
    """The calibration refits; a critical slope is recomputed (not "refitted")."""
    assert "one refit at +1 sd" in carry_bounded(0.0, 0.2, 1.0, None)[2]
    how = carry_bounded(0.0, 0.2, 1.0, None, evaluations=("recomputation of the critical slope", "x"))[2]
    assert "one recomputation of the critical slope at +1 sd" in how and "refit" not in how
    e = SimpleNamespace(value=0.0, sd=0.2)
    win = SimpleNamespace(entries={"guide_friction_n": e})
    rows = [{"name": "guide_friction_n", "plus_deg": 2.1, "minus_deg": None, "contribution_deg": 0.1, "note": ""}]
    carry_rows(rows, win, 2.0, "critical slope")
    assert "recomputation of the critical slope" in rows[0]["carried_as"] and "refit" not in rows[0]["carried_as"]
    rows = [{"name": "guide_friction_n", "plus_deg": 2.1, "minus_deg": 1.9, "contribution_deg": 0.1, "note": ""}]
    win.entries["guide_friction_n"] = SimpleNamespace(value=1.0, sd=0.2)
    carry_rows(rows, win, 2.0, "critical slope")
    assert "central recomputations of the critical slope at +-1 sd" in rows[0]["carried_as"]


def test_a_critical_slopes_interval_is_cut_at_zero() -> None:
    assert _slope_ci([-0.1, 0.5]) == {"ci_deg": [0.0, 0.5], "ci_linear_deg": [-0.1, 0.5], "ci_at_bound": True}
    assert _slope_ci([0.1, 0.5])["ci_deg"] == [0.1, 0.5] and not _slope_ci([0.1, 0.5])["ci_at_bound"]


def test_each_slope_pass_reports_its_own_held_exact_probe(monkeypatch) -> None:
    """Three passes (the slopes keep moving): each history row holds its own pass's probe; the result's probe is
    the kept (last) pass's, and says so."""
    from rimless.analysis.api import slope_passes as sp
    from rimless.sim import Wheel

    calls = []

    def fake_calibrate(loaded, names, fit, **kw):
        calls.append(len(calls) + 1)
        k = ParamEstimate("k", "stiffness_n_per_m", "N/m", 2700.0, 1900.0 + len(calls), 50.0, True)
        res = _result([k], [])
        res.held_exact_probe = {"guide_friction_n": {"call": len(calls)}}
        return res

    monkeypatch.setattr(cal, "calibrate", fake_calibrate)
    trial = lambda lo: SimpleNamespace(meta=SimpleNamespace(slope_deg=2.0, slope_ci_rad=(lo, 0.04)))  # noqa: E731
    moved = iter([0.02, 0.01, 0.0, -0.01])
    out = sp.calibrate_in_passes(
        [trial(0.03)], ["a"], ["k"], Wheel(), first_legs=None, reimport=lambda legs: [trial(next(moved))]
    )
    rows = [h for h in out.slope_passes["history"] if h["calibrated"]]
    assert [h["held_exact_probe"]["guide_friction_n"]["call"] for h in rows] == [1, 2, 3] == calls
    assert out.held_exact_probe["pass"] == 3 == out.slope_passes["held_exact_probe_pass"]
    assert out.held_exact_probe["guide_friction_n"]["call"] == 3


def test_a_stalled_trial_is_judged_on_its_periods_not_on_a_zero_com_residual() -> None:
    """The model adequacy of a trial whose simulated walk stalls (released at 0.3 rad/s, its truth at 2.0): its
    CoM chi^2/dof is none (no CoM curve), not the 0 of `_residuals`' placeholder, and its periods misfit."""
    from tests.support.analysis_sim_truth import sim_trial

    truth = WheelParams()
    trial = sim_trial(truth, 2.5, 2.0, np.random.default_rng(3), name="t", n_steps=8, noise_m=0.1e-3)
    data, _ = cal._usable([trial], ["t"])
    obj = cal._Objective(cal._Sim("er", 1e-7, 8e-3), cal._Globals.of(truth, ["c"]), data, lambda: None)
    u = np.concatenate([np.zeros(1), [0.3], [0.0]])
    row = cal._adequacy(obj, u, cal._slope_moved(obj, u))["per_trial"][0]
    assert row["com"]["ratio"] is None and row["com"]["chi2"] is None
    assert row["periods"]["ratio"] > 100 and not row["fits"]


def test_the_reports_calibration_line_shows_the_cut_interval() -> None:
    """The report's misfit section printed ``F_c = 0.9597 ± 2.7 N`` (reaching -1.78 N); now the cut interval."""
    from rimless.analysis.report.html import _misfit_html

    res = SimpleNamespace(calibration=SimpleNamespace(params=[_audit_fc()], residuals=[], converged=True))
    page = _misfit_html(res)
    assert "0.9597 (95 % interval 0-3.704, cut at its bound 0)" in page and "±" not in page.split("Calibrated")[1]


def test_the_critical_commands_held_lines_mark_a_cut_interval() -> None:
    from rimless.analysis.cli.critical import held_lines

    model = {"critical_slope_deg": 0.05, "contributions": [], "complete": True, **_slope_ci([-0.02, 0.12])}
    lines = held_lines({"parameter_uncertainty": {"method": "m", "trials": None, "models": {"er": model}}})
    line = next(ln for ln in lines if ln.startswith("model ER"))
    assert "95 % interval 0.000-0.120 deg" in line and "cut at 0 deg (the linearised interval reached -0.020" in line


def test_a_relative_uncertainty_just_over_the_limit_is_shown_over_it() -> None:
    """The not-identifiable note shows the digits that put the figure over the 50 % limit (an end-to-end run
    printed "relative uncertainty 50% > 50%")."""
    from rimless.analysis.inference.calibrate import NOT_IDENTIFIABLE_REL_SE, _over_limit

    for rel in (0.5004, 0.504, 0.52, 1.5):
        shown, limit = _over_limit(rel).split(" > ")
        assert limit == f"{NOT_IDENTIFIABLE_REL_SE:.0%}"
        assert float(shown.rstrip("%")) > NOT_IDENTIFIABLE_REL_SE * 100
        assert abs(float(shown.rstrip("%")) / 100 - rel) <= 0.005


def test_a_relative_uncertainty_of_a_value_near_zero_is_not_printed_in_billions() -> None:
    """F_c near 0 on a frictionless wheel printed "relative uncertainty 120522766522% > 50%" (session 21's audit):
    above 1000 % the note says "over 1000%", and an infinite ratio (value 0) reads the same."""
    from rimless.analysis.inference.calibrate import _over_limit

    for rel in (1.205e9, 10.0, math.inf):
        assert _over_limit(rel) == "over 1000% > 50%"
    assert _over_limit(9.99) == "999% > 50%"
