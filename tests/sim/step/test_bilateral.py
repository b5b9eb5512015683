"""Gaits that violate unilateral contact are found (the stance foot held: the compiled map's bilateral mode) and
listed as contact-invalid with the reason and the size of the violation; the default map is unchanged.

Independent expectations: the unilateral map itself rejects the invalid gait (its located lift-off guard);
the bilateral step equals the unilateral one bit for bit where the stance force stays positive; the recorded
and reported minima agree with the reference path's forces sampled every 0.1 ms along the same step with the
stance foot held (scipy DOP853, `HeldStance`); the force's zero in k lies where the reference path puts it
(positive at k = 2500, negative at k = 2551.4: tests.support.sim_dip). For scale (VE fast gait, Table 1):
about +0.47 N at k = 2500 and -1.38 N at k = 2700."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.cli import app
from rimless.sim.fast import fast_step
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.fast_map import FastPoincareMap, HeldStance
from rimless.sim.step.hybrid import simulate_step
from tests.support.sim_dip import DIP_PARAMS

FAST_2500 = np.array([-0.45035523, 3.17963352])  # the VE fast gait at k = 2500 (what `gaits` lists)


SAMPLED_MIN_TOL_N = 2e-3  # a minimum of a force sampled every 0.1 ms against the located one


def _reference_min_stance_force(k: float, z: np.ndarray) -> float:
    """The smallest single-support stance normal force (N) of the VE step from z with the stance foot held,
    on the reference path (scipy DOP853, Python right-hand side), sampled every 0.1 ms."""
    p = WheelParams().replace(stiffness_n_per_m=k)
    mech = Mechanics.of(p)
    held = HeldStance(ScipyIntegrator(rtol=1e-10, atol=1e-12))
    step = simulate_step(mech, "ve", state_from_section(mech, z), held, diagnostics=True, record_dt=1e-4)
    return step.diagnostics["min_normal_force_b_slsp_free_N"]


def _gaits(k):
    res = CliRunner().invoke(app, ["sim", "gaits", "--model", "ve", "--k", str(k), "--guesses", "8", "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)["gaits"]


def test_where_the_foot_stays_down_bilateral_is_the_unilateral_step_bit_for_bit():
    p = WheelParams().replace(stiffness_n_per_m=2500.0)
    uni = fast_step(p, "ve", FAST_2500, jacobian=True)
    bil = fast_step(p, "ve", FAST_2500, jacobian=True, bilateral=True)
    assert np.array_equal(uni.z_next, bil.z_next) and uni.period_s == bil.period_s
    assert np.array_equal(uni.jacobian, bil.jacobian)
    assert uni.contact is None
    c = bil.contact
    # the recorded minimum against the reference path's samples of the same step (every 0.1 ms)
    ref = _reference_min_stance_force(2500.0, FAST_2500)
    assert ref > 0.0
    assert c.min_stance_force_N == pytest.approx(ref, abs=SAMPLED_MIN_TOL_N) and c.negative_force_s == 0.0
    assert uni.phase_end_s[0] < c.min_stance_force_time_s < uni.phase_end_s[2]  # in single support
    assert c.min_impulse_N_s > 0


def test_k2700_fast_gait_is_listed_invalid_with_its_lift_off_and_k2500_valid():
    g2700 = _gaits(2700)
    fast = [g for g in g2700 if abs(g["step_period_s"] - 0.25) < 0.01]
    assert len(fast) == 1, g2700
    f = fast[0]
    assert f["stable"] and not f["contact_valid"]
    assert f["contact_violation"] == "stance-lift-off" and f["contact_model"] == "bilateral"
    z = np.array([f["theta_plus_rad"], f["theta_dot_plus_rad_s"]])
    ref = _reference_min_stance_force(2700.0, z)
    assert ref < 0.0
    reported = f["contact"]["min_stance_force_single_support_N"]
    assert reported == pytest.approx(ref, abs=SAMPLED_MIN_TOL_N)
    assert "stance-lift-off" in f["contact_reason"] and f"{reported:.2f} N" in f["contact_reason"]
    assert 0 < f["contact"]["negative_stance_force_s"] < f["step_period_s"]
    # independent: the unilateral map rejects the step from that gait by its located lift-off guard
    with pytest.raises(StepFailure) as err:
        fast_step(WheelParams().replace(stiffness_n_per_m=2700.0), "ve", z)
    assert err.value.reason == FailureReason.STANCE_LIFT_OFF
    assert all(g["contact_valid"] for g in g2700 if g is not f)  # the others are ordinary gaits
    fast2500 = [g for g in _gaits(2500) if abs(g["step_period_s"] - 0.261) < 0.01]
    assert len(fast2500) == 1 and fast2500[0]["contact_valid"] and fast2500[0]["contact_model"] == "unilateral"
    z2500 = np.array([fast2500[0]["theta_plus_rad"], fast2500[0]["theta_dot_plus_rad_s"]])
    assert fast2500[0]["contact"]["min_stance_force_single_support_N"] == pytest.approx(
        _reference_min_stance_force(2500.0, z2500), abs=SAMPLED_MIN_TOL_N
    )


def test_sweep_row_of_the_invalid_gait_says_why_and_gait_n_refuses_it():
    from rimless.sim.studies.sweep import SweepOptions, compute_point

    point = {"model": "ve", "params": WheelParams().replace(stiffness_n_per_m=2700.0).to_dict()}
    rows = compute_point(point, SweepOptions(n_guesses=8))["rows"]
    bad = [r for r in rows if not r["contact_valid_at_start"]]
    assert len(bad) == 1 and bad[0]["step_period_s"] == pytest.approx(0.25, abs=0.01)
    assert bad[0]["reason"] == "contact-invalid-at-start" and bad[0]["contact_violation"] == "stance-lift-off"
    z = np.array([bad[0]["theta_plus_rad"], bad[0]["theta_dot_plus_rad_s"]])
    assert bad[0]["min_stance_force_single_support_N"] == pytest.approx(
        _reference_min_stance_force(2700.0, z), abs=SAMPLED_MIN_TOL_N
    )
    assert np.isnan(bad[0]["critical_slope_rad"])
    res = CliRunner().invoke(app, ["sim", "fixed-point", "--model", "ve", "--k", "2700", "--gait", "1"])
    assert res.exit_code == 1 and "violates unilateral contact" in res.stderr


def test_stance_force_test_function_brackets_the_zero_of_the_stance_force():
    """The continuation's bracket of the stance force's zero lies where the reference path puts the zero:
    above k = 2500 (a positive minimum, test above) and below k = 2551.4 (a dip below zero located by the
    reference path, tests.support.sim_dip), within the bracket's width of it."""
    from rimless.sim.continuation.arclength import STANCE_FORCE, ArclengthContinuation
    from rimless.sim.step.poincare import bilateral_map

    base = WheelParams().replace(stiffness_n_per_m=2500.0)
    cont = ArclengthContinuation(
        lambda q: bilateral_map(FastPoincareMap(q, "ve")), base, "ve", "k", facts_every=1, max_points=40
    )
    br = cont.trace(FAST_2500, direction=1.0, p_max=2700.0, stop_at_first_loss=True)
    sp = br.first_loss()
    assert sp is not None and sp.kind == STANCE_FORCE
    lo, hi = sorted(sp.bracket_p)
    k_negative = DIP_PARAMS.stiffness_n_per_m
    assert 2500.0 < lo < k_negative and lo <= hi < k_negative + 0.5 and hi - lo < 0.5
    a, b = sp.bracket_values
    assert a > 0 > b
