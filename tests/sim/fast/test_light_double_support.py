"""Legs of 1 mg (m_H / m ~ 2.6e6): double support's field from the pivoted KKT solve, so that the compiled step
map succeeds there (on bfde425 it failed in double support: DOP853 took more than 200 000 steps on the rounding
noise of the generated reduced equations, some eps (m_H / m)^2). Checked against code written apart: the
reference model's KKT solve (rimless.sim.model.dynamics, numpy's LAPACK) and scipy's DOP853 on it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.sim.fast import FastIntegrator, fast_step, param_vector
from rimless.sim.fast import model as fm
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import dynamics
from rimless.sim.model.guards import LIFTOFF_A, STALL, TOUCHDOWN
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section

RELEASE = np.array([-math.pi / 8, 2.0])  # theta (rad), theta' (rad/s): released on two feet


def light(m: float) -> WheelParams:
    """The rigid truth wheel of rimless.analysis.validation.critical_truth (M 2.6 kg, I_hub 0.05 kg m^2, L 0.21 m)
    with legs of mass m (kg) as its wheel_params() writes it, on a 4 deg ramp."""
    return WheelParams(
        hub_mass_kg=2.6 - 8 * m,
        leg_mass_kg=m,
        inertia_kg_m2=0.05 - 8 * m * 0.21**2,
        leg_length_m=0.21,
        slope_rad=math.radians(4.0),
    )


def _states(mech: Mechanics) -> list[np.ndarray]:
    """The release's post-impact state and three perturbed ones (a compressed or stretched trailing leg moving)."""
    y0 = state_from_section(mech, RELEASE)
    out = [y0]
    for dL, dLd in ((3e-3, 0.05), (-2e-3, -0.1), (1e-3, 0.3)):
        y = y0.copy()
        y[4] += dL
        y[9] += dLd
        out.append(y)
    return out


@pytest.mark.parametrize("m", [1e-4, 1e-6, 1e-8])
def test_double_support_field_of_light_legs_matches_the_reference_kkt_solve(m: float) -> None:
    """q'' and lambda of the compiled double support (what DOP853 integrates and the lift-off guard reads) against
    the reference model's KKT solve by LAPACK, written apart: to 1e-11 (absolute, q'' ~ 3, lambda ~ 25 N). On
    bfde425 the generated reduced equations were off by 1.7e-8 at 0.1 g and 6.6e-4 at 1 mg."""
    mech = Mechanics.of(light(m))
    p = param_vector(light(m))
    for y in _states(mech):
        qdd, lam = np.empty(5), np.zeros(4)
        assert fm.accel(0, fm.DLSP, y[:5], y[5:], p, qdd, lam)
        ref_qdd, ref_lam = dynamics.accel(mech, dynamics.DLSP, y[:5], y[5:])
        np.testing.assert_allclose(qdd, ref_qdd, rtol=0, atol=1e-11)
        np.testing.assert_allclose(lam, ref_lam, rtol=0, atol=1e-11)


def test_light_leg_double_support_phase_agrees_with_scipy_dop853_on_the_reference_model() -> None:
    """The double-support phase of 1 mg legs, compiled DOP853 at rtol 1e-10 (the map's tightened double-support
    tolerance), against scipy's DOP853 on the reference model at rtol 1e-12: the trailing foot lifts off at the
    same time (1e-10 s; measured 3e-12) in the same state (1e-9; measured 2e-11), in a bounded number of
    evaluations (48 measured; on bfde425: no end within the step limit)."""
    mech = Mechanics.of(light(1e-6))
    y0 = state_from_section(mech, RELEASE)
    guards = (LIFTOFF_A, STALL, TOUCHDOWN)
    ref = ScipyIntegrator("DOP853", rtol=1e-12, atol=1e-14).run_phase(mech, dynamics.DLSP, y0, 0.0, guards, 5.0)
    got = FastIntegrator(rtol=1e-10, atol=1e-12, max_steps=2000).run_phase(mech, dynamics.DLSP, y0, 0.0, guards, 5.0)
    assert not ref.failed and ref.guard == LIFTOFF_A
    assert not got.failed, got.message
    assert got.guard == LIFTOFF_A
    assert got.t_end == pytest.approx(ref.t_end, abs=1e-10)
    np.testing.assert_allclose(got.y_end, ref.y_end, rtol=0, atol=1e-9)
    assert got.nfev < 500


@pytest.mark.parametrize("rtol", [1e-8, 1e-10])
def test_one_mg_leg_step_map_succeeds_and_converges_to_the_light_leg_limit(rtol: float) -> None:
    """The compiled step map with 1 mg legs succeeds (bfde425: StiffnessLimit in double support) in a bounded
    number of evaluations, with and without its Jacobian. Its result sits on the light-leg limit: the map is
    smooth in m (first order: the 0.1 g and 0.01 g maps differ by 8.9e-6 s), so the 1 mg map lies on the line
    through the 0.1 g and 0.01 g maps to within the second-order term and the tolerance's error (measured 2e-11 s
    and 5e-11 at rtol 1e-8 to 1e-12); asserted to 1e-9."""
    steps = {m: fast_step(light(m), "er", RELEASE, rtol=rtol) for m in (1e-4, 1e-5, 1e-6)}
    got = steps[1e-6]
    assert got.nfev < 12_000 and got.phase_steps[0] < 50
    # linear extrapolation in m from 0.1 g and 0.01 g to 1 mg
    lin_t = steps[1e-5].period_s + (steps[1e-5].period_s - steps[1e-4].period_s) * (1e-6 - 1e-5) / (1e-5 - 1e-4)
    lin_z = steps[1e-5].z_next + (steps[1e-5].z_next - steps[1e-4].z_next) * (1e-6 - 1e-5) / (1e-5 - 1e-4)
    assert got.period_s == pytest.approx(lin_t, abs=1e-9)
    np.testing.assert_allclose(got.z_next, lin_z, rtol=0, atol=1e-9)
    with_j = fast_step(light(1e-6), "er", RELEASE, rtol=rtol, jacobian=True)
    assert with_j.jacobian is not None and np.all(np.isfinite(with_j.jacobian))
    assert with_j.period_s == pytest.approx(got.period_s, abs=5e-8)


def test_one_mg_leg_exact_jacobian_matches_central_differences() -> None:
    """The exact map Jacobian with 1 mg legs (variational equations through double support on the pivoted KKT
    derivatives) against central differences of the map at rtol 1e-12 (dz 1e-6: their error some 1e-8 / 1e-6),
    to 1e-6 of its largest entry (measured 2e-8)."""
    P = light(1e-6)
    J = fast_step(P, "er", RELEASE, rtol=1e-10, jacobian=True).jacobian
    assert J is not None
    fd = np.empty((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = 1e-6
        fd[:, j] = (
            fast_step(P, "er", RELEASE + e, rtol=1e-12).z_next - fast_step(P, "er", RELEASE - e, rtol=1e-12).z_next
        ) / 2e-6
    assert np.max(np.abs(J - fd)) < 1e-6 * np.max(np.abs(fd))
