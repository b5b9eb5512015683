"""Fixed points of the ER and VE wheels at Table 1: residual, stability, and model.md's expectations."""

import numpy as np
import pytest

from rimless.sim.step.poincare import PoincareMap


def _regression_jacobian(pmap: PoincareMap, z: np.ndarray, radius: float = 2e-5, n: int = 8) -> np.ndarray:
    """An independent estimate: least-squares fit of P(z + d) - P(z) = J d over a ring of perturbations."""
    base = pmap(z)
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    D = radius * np.column_stack((np.cos(angles), np.sin(angles)))
    Y = np.array([pmap(z + d) - base for d in D])
    # second-order terms cancel pairwise on a symmetric ring: fit with the opposite points averaged
    sol, *_ = np.linalg.lstsq(D, Y, rcond=None)
    return sol.T


@pytest.mark.parametrize("which", ["er_fixed_point", "ve_fixed_point"])
def test_fixed_point_residual_and_two_jacobian_estimates_agree(which, request):
    pmap, fp = request.getfixturevalue(which)
    assert fp.residual <= 1e-10
    assert np.max(np.abs(pmap(fp.z) - fp.z)) <= 1e-10
    J2 = _regression_jacobian(pmap, fp.z)
    ev1 = np.sort_complex(np.linalg.eigvals(fp.jacobian))
    ev2 = np.sort_complex(np.linalg.eigvals(J2))
    assert np.max(np.abs(ev1 - ev2)) <= 1e-6


def test_er_gait_matches_model_md_orders_of_magnitude(er_fixed_point):
    _, fp = er_fixed_point
    assert fp.step.period_s == pytest.approx(0.31, abs=0.01)
    assert fp.z[1] == pytest.approx(2.6, abs=0.05)
    assert fp.max_abs_eigenvalue == pytest.approx(0.79, abs=0.01)
    assert fp.step.impact.energy_ratio == pytest.approx(0.85, abs=0.01)
    assert fp.stable
    assert [p.name for p in fp.step.phases] == ["dlsp", "slsp_free", "slsp_clutched"]
    d = fp.step.diagnostics
    # model.md section 9: brief leading-foot tension at the start of DLSP (a few newtons, ~1/3 of the phase)
    assert -20 < d["min_normal_force_b_dlsp_N"] < 0
    assert 0 < d["leading_foot_tension_s"] < 0.6 * fp.step.phase_durations_s["dlsp"]
    # the lifted trailing foot dips a few millimetres below the slope
    assert -0.006 < d["trailing_foot_min_height_m"] < 0


def test_ve_medium_gait_matches_model_md(ve_fixed_point):
    _, fp = ve_fixed_point
    assert fp.step.period_s == pytest.approx(0.40, abs=0.01)
    assert fp.step.impact.energy_ratio == pytest.approx(0.81, abs=0.01)
    assert [p.name for p in fp.step.phases] == ["dlsp", "slsp_free"]


def test_period_one_gait_repeats_itself(er_fixed_point):
    """Iterating the map from the fixed point stays there (a closed-form-free consistency check)."""
    pmap, fp = er_fixed_point
    z = fp.z
    for _ in range(3):
        z = pmap(z)
    assert np.max(np.abs(z - fp.z)) < 1e-9


def test_reference_jacobian_next_to_the_er_stall_matches_the_variational_one():
    """Next to the stall, a fixed central-difference step of 1e-4 crosses the stall boundary (the perturbed
    step rolls back); the curvature-scaled step must agree with the exact (variational) Jacobian."""
    from rimless.sim.continuation.arclength import ArclengthContinuation
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import default_guess

    base = WheelParams()
    cont = ArclengthContinuation(lambda q: make_map(q, "er", backend="fast"), base, "er")
    br = cont.trace(default_guess(base, "er"), stop_at_first_loss=True)
    end = br.first_loss()
    assert end.kind == "stall"
    # a fixed point 1e-5 rad above the stall, reached along the branch
    br2 = ArclengthContinuation(lambda q: make_map(q, "er", backend="fast"), base, "er").trace(
        default_guess(base, "er"), stop=lambda pt: pt.p < end.p + 1e-5
    )
    pt = br2.points[-1]
    ref = PoincareMap(base.replace(slope_rad=pt.p), "er", ScipyIntegrator(rtol=1e-10, atol=1e-12))
    with pytest.raises(StepFailure):
        ref(pt.z + np.array([0.0, -1e-4]))  # what the old fixed step evaluated
    J = ref.jacobian(pt.z)
    assert np.max(np.abs(J - pt.jacobian)) <= 1e-5 * (1 + np.max(np.abs(pt.jacobian)))


def test_newton_tolerance_follows_the_maps_own_noise():
    """Very light legs (m = 1e-4 kg) at a loose rtol (1e-6): the map's noise sits above the 1e-10 tolerance;
    Newton must accept its own noise floor instead of reporting that no gait exists. (At the default rtol the
    compiled map is now accurate enough to meet 1e-10 there.)"""
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import FIXED_POINT_TOL, default_guess, map_noise, solve_fixed_point

    p = WheelParams(leg_mass_kg=1e-4)
    pmap = make_map(p, "er", backend="fast", rtol=1e-6)
    fp = solve_fixed_point(pmap, default_guess(p, "er"), jacobian=pmap.jacobian)
    # accepted at its own noise floor when that lies above the tolerance (it did at ebb1b78), at the tolerance
    # otherwise: no NoFixedPoint either way
    assert fp.residual <= max(FIXED_POINT_TOL, 10 * map_noise(pmap, fp.z, fp.jacobian))
    assert fp.residual < 1e-7
    assert fp.stable
