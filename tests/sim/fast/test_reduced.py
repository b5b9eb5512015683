"""The generated reduced dynamics of each phase against the full KKT solve (the cross-check kept for this).

Agreement to 1e-12 relative to the size of the equations' terms, on random states of each phase: foot b
at rest (x_b' = y_b' = 0), L1' = 0 when clutched, and in double support the velocities in the null space
of the double-support constraint Jacobian. The variational (directional) form is checked on arbitrary
states and tangents."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.sim.fast import model as fm
from rimless.sim.model import dynamics
from rimless.sim.model.impact import double_support_jacobian
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import MASS_MODELS, WheelParams
from tests.support.sim_states import random_states

PHASES = (dynamics.DLSP, dynamics.SLSP_FREE, dynamics.SLSP_CLUTCHED)

# Each mass model compiles kernels of its own (tens of seconds on a cold cache): eight-leg (the robot's) runs in
# every run, the other two are marked `full` (CI runs them).
MASS_MODEL_CASES = [m if m == "eight-leg" else pytest.param(m, marks=pytest.mark.full) for m in MASS_MODELS]


def _phase_state(mech: Mechanics, phase: int, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    qd = qd.copy()
    qd[:2] = 0.0
    if phase == dynamics.SLSP_CLUTCHED:
        qd[3] = 0.0
    if phase == dynamics.DLSP:
        Jc = double_support_jacobian(mech, q)
        null = np.linalg.svd(Jc)[2][-1]
        qd = null * (qd[2] / null[2])
    return np.concatenate((q, qd))


@pytest.mark.parametrize("mass_model", MASS_MODEL_CASES)
@pytest.mark.parametrize("phase", PHASES)
def test_reduced_dynamics_match_the_full_kkt_solve(mass_model: str, phase: int) -> None:
    params = WheelParams(mass_model=mass_model, leg_mass_kg=0.0378, damping_ns_per_m=8.0)
    mech = Mechanics.of(params)
    mi = fm.MASS_MODEL_INDEX[mass_model]
    rng = np.random.default_rng(11 + phase)
    n = dynamics.N_CONSTRAINTS[phase]
    worst = 0.0
    for q, qd in random_states(rng, 200):
        y = _phase_state(mech, phase, q, qd)
        a, la = np.empty(5), np.zeros(4)
        b, lb = np.empty(5), np.zeros(4)
        assert fm.accel_reduced(mi, phase, y[:5], y[5:], mech.p, a, la, np.empty(fm.WORKSPACE_SIZE))
        assert fm.accel_kkt(mi, phase, y[:5], y[5:], mech.p, b, lb)
        # relative to the size of the equations' terms (a result that is small by cancellation of large
        # gravity, spring and centrifugal terms is known to round-off of those terms only)
        h = mech.bias(y[:5], y[5:])
        scale_q = max(np.linalg.norm(b), np.linalg.norm(np.linalg.solve(mech.mass_matrix(y[:5]), h)))
        scale_l = max(np.linalg.norm(lb[:n]), np.linalg.norm(h))
        err = max(np.linalg.norm(a - b) / scale_q, np.linalg.norm(la[:n] - lb[:n]) / scale_l)
        worst = max(worst, err)
        # and the reference (numpy) implementation
        qdd_ref, lam_ref = dynamics.accel(mech, phase, y[:5], y[5:])
        np.testing.assert_allclose(a, qdd_ref, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(la[:n], lam_ref, rtol=1e-10, atol=1e-9)
    assert worst <= 1e-12, worst


@pytest.mark.parametrize("mass_model", MASS_MODEL_CASES)
@pytest.mark.parametrize("phase", PHASES)
def test_reduced_variational_equations_match_the_full_kkt_derivative(mass_model: str, phase: int) -> None:
    """(dq''/dy) V from the generated reduced equations against the full KKT derivative (accel_jacobian),
    for arbitrary states and tangent columns (the reduced equations need no consistency)."""
    params = WheelParams(mass_model=mass_model)
    mech = Mechanics.of(params)
    mi = fm.MASS_MODEL_INDEX[mass_model]
    rng = np.random.default_rng(23 + phase)
    worst = 0.0
    for q, qd in random_states(rng, 100):
        y = np.concatenate((q, qd))
        V = rng.normal(size=(10, 2))
        qdd, lam, dqdd = np.empty(5), np.zeros(4), np.empty((5, 2))
        assert fm.accel_directional(mi, phase, y[:5], y[5:], mech.p, qdd, lam, V, dqdd, np.empty(fm.WORKSPACE_SIZE + 5))
        b, lb, D, Dl = np.empty(5), np.zeros(4), np.empty((5, 10)), np.empty((4, 10))
        assert fm.accel_jacobian(mi, phase, y[:5], y[5:], mech.p, b, lb, D, Dl)
        full = D @ V
        scale = np.linalg.norm(np.abs(D) @ np.abs(V))  # the size of the terms summed
        free_fall = np.linalg.solve(mech.mass_matrix(y[:5]), mech.bias(y[:5], y[5:]))
        scale_q = max(np.linalg.norm(b), np.linalg.norm(free_fall))
        worst = max(worst, np.linalg.norm(dqdd - full) / scale, np.linalg.norm(qdd - b) / scale_q)
    assert worst <= 1e-12, worst
