"""Critical slope from trials, against an independent rigid wheel whose critical slope is Coleman's closed form."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rimless.analysis.inference.critical_slope import estimate_critical_slope, firth_logistic, group_slopes
from rimless.analysis.inference.sustained import StancePendulum, consecutive_periods, trial_verdict, trial_verdicts
from tests.support.analysis_rigid_truth import RigidTruth, duck_trial

TRUTH = RigidTruth()
SLOPES_DEG = (0.8, 1.0, 1.2, 1.4, 1.6, 1.8)  # straddle Coleman's 1.267 deg, not symmetric about it
RELEASES = (2.0, 3.0)  # rad/s: two release speeds


@pytest.fixture(scope="module")
def series():
    rng = np.random.default_rng(20261123)
    trials = [
        duck_trial(TRUTH, s, w, rng, name=f"rigid_{s}deg_{w}rad_s_{k}")
        for s in SLOPES_DEG
        for w in RELEASES
        for k in range(2)
    ]
    params = TRUTH.wheel_params()
    verdicts = trial_verdicts(trials, params)
    return trials, verdicts


def test_truth_model_is_what_it_claims():
    """The independent wheel: its critical slope from Coleman, and a walk at 3 deg settles where Coleman says."""
    crit = TRUTH.critical_slope_deg()
    assert 1.0 < crit < 1.5
    t, _x, _y, _a, imp, stalled = TRUTH.walk(3.0, 3.0, ramp_steps=40)
    assert not stalled
    # fixed-point period from the closed-form omega*: integrate d theta / omega(theta) by hand
    phi, b2 = math.radians(3.0), TRUTH.beta**2
    k = 2 * TRUTH.mass_kg * 9.81 * TRUTH.leg_m / TRUTH.inertia_foot
    gain = 2 * k * math.sin(phi) * math.sin(math.pi / 8)
    w2 = b2 * gain / (1 - b2)
    th = np.linspace(-math.pi / 8, math.pi / 8, 200001)
    om = np.sqrt(w2 + k * (math.cos(phi - math.pi / 8) - np.cos(th + phi)))
    period = float(np.trapezoid(1 / om, th))
    assert abs(np.diff(imp)[-1] - period) < 2e-4


def test_pendulum_relation_inverts_and_matches_quadrature():
    pend = StancePendulum.from_params(TRUTH.wheel_params(), math.radians(1.3))
    for e in (0.01, 0.3, 4.0):
        T = pend.period_s(e)
        th = np.linspace(-math.pi / 8, math.pi / 8, 400001) + math.radians(1.3)
        ref = float(np.trapezoid(1 / np.sqrt(e + pend.kappa_s2 * (1 - np.cos(th))), th))
        assert T == pytest.approx(ref, rel=1e-5)
        assert pend.energy(T) == pytest.approx(e, rel=1e-8)
    assert math.isnan(pend.energy(1e-3))  # faster than any walk


def test_estimate_within_0p1_deg_of_coleman(series):
    trials, verdicts = series
    res = estimate_critical_slope(verdicts, [t.meta.source_file for t in trials])
    truth = TRUTH.critical_slope_deg()
    assert res.chosen is not None
    assert abs(res.critical_slope_deg - truth) < 0.1, res.summary()["estimates"]
    lo, hi = res.bracket_deg
    assert lo < truth < hi
    assert res.chosen.ci_deg[0] - 0.02 < truth < res.chosen.ci_deg[1] + 0.02
    methods = {e.method for e in res.estimates}
    assert {"bracket", "logistic", "fixed-point-extrapolation"} <= methods
    s = res.summary()
    for key in ("critical_slope_deg", "bracket_deg", "ci_deg", "method", "per_trial", "model_critical_slope_deg"):
        assert key in s
    assert {"file", "slope_deg", "verdict", "steps", "reason"} <= set(s["per_trial"][0])


def test_below_critical_trial_that_walks_the_ramp_is_decaying(series):
    trials, verdicts = series
    truth = TRUTH.critical_slope_deg()
    walked_below = [
        (t, v) for t, v in zip(trials, verdicts) if t.meta.slope_deg < truth - 0.1 and t.meta.outcome == "walked"
    ]
    assert walked_below, "the series must hold a below-critical trial that reaches the end of the ramp"
    for t, v in walked_below:
        assert v.verdict == "decaying", (t.meta.source_file, v.reason)
    # and no verdict contradicts the truth
    for t, v in zip(trials, verdicts):
        if v.verdict == "sustained":
            assert t.meta.slope_deg > truth
        if v.verdict == "decaying":
            assert t.meta.slope_deg < truth


def test_few_steps_are_undetermined_not_guessed():
    pend = StancePendulum.from_params(TRUTH.wheel_params(), math.radians(1.6))
    from rimless.analysis.inference.sustained import verdict_from_periods

    v = verdict_from_periods([np.array([0.7, 0.72, 0.73])], pend, slope_deg=1.6)
    assert v.verdict == "undetermined" and "too few" in v.reason
    v = verdict_from_periods([np.array([0.7, 0.9])], pend, slope_deg=1.6, stalled=True)
    assert v.verdict == "decaying" and "stalled" in v.reason


def test_gap_breaks_the_chain():
    t = SimpleNamespace(
        impact_time_s=np.array([0.0, 0.5, 1.0, 2.0, 2.5, 3.0]), step_period_s=np.array([0.5, 0.5, 0.5, 0.5])
    )
    chains = consecutive_periods(t)
    assert [c.size for c in chains] == [2, 2]


def test_firth_logistic_is_finite_under_separation_and_grouping():
    x = np.array([1.0, 1.0, 1.2, 1.2, 1.4, 1.4, 1.6, 1.6])
    y = np.array([0, 0, 0, 0, 1, 1, 1, 1.0])
    beta, cov = firth_logistic(x - 1.3, y)
    assert np.all(np.isfinite(beta)) and beta[1] > 0
    assert -beta[0] / beta[1] == pytest.approx(0.0, abs=1e-9)  # data symmetric about 1.3: P = 0.5 exactly there
    g = group_slopes(np.array([1.0, 1.02, 1.5, 1.49]), 0.05)
    assert g[0] == g[1] == pytest.approx(1.01) and g[2] == g[3] == pytest.approx(1.495)


def test_all_sustained_gives_no_estimate_and_says_why():
    pend_params = TRUTH.wheel_params()
    rng = np.random.default_rng(1)
    trials = [duck_trial(TRUTH, 2.0, w, rng, name=f"a{w}") for w in (2.0, 2.5)]
    res = estimate_critical_slope([trial_verdict(t, pend_params) for t in trials], ["a", "b"])
    # every trial sustained, all at one slope: no bracket, no logistic, and no line of e* against the slope
    assert res.chosen is None and not res.estimates and res.bracket_deg is None
    assert "sustained" in res.why and "below" in res.why
