"""Constrained dynamics of the three continuous phases.

M(q) q'' + h(q, q') = A^T lambda with A the phase's constraint rows (model.md section 3-4):
- DLSP: both feet pinned, A = [e_xb; e_yb; J_a], lambda = (l_bx, l_by, l_ax, l_ay), N;
- SLSP_FREE: foot b pinned, A = [e_xb; e_yb], lambda = (l_bx, l_by);
- SLSP_CLUTCHED: foot b pinned and L1' = 0, A = [e_xb; e_yb; e_L1], lambda = (l_bx, l_by, l_L1).
The state is y = [q, q'] (10,), SI units, slope frame.
"""

from __future__ import annotations

import numpy as np

from rimless.sim.model.mechanics import Mechanics

DLSP = 0
SLSP_FREE = 1
SLSP_CLUTCHED = 2

PHASE_NAMES = {DLSP: "dlsp", SLSP_FREE: "slsp_free", SLSP_CLUTCHED: "slsp_clutched"}
N_CONSTRAINTS = {DLSP: 4, SLSP_FREE: 2, SLSP_CLUTCHED: 3}


def constraint_rows(mech: Mechanics, phase: int, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, A' q') of a phase: constraint Jacobian rows and their velocity term."""
    n = N_CONSTRAINTS[phase]
    A = np.zeros((n, 5))
    adot = np.zeros(n)
    A[0, 0] = 1.0
    A[1, 1] = 1.0
    if phase == DLSP:
        A[2:4] = mech.jac_a(q)
        adot[2:4] = mech.jdot_qd_a(q, qd)
    elif phase == SLSP_CLUTCHED:
        A[2, 3] = 1.0
    return A, adot


def accel(mech: Mechanics, phase: int, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) of a phase: solves [[M, -A^T], [A, 0]] [q''; lambda] = [-h; -A' q']."""
    M = mech.mass_matrix(q)
    h = mech.bias(q, qd)
    A, adot = constraint_rows(mech, phase, q, qd)
    n = A.shape[0]
    K = np.zeros((5 + n, 5 + n))
    K[:5, :5] = M
    K[:5, 5:] = -A.T
    K[5:, :5] = A
    rhs = np.concatenate((-h, -adot))
    sol = np.linalg.solve(K, rhs)
    return sol[:5], sol[5:]


def rhs(mech: Mechanics, phase: int, y: np.ndarray) -> np.ndarray:
    """dy/dt of a phase, y = [q, q']."""
    qdd, _ = accel(mech, phase, y[:5], y[5:])
    return np.concatenate((y[5:], qdd))


def damping_power(mech: Mechanics, phase: int, qd: np.ndarray) -> float:
    """Power dissipated by the leg dampers, W (>= 0)."""
    c = mech.params.damping_ns_per_m
    l1 = 0.0 if phase == SLSP_CLUTCHED else qd[3]
    return c * (l1 * l1 + qd[4] * qd[4])
