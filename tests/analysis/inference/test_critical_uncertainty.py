"""The critical slope's interval: each trial's slope uncertainty and the spread between trials, and its coverage.

Truths: Coleman's closed form for a rigid wheel (tests/support/analysis_rigid_truth.py, written apart from
rimless.analysis), and scipy's adaptive quadrature for the coverage model's stance time.
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import quad
from typer.testing import CliRunner

from rimless.analysis.inference.critical_slope import estimate_critical_slope
from rimless.analysis.inference.sustained import trial_slope_sigma_deg, trial_verdicts
from rimless.analysis.validation.coverage import RigidFrictionWheel, run_coverage, synthetic_series
from tests.support.analysis_rigid_truth import RigidTruth, duck_trial

TRUTH = RigidTruth()


def test_slope_sigma_from_interval_source_or_default():
    lo, hi = math.radians(1.0), math.radians(1.4)
    s, why = trial_slope_sigma_deg(SimpleNamespace(slope_ci_rad=(lo, hi), slope_source="estimated"))
    assert s == pytest.approx(0.4 / (2 * 1.959963984540054)) and why == "slope_ci_rad"
    s_given, _ = trial_slope_sigma_deg(SimpleNamespace(slope_ci_rad=None, slope_source="given"))
    s_est, _ = trial_slope_sigma_deg(SimpleNamespace(slope_source="estimated"))
    s_none, why = trial_slope_sigma_deg(SimpleNamespace())
    assert 0 < s_given < s_est and s_none > 0 and "default" in why
    assert trial_slope_sigma_deg(SimpleNamespace(slope_ci_rad=(math.nan, 1.0)))[1] != "slope_ci_rad"


def test_coverage_model_matches_coleman_and_quadrature():
    """Without the friction loss the coverage model is the rigid wheel: Coleman's critical slope."""
    w = RigidFrictionWheel(inertia_hub_kg_m2=TRUTH.inertia_hub_kg_m2, mass_kg=TRUTH.mass_kg, leg_m=TRUTH.leg_m)
    assert w.critical_slope_deg() == pytest.approx(TRUTH.critical_slope_deg(), abs=1e-6)
    lossy = dataclasses.replace(w, loss_rad2_s2=0.2)
    assert lossy.critical_slope_deg() > w.critical_slope_deg() + 0.1  # friction needs a steeper slope
    phi = math.radians(1.5)
    for W in (2.2, 4.0, 9.0):
        assert w.top_margin(W, phi) > 0
        ref = quad(
            lambda th: 1 / math.sqrt(W + 2 * w.k * (math.cos(phi - math.pi / 8) - math.cos(th + phi))),  # noqa: B023
            -math.pi / 8,
            math.pi / 8,
            points=[-phi],
            limit=200,
            epsabs=1e-13,
        )[0]
        assert w.period_s(W, phi) == pytest.approx(ref, rel=1e-9)


@pytest.fixture(scope="module")
def rigid_series():
    rng = np.random.default_rng(20261124)
    trials = [
        duck_trial(TRUTH, s, w, rng, name=f"rigid_{s}deg_{w}_{k}")
        for s in (0.9, 1.1, 1.3, 1.5, 1.7)
        for w in (2.0, 3.0)
        for k in range(2)
    ]
    return trials, trial_verdicts(trials, TRUTH.wheel_params())


def test_interval_covers_coleman_and_says_which_estimate(rigid_series):
    trials, verdicts = rigid_series
    res = estimate_critical_slope(verdicts, [t.meta.source_file for t in trials])
    truth = TRUTH.critical_slope_deg()
    assert res.chosen is not None and res.why
    assert res.chosen.ci_deg[0] <= truth <= res.chosen.ci_deg[1], (truth, res.summary()["estimates"])
    s = res.summary()
    assert s["method"] in ("bracket", "logistic", "fixed-point-extrapolation")
    for e in s["estimates"]:
        assert {"ci_closed_form_deg", "ci_bootstrap_deg"} <= set(e)
    row = s["per_trial"][0]
    assert row["slope_sigma_deg"] > 0 and row["slope_ci_deg"][0] < row["slope_deg"] < row["slope_ci_deg"][1]


def test_slope_uncertainty_widens_every_interval(rigid_series):
    trials, verdicts = rigid_series
    tight = [dataclasses.replace(v, slope_sigma_deg=0.0) for v in verdicts]
    loose = [dataclasses.replace(v, slope_sigma_deg=0.15) for v in verdicts]
    names = [t.meta.source_file for t in trials]
    a = {e.method: e for e in estimate_critical_slope(tight, names).estimates}
    b = {e.method: e for e in estimate_critical_slope(loose, names).estimates}
    for m in a:
        wa, wb = a[m].ci_deg[1] - a[m].ci_deg[0], b[m].ci_deg[1] - b[m].ci_deg[0]
        assert wb > wa, m
    # seeded bootstrap: the same inputs give the same interval
    again = {e.method: e for e in estimate_critical_slope(loose, names).estimates}
    assert all(again[m].ci_deg == b[m].ci_deg for m in b)


def test_synthetic_series_states_its_slope_uncertainty():
    wheel, crit, trials = synthetic_series(np.random.default_rng(5))
    assert crit == pytest.approx(wheel.critical_slope_deg())
    slopes = [t.meta.true_slope_deg for t in trials]
    assert min(slopes) < crit < max(slopes)
    for t in trials:
        lo, hi = t.meta.slope_ci_rad
        assert lo < math.radians(t.meta.slope_deg) < hi
        assert t.meta.outcome in ("stalled", "walked")
        if t.meta.outcome == "walked":
            assert t.meta.true_slope_deg > crit or t.step_period_s.size >= 8


def test_coverage_run_reports_its_figures():
    res = run_coverage(4, seed=11, n_boot=50)
    s = res.summary()
    assert s["series"] == 4 and s["estimated"] <= 4
    assert 0.0 <= s["coverage"] <= 1.0 and s["coverage_ci95"][0] <= s["coverage"] <= s["coverage_ci95"][1]
    for o in res.outcomes:  # every estimate lands near its own truth (errors are hundredths of a degree)
        assert abs(o.estimate_deg - o.truth_deg) < 0.2


def test_coverage_command_json():
    from rimless.cli import app

    r = CliRunner().invoke(app, ["trials", "coverage", "--truth", "pendulum", "--series", "2", "--seed", "3", "--json"])
    assert r.exit_code == 0, r.output
    import json

    out = json.loads(r.stdout)
    for key in ("series", "coverage", "coverage_ci95", "median_abs_error_deg", "median_error_deg", "per_method"):
        assert key in out
    r = CliRunner().invoke(app, ["trials", "coverage", "--series", "0"])
    assert r.exit_code == 2 and "--series" in r.output


@pytest.mark.parametrize("shared", [False, True], ids=["own-fit", "pooled-slope"])
def test_fixed_point_se_matches_its_error_against_the_lossy_truth(shared):
    """A trial's fixed point e* against the independent lossy rigid truth (`critical_truth`: its own step map
    gives e* = w* - the stance's top threshold), over replicates of one walk whose impact times carry a known
    noise: e*'s standard error must be its error's size (consecutive periods share an impact, so their
    energies' errors are correlated; treating them as independent made it 2-3 times too wide: rms z 0.38 and 0.51
    before). The scale is never deflated by a small residual scatter (only inflated by a large one), so the
    interval may hold a little more than 95 % (98.7 and 99 % here)."""
    from rimless.analysis.inference.sustained import StancePendulum, verdict_from_periods
    from rimless.analysis.validation.critical_truth import LossyWheel, walk

    wheel = LossyWheel(mass_kg=2.2, inertia_hub_kg_m2=0.9 * 2.2 * 0.23**2, leg_m=0.23, friction_n=0.3)
    slope_deg = wheel.critical_slope_deg() + 0.3
    phi = math.radians(slope_deg)
    e_true = wheel.fixed_point_w(phi) - wheel.top_threshold(phi)
    release = 1.8 * math.sqrt(wheel.top_threshold(phi))
    impacts = walk(wheel, slope_deg, release, 11).impacts
    pend = StancePendulum.from_params(wheel.wheel_params(), phi)
    sig_impact = 1e-3  # s, per impact time (a tenth of a frame at 100 Hz)
    a_true = wheel.beta**2
    rng = np.random.default_rng(3)
    z = []
    for _ in range(300):
        periods = np.diff(impacts + rng.normal(0.0, sig_impact, impacts.size))
        v = verdict_from_periods(
            [periods],
            pend,
            slope_deg=slope_deg,
            timing_sigma_s=math.sqrt(2.0) * sig_impact,
            shared_slope=(a_true, 1e-4) if shared else None,
        )
        z.append((v.fixed_point - e_true) / v.fixed_point_se)
    z_arr = np.array(z)
    rms = float(np.sqrt(np.mean(z_arr**2)))
    covered = float(np.mean(np.abs(z_arr) <= 1.96))
    assert 0.75 < rms < 1.3, rms
    assert 0.9 <= covered <= 0.995, covered


def test_extrapolation_half_width_parts_match_their_monte_carlo_spread():
    """The root's standard error split by source (`line_root_parts`): each part must be the spread of the root
    when only that source is redrawn (an independent Monte Carlo of a known line, e* = 1.6 (x - 2.0)), and the
    parts add in quadrature to the fit's own standard error when the points scatter as stated."""
    from rimless.analysis.inference.critical_slope import _line_root, line_root_parts

    x0 = np.array([1.7, 1.8, 1.9, 2.1, 2.2, 2.3, 2.4, 2.5])
    y0 = 1.6 * (x0 - 2.0)
    se = np.array([0.02, 0.03, 0.015, 0.02, 0.04, 0.02, 0.03, 0.025])  # e*, rad^2/s^2
    sx = np.array([0.01, 0.02, 0.015, 0.005, 0.01, 0.02, 0.01, 0.015])  # slope, deg
    root, se_root, c0, c1, _ = _line_root(x0, y0, se, sx)
    parts = line_root_parts(x0, y0, se, sx, c0, c1, se_root)
    assert root == pytest.approx(2.0) and parts["scatter"] == pytest.approx(1.0)
    assert math.hypot(parts["fixed_points"], parts["slopes"]) == pytest.approx(se_root, rel=1e-9)
    rng = np.random.default_rng(11)
    only_fp, only_sx = [], []
    for _ in range(3000):
        r = _line_root(x0, y0 + rng.normal(0.0, se), se, sx)
        only_fp.append(r[0] if r else math.nan)
        xs = x0 + rng.normal(0.0, sx)  # the slope is measured off, the fixed point is the walk's own
        r = _line_root(xs, y0, se, sx)
        only_sx.append(r[0] if r else math.nan)
    assert np.std(only_fp) == pytest.approx(parts["fixed_points"], rel=0.08)
    assert np.std(only_sx) == pytest.approx(parts["slopes"], rel=0.08)


def test_reported_extrapolation_states_its_half_width_parts(rigid_series):
    """On the rigid truth's series the reported extrapolation carries its parts (JSON ``se_parts_deg``), and
    1.96 x their quadrature sum x the scatter factor is its interval's half width."""
    trials, verdicts = rigid_series
    res = estimate_critical_slope(verdicts, [t.meta.source_file for t in trials], n_boot=0)
    ex = next(e for e in res.estimates if e.method == "fixed-point-extrapolation")
    parts = ex.as_dict()["se_parts_deg"]
    assert parts["scatter"] >= 1.0 and parts["fixed_points"] > 0 and parts["slopes"] > 0
    half = 0.5 * (ex.ci_deg[1] - ex.ci_deg[0])
    assert 1.959963984540054 * math.hypot(parts["fixed_points"], parts["slopes"]) * parts["scatter"] == pytest.approx(
        half, rel=1e-9
    )


def test_fixed_point_se_follows_the_timing_noise_the_trials_show():
    """Six walks of the independent lossy rigid truth (`critical_truth`) whose impact times carry 0.3 ms of
    noise at 100 Hz, a third of the tenth of a frame assumed: each trial's e* against the truth's own fixed point
    (its step map's w* less the stance's top threshold) must have a standard error its error's size (rms z
    0.7-1.3). With the assumed noise alone (never lowered by the trials' scatter) it was three times too wide
    (rms z about 0.3), as on the imported walks of ``rimless trials coverage`` (0.29-0.37 on eight series)."""
    from rimless.analysis.inference.sustained import pooled_timing_scale, trial_verdict
    from rimless.analysis.validation.critical_truth import LossyWheel, walk

    wheel = LossyWheel(mass_kg=2.4, inertia_hub_kg_m2=1.2 * 2.4 * 0.24**2, leg_m=0.24, friction_n=0.2)
    crit = wheel.critical_slope_deg()
    slopes = [crit + d for d in (0.2, 0.35, 0.5)]
    walks = []
    for s in slopes:
        phi = math.radians(s)
        top = math.sqrt(wheel.top_threshold(phi))
        for f in (1.3, 2.0):
            walks.append((s, walk(wheel, s, f * top, 10).impacts, wheel.fixed_point_w(phi) - wheel.top_threshold(phi)))
    params = wheel.wheel_params()
    rng = np.random.default_rng(5)
    z, scales = [], []
    for _ in range(25):
        trials = []
        for k, (s, imp, _e) in enumerate(walks):
            noisy = imp + rng.normal(0.0, 3e-4, imp.size)
            meta = SimpleNamespace(
                slope_deg=s, source_file=f"w{k}", rate_hz=100.0, outcome="walked", slope_source="given"
            )
            trials.append(
                SimpleNamespace(
                    time_s=np.arange(0.0, noisy[-1] + 0.3, 0.01),
                    impact_time_s=noisy,
                    step_period_s=np.diff(noisy),
                    meta=meta,
                    series={},
                )
            )
        verdicts = trial_verdicts(trials, params)
        scales.append(pooled_timing_scale([trial_verdict(t, params) for t in trials]))  # at the assumed noise
        for v, (_s, _imp, e_true) in zip(verdicts, walks, strict=True):
            assert v.verdict == "sustained", v.reason
            z.append((v.fixed_point - e_true) / v.fixed_point_se)
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 < rms < 1.3, (rms, np.median(scales))
    assert 0.15 < float(np.median(scales)) < 0.6  # about 0.3 ms of the 1 ms assumed per impact


def test_pooled_timing_scale_only_lowers_and_needs_enough_pairs():
    """By hand: r'r 0.25 of its expectation over 30 degrees of freedom gives sqrt(0.25) = 0.5; a scatter larger
    than the assumed noise never raises it (1: each fit inflates its own); fewer than 20 pooled degrees of
    freedom leave the assumed noise (1)."""
    from rimless.analysis.inference.sustained import Verdict, pooled_timing_scale

    def v(rr: float, expected: float, dof: int) -> Verdict:
        out = Verdict("sustained", "", dof + 3, 2.0)
        out.timing_scatter = (rr, expected, dof)
        return out

    assert pooled_timing_scale([v(0.1, 0.5, 15), v(0.15, 0.5, 15)]) == pytest.approx(0.5)
    assert pooled_timing_scale([v(2.0, 0.5, 15), v(0.1, 0.5, 15)]) == 1.0
    assert pooled_timing_scale([v(0.1, 0.5, 9), v(0.1, 0.5, 9)]) == 1.0
    assert pooled_timing_scale([v(0.0, 0.0, 0)]) == 1.0
