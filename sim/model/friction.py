"""Coulomb friction in the legs' linear guides (beyond the paper; docs/simulator.md, "Guide friction").

Each sliding leg feels a friction force of magnitude F_c = WheelParams.guide_friction_n (N) against its slide.
The sliding legs of a phase (`friction_legs`): both active legs in double support and in free single support;
in the clutched phase only the trailing leg (the clutch holds the stance leg; friction does not act on it).

Each friction leg is in one of three states (the constants of rimless.sim.model.clutch):
- SLIP_UP / SLIP_DOWN: L' > 0 / L' < 0, the generalised force -F_c / +F_c acts on L;
- STUCK: L' = 0 is a constraint (the locked-leg constraint of the clutch, without power) whose force lambda
  must satisfy |lambda| <= F_c.
A slipping leg whose rate reaches 0 (guard SLIP_END_i) sticks if holding it needs |lambda| <= F_c, else it slips
on in the direction the unbalanced force drives it; a stuck leg slips again when |lambda| exceeds F_c (guard
STICK_END_i = F_c - |lambda|). In double support the wheel has one degree of freedom: a stuck leg would lock the
rigid triangle (two pinned feet, the fixed spoke angle) and stop the wheel, so there a leg whose rate crosses 0
reverses its slide (the crossing is kinematic: L_i' = v_i(q) theta').

A friction phase (a base phase of rimless.sim.model.dynamics with the friction legs' states) is one int, the
phase code the integrators take (`encode`): FRICTION_PHASE0 + 16 base + 4 state1 + state2 (codes below
FRICTION_PHASE0 are the frictionless phases). The friction work over a stretch where each leg keeps its state is
F_c times the distance the slipping legs slid (`slide_work`): exact, no quadrature.
"""

from __future__ import annotations

import numpy as np

from rimless.sim.model import clutch as ch
from rimless.sim.model.dynamics import DLSP, SLSP_CLUTCHED
from rimless.sim.model.guards import SLIP_END_1, SLIP_END_2, STICK_END_1, STICK_END_2, mode_guard_value
from rimless.sim.model.mechanics import Mechanics

FRICTION_PHASE0 = 16  # phase codes >= this are friction phases (encode / decode)
FRICTION_INDEX = 8  # F_c's index in Mechanics.p (after WheelParams.as_vector()), read by the compiled path
MAX_SWITCHES = 2000  # stick/slip switches per phase before the phase is reported as failed (chattering)
SLIP_UP, SLIP_DOWN, STUCK = ch.SLIP_UP, ch.SLIP_DOWN, ch.STUCK
LEG_INDEX = {1: ch.L1_INDEX, 2: ch.L2_INDEX}


def encode(base: int, s1: int, s2: int) -> int:
    """The phase code of base phase `base` with leg states s1, s2 (s1 ignored and STUCK when clutched)."""
    if base == SLSP_CLUTCHED:
        s1 = STUCK
    return FRICTION_PHASE0 + 16 * base + 4 * s1 + s2


def decode(code: int) -> tuple[int, int, int]:
    """(base, s1, s2) of a friction phase code."""
    c = code - FRICTION_PHASE0
    return c // 16, (c % 16) // 4, c % 4


def is_friction_phase(code: int) -> bool:
    return code >= FRICTION_PHASE0


def friction_legs(base: int) -> tuple[int, ...]:
    """The legs that slide against guide friction in base phase `base` (1: stance, 2: trailing)."""
    return (2,) if base == SLSP_CLUTCHED else (1, 2)


def mode_of(code: int) -> ch.Mode:
    """The clutch-module constraint mode of a friction phase (foot a, each leg FREE/STUCK/SLIP)."""
    base, s1, s2 = decode(code)
    return ch.Mode(foot_a=base == DLSP, leg1=STUCK if base == SLSP_CLUTCHED else s1, leg2=s2)


def friction_guards(code: int) -> tuple[int, ...]:
    """The stick/slip guards of a friction phase (codes of rimless.sim.model.guards)."""
    base, s1, s2 = decode(code)
    out = []
    for leg, st in ((1, s1), (2, s2)):
        if leg not in friction_legs(base):
            continue
        if st == STUCK:
            out.append(STICK_END_1 if leg == 1 else STICK_END_2)
        else:
            out.append(SLIP_END_1 if leg == 1 else SLIP_END_2)
    return tuple(out)


def accel(mech: Mechanics, code: int, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) of a friction phase; lambda in the row order of clutch.constraint_rows (N)."""
    return ch.accel(mech, mode_of(code), q, qd, mech.params.guide_friction_n)


def stick_force(mech: Mechanics, code: int, leg: int, y: np.ndarray) -> float:
    """The constraint force (N, along +L) holding stuck leg `leg` in friction phase `code`."""
    mode = mode_of(code)
    _, lam = ch.accel(mech, mode, y[:5], y[5:10], mech.params.guide_friction_n)
    return float(lam[ch.clutch_force_index(mode, leg)])


def _with(code: int, leg: int, state: int) -> int:
    base, s1, s2 = decode(code)
    return encode(base, state if leg == 1 else s1, state if leg == 2 else s2)


def _slip_or_stick(mech: Mechanics, code: int, leg: int, y: np.ndarray) -> tuple[int, np.ndarray]:
    """Leg `leg` at rest (its rate set to 0): stuck if holding it needs at most F_c, else slipping the way the
    unbalanced holding force drives it. Returns (code, y)."""
    y = np.array(y, dtype=float)
    y[5 + LEG_INDEX[leg]] = 0.0
    stuck = _with(code, leg, STUCK)
    lam = stick_force(mech, stuck, leg, y)
    if abs(lam) <= mech.params.guide_friction_n:
        return stuck, y
    return _with(code, leg, SLIP_DOWN if lam > 0.0 else SLIP_UP), y


def settle(mech: Mechanics, code: int, y: np.ndarray) -> tuple[int, np.ndarray]:
    """Release every stuck leg whose holding force exceeds F_c (after another leg changed state); (code, y)."""
    base = decode(code)[0]
    for _ in range(4):
        changed = False
        for leg in friction_legs(base):
            if decode(code)[leg] == STUCK:
                lam = stick_force(mech, code, leg, y)
                if abs(lam) > mech.params.guide_friction_n:
                    code = _with(code, leg, SLIP_DOWN if lam > 0.0 else SLIP_UP)
                    changed = True
        if not changed:
            break
    return code, y


def initial_phase(mech: Mechanics, base: int, y: np.ndarray) -> tuple[int, np.ndarray]:
    """The friction phase a base phase starts in from state y: each friction leg slips the way it moves; a leg
    at rest sticks or slips (`_slip_or_stick`; in double support it slips the way it accelerates). (code, y)."""
    y = np.array(y, dtype=float)
    code = encode(base, SLIP_UP, SLIP_UP)
    for leg in friction_legs(base):
        rate = y[5 + LEG_INDEX[leg]]
        if rate > 0.0:
            code = _with(code, leg, SLIP_UP)
        elif rate < 0.0:
            code = _with(code, leg, SLIP_DOWN)
        elif base == DLSP:
            qdd, _ = accel(mech, _with(code, leg, SLIP_UP), y[:5], y[5:10])
            code = _with(code, leg, SLIP_UP if qdd[LEG_INDEX[leg]] > 0.0 else SLIP_DOWN)
        else:
            code, y = _slip_or_stick(mech, code, leg, y)
    return settle(mech, code, y)


def switch(mech: Mechanics, code: int, guard: int, y: np.ndarray) -> tuple[int, np.ndarray]:
    """The friction phase after stick/slip guard `guard` fired at y: (code, y)."""
    base, s1, s2 = decode(code)
    leg = 1 if guard in (SLIP_END_1, STICK_END_1) else 2
    if guard in (SLIP_END_1, SLIP_END_2):
        if base == DLSP:  # no stick in double support: the slide reverses
            state = s1 if leg == 1 else s2
            code = _with(code, leg, SLIP_DOWN if state == SLIP_UP else SLIP_UP)
        else:
            code, y = _slip_or_stick(mech, code, leg, y)
    else:
        lam = stick_force(mech, code, leg, y)
        code = _with(code, leg, SLIP_DOWN if lam > 0.0 else SLIP_UP)
    return settle(mech, code, y)


def slide_work(code: int, y_start: np.ndarray, y_end: np.ndarray, friction_n: float) -> float:
    """Friction work (J, >= 0) over a stretch of one friction phase: F_c times the slipping legs' slide."""
    base, s1, s2 = decode(code)
    w = 0.0
    for leg, st in ((1, s1), (2, s2)):
        if leg in friction_legs(base) and st != STUCK:
            i = LEG_INDEX[leg]
            w += friction_n * abs(float(y_end[i]) - float(y_start[i]))
    return w


def guard_value(mech: Mechanics, code: int, guard: int, y: np.ndarray) -> float:
    """Value of `guard` in friction phase `code` (the clutch-mode guards with F_c as the holding force)."""
    return mode_guard_value(mech, mode_of(code), guard, y, mech.params.guide_friction_n)


def damping_power(mech: Mechanics, code: int, qd: np.ndarray) -> float:
    """Power dissipated by the dampers of the legs that slide in friction phase `code`, W."""
    return ch.damping_power(mech, mode_of(code), qd)


REST_RATE = 1e-9  # m/s: a recorded leg rate below this counts as at rest (stuck) in `sample_accel`


def sample_accel(mech: Mechanics, base: int, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) of base phase `base` at a recorded sample y, the friction state read off the legs' rates
    (|L'| < REST_RATE: at rest, stuck or slipping by the stick test); lambda's first rows are the feet's."""
    y = np.array(y, dtype=float)
    for leg in friction_legs(base):
        if abs(y[5 + LEG_INDEX[leg]]) < REST_RATE:
            y[5 + LEG_INDEX[leg]] = 0.0
    code, y = initial_phase(mech, base, y)
    return accel(mech, code, y[:5], y[5:10])
