"""The one guard table of the hybrid system: every g(y) whose zero crossing in its direction ends a phase
(model.md section 4), for the phase sequence of a step and for the clutch modes of the firmware in the loop.

Each guard is named by a small integer code (module-level int constants, which the compiled path reads as
compile-time constants), with its name, its crossing direction (-1: falls through 0, +1: rises through 0),
whether it is a normal-force guard (located also when the force dips below zero and recovers between two
solver steps, rimless.sim.integrate.events) and the failure it means when it fires (None: it ends a phase).

`failure_of` turns a failure guard into its classified StepFailure. `guard_value` evaluates the guards of
the step's phases (rimless.sim.model.dynamics), `mode_guard_value` those of a clutch mode
(rimless.sim.model.clutch.Mode, with the clutch's holding force, or the guide friction F_c for the friction
phases of rimless.sim.model.friction); both return N for force guards, rad/s or
m/s for rate guards, m for heights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rimless.sim.model import clutch as ch
from rimless.sim.model.dynamics import DLSP, accel
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import Mechanics, swing_height

LIFTOFF_A = 0  # lambda_a,y falls through 0: the trailing foot lifts off (ends DLSP)
STALL = 1  # theta' falls through 0: the wheel stops and rolls back (failure)
CLUTCH_LOCK = 2  # L1' rises through 0: maximum compression, the clutch locks (ends free compression)
TOUCHDOWN = 3  # swing-foot height falls through 0 (ends single support)
LIFTOFF_B = 4  # lambda_b,y falls through 0 in single support (failure)
# the clutch modes of the firmware in the loop (rimless.sim.in_the_loop.loop) and the guide friction's
# stick/slip phases (rimless.sim.model.friction, holding force = F_c) add:
FOOT_A_DOWN = 5  # the lifted foot a's height falls through 0: it comes down again (a re-contact impact)
SLIP_END_1 = 6  # the slipping stance leg's rate |L1'| falls through 0 (the slip ends)
SLIP_END_2 = 7  # the slipping trailing leg's rate |L2'| falls through 0
STICK_END_1 = 8  # holding force - |holding constraint force| of the stuck stance leg falls through 0 (it slips)
STICK_END_2 = 9  # likewise for the trailing leg


@dataclass(frozen=True)
class Guard:
    """One row of the table: code, name, crossing direction, force guard?, failure (and why) when it fires."""

    code: int
    name: str
    direction: int
    force: bool = False
    failure: FailureReason | None = None
    why: str = ""


TABLE: dict[int, Guard] = {
    g.code: g
    for g in (
        Guard(LIFTOFF_A, "lift-off-a", -1, force=True),
        Guard(
            STALL,
            "stall",
            -1,
            failure=FailureReason.STALL,
            why="theta' reached 0 before touchdown (the wheel rolls back)",
        ),
        Guard(CLUTCH_LOCK, "clutch-lock", +1),
        Guard(TOUCHDOWN, "touchdown", -1),
        Guard(
            LIFTOFF_B,
            "lift-off-b",
            -1,
            force=True,
            failure=FailureReason.STANCE_LIFT_OFF,
            why="the stance foot's normal force fell below 0",
        ),
        Guard(FOOT_A_DOWN, "foot-a-down", -1),
        Guard(SLIP_END_1, "slip-end-1", -1),
        Guard(SLIP_END_2, "slip-end-2", -1),
        Guard(STICK_END_1, "stick-end-1", -1),
        Guard(STICK_END_2, "stick-end-2", -1),
    )
}

GUARD_NAMES = {c: g.name for c, g in TABLE.items()}
DIRECTION = {c: g.direction for c, g in TABLE.items()}
FORCE_GUARDS = tuple(c for c, g in TABLE.items() if g.force)  # located also when they dip between solver steps
FAILURE = {c: g.failure for c, g in TABLE.items() if g.failure is not None}


def failure_of(code: int | None, time_s: float, phase: str) -> StepFailure | None:
    """The classified StepFailure of guard `code` firing at time_s (s) in `phase`, or None if it ends a phase."""
    row = TABLE.get(code) if code is not None else None
    if row is None or row.failure is None:
        return None
    return StepFailure(row.failure, row.why, time_s=time_s, phase=phase)


def guard_value(mech: Mechanics, phase: int, code: int, y: np.ndarray) -> float:
    """Value of guard `code` at state y during step phase `phase` (units: N, rad/s, m/s or m)."""
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


def clutch_forces(mech: Mechanics, mode: ch.Mode, y: np.ndarray, holding_force_N: float) -> np.ndarray:
    """The constraint forces (N) of clutch mode `mode` at y; a slipping clutch pulls with holding_force_N
    (an infinite holding force is a rigid clutch: no slip force)."""
    friction = holding_force_N if np.isfinite(holding_force_N) else 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        _, lam = ch.accel(mech, mode, y[:5], y[5:10], friction)
    return lam


def mode_guard_value(mech: Mechanics, mode: ch.Mode, code: int, y: np.ndarray, holding_force_N: float) -> float:
    """Value of guard `code` at state y in clutch mode `mode` (units: N, m/s or m)."""
    if code == TOUCHDOWN:
        return swing_height(y[:5], mech.params.leg_length_m)
    if code == STALL:
        return float(y[7])
    if code == CLUTCH_LOCK:
        return float(y[8])
    if code == FOOT_A_DOWN:
        return ch.foot_a_height(y[:5])
    if code in (SLIP_END_1, SLIP_END_2):
        which = 1 if code == SLIP_END_1 else 2
        st = mode.leg1 if which == 1 else mode.leg2
        rate = float(y[5 + (ch.L1_INDEX if which == 1 else ch.L2_INDEX)])
        return rate if st == ch.SLIP_UP else -rate
    lam = clutch_forces(mech, mode, y, holding_force_N)
    if code in (STICK_END_1, STICK_END_2):
        which = 1 if code == STICK_END_1 else 2
        return holding_force_N - abs(float(lam[ch.clutch_force_index(mode, which)]))
    if code == LIFTOFF_B:
        return float(lam[1])
    if code == LIFTOFF_A:
        return float(lam[3])
    raise ValueError(f"unknown guard {code}")
