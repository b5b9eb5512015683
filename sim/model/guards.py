"""Guards of the hybrid system: g(y) whose zero crossing in `direction` ends a phase (model.md section 4).

Each guard is named by a small integer code so that every integrator backend (scipy or compiled)
evaluates the same functions with the same semantics.
"""

from __future__ import annotations

import numpy as np

from rimless.sim.model.dynamics import DLSP, accel
from rimless.sim.model.mechanics import Mechanics, swing_height

LIFTOFF_A = 0  # lambda_a,y falls through 0: the trailing foot lifts off (ends DLSP)
STALL = 1  # theta' falls through 0: the wheel stops and rolls back (failure)
CLUTCH_LOCK = 2  # L1' rises through 0: maximum compression, the clutch locks (ends free compression)
TOUCHDOWN = 3  # swing-foot height falls through 0 (ends single support)
LIFTOFF_B = 4  # lambda_b,y falls through 0 in single support (failure)

GUARD_NAMES = {LIFTOFF_A: "lift-off-a", STALL: "stall", CLUTCH_LOCK: "clutch-lock", TOUCHDOWN: "touchdown", LIFTOFF_B: "lift-off-b"}
FORCE_GUARDS = (LIFTOFF_A, LIFTOFF_B)  # normal-force guards: located also when they dip between solver steps
DIRECTION = {LIFTOFF_A: -1, STALL: -1, CLUTCH_LOCK: +1, TOUCHDOWN: -1, LIFTOFF_B: -1}


def guard_value(mech: Mechanics, phase: int, code: int, y: np.ndarray) -> float:
    """Value of guard `code` at state y during `phase` (units: N, rad/s, m/s or m)."""
    if code == STALL:
        return float(y[7])
    if code == CLUTCH_LOCK:
        return float(y[8])
    if code == TOUCHDOWN:
        return swing_height(y[:5], mech.params.leg_length_m)
    _, lam = accel(mech, phase, y[:5], y[5:])
    if code == LIFTOFF_A:
        if phase != DLSP:
            raise ValueError("lift-off-a is a double-support guard")
        return float(lam[3])
    if code == LIFTOFF_B:
        return float(lam[1])
    raise ValueError(f"unknown guard {code}")
