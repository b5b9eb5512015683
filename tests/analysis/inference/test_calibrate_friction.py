"""Calibration of guide friction beside damping (`--fit c,guide_friction_n`): the fit recovers a known friction
force from simulated, noisy trials of a wheel with friction, and says whether the trials told friction from
damping (a damper's loss per step grows with speed, Coulomb friction's does not).

Measured (4 trials at 2.5 and 3.0 deg, releases 2.0 and 2.6 rad/s, truth c = 8, F_c = 1 N): c = 7.74 +- 0.34,
F_c = 1.063 +- 0.076 N, correlation -0.998: a ridge, reported as not told apart (a combination is fixed; here
the linearised intervals happen to cover the truth because the fitted model is the truth model)."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.inference.calibrate import (
    RIDGE_CORRELATION,
    ParamEstimate,
    calibrate,
    friction_vs_damping,
    parse_fit,
)
from tests.support.analysis_sim_truth import sim_trial

C_TRUE = 8.0  # N s/m
F_TRUE = 1.0  # N


def _est(name: str, ident: bool) -> ParamEstimate:
    return ParamEstimate(name, name, "", 0.0, 1.0, 0.1, ident)


def test_friction_is_a_fit_name():
    assert parse_fit("c,guide_friction_n") == ["c", "guide_friction_n"]


@pytest.mark.parametrize(
    "rho, ident, told",
    [
        (0.3, (True, True), True),
        (0.99, (True, True), False),
        (-0.97, (False, True), False),
        (0.3, (True, False), False),
    ],
)
def test_the_statement_follows_identifiability_and_the_ridge(rho, ident, told):
    est = [_est("c", ident[0]), _est("guide_friction_n", ident[1])]
    out = friction_vs_damping(est, np.array([[1.0, rho], [rho, 1.0]]), [1.9, 2.2])
    assert out["told_apart"] is told and out["correlation"] == rho
    assert out["statement"].startswith("yes" if told else "no")
    assert out["ridge"] is (abs(rho) > RIDGE_CORRELATION)
    assert ("ridge" in out["statement"]) is out["ridge"]
    assert out["release_speed_ratio"] == pytest.approx(2.2 / 1.9)
    assert friction_vs_damping([_est("c", True)], np.eye(1), [2.0]) is None  # only when both are fitted


@pytest.mark.slow
def test_recovers_friction_and_damping_from_trials_at_different_speeds():
    from rimless.sim.model.params import WheelParams

    truth = WheelParams(damping_ns_per_m=C_TRUE, guide_friction_n=F_TRUE)
    rng = np.random.default_rng(5)
    trials = [sim_trial(truth, s, w, rng, name=f"sim_{s}deg_{w}") for s in (2.5, 3.0) for w in (2.0, 2.6)]
    res = calibrate(
        trials,
        [t.meta.source_file for t in trials],
        ["c", "guide_friction_n"],
        params=WheelParams(guide_friction_n=0.5),
    )
    c, f = res.params
    s = res.summary()
    fvd = s["friction_vs_damping"]
    assert fvd["correlation"] == pytest.approx(s["correlation"]["matrix"][0][1])
    # each estimate's 95 % interval covers its truth
    assert abs(f.value - F_TRUE) <= 1.96 * f.se, (f.value, f.se)
    assert abs(c.value - C_TRUE) <= 1.96 * c.se, (c.value, c.se)
    assert fvd["ridge"] == (abs(fvd["correlation"]) > RIDGE_CORRELATION)
    assert fvd["told_apart"] == (c.identifiable and f.identifiable and not fvd["ridge"])
