"""Constraint combinations for a real clutch: legs locked wherever they are, clutches that slip.

The ideal path (rimless.sim.model.dynamics) has three phases. A clutch driven by sensors and a controller
also produces these combinations (foot b is always pinned; `Mode`):

- foot a on the ground or not;
- each active leg's clutch FREE, STUCK (L' = 0 is a constraint, the leg locked at its current length)
  or SLIPPING: an engaged clutch with a finite holding force F lets the leg slide when holding it would
  need more than F; it then acts as Coulomb friction of magnitude F against the slip.

With a finite holding force no impulse passes through a clutch: an engagement while the leg moves
starts a slip that the friction brings to rest; a touchdown while the trailing clutch is still engaged
is the reference impact (both legs slide through the impulse) followed by the trailing leg slipping
against F until the clutch lets go. Double support with a stuck trailing leg has no freedom left (two
pinned feet, a locked leg and the fixed spoke angle make a rigid triangle), so with finite F it slips.

A rigid clutch (F = inf) is kept for comparison: its engagement is an inelastic leg impact, and an
impact or engagement that must hold a leg in double support is resolved with contact complementarity
for foot a (`inelastic_transition`, `touchdown_with_locks`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rimless.sim.model.impact import ImpactResult, impact, relabel
from rimless.sim.model.mechanics import Mechanics, foot_a

L1_INDEX = 3
L2_INDEX = 4


FREE, STUCK, SLIP_UP, SLIP_DOWN = 0, 1, 2, 3  # clutch state of one leg
CLUTCH_STATE_NAMES = {FREE: "free", STUCK: "locked", SLIP_UP: "slip-extending", SLIP_DOWN: "slip-compressing"}


@dataclass(frozen=True)
class Mode:
    """Which constraints are active besides foot b: foot a on the ground, and each leg's clutch state.

    `leg1`, `leg2`: FREE (clutch off), STUCK (L' = 0 is a constraint), SLIP_UP / SLIP_DOWN (clutch engaged
    but slipping: L free, with the clutch's holding force opposing the slip as Coulomb friction)."""

    foot_a: bool
    leg1: int = FREE
    leg2: int = FREE

    @property
    def lock1(self) -> bool:
        return self.leg1 == STUCK

    @property
    def lock2(self) -> bool:
        return self.leg2 == STUCK

    @property
    def name(self) -> str:
        parts = ["dlsp" if self.foot_a else "slsp"]
        for i, st in ((1, self.leg1), (2, self.leg2)):
            if st != FREE:
                parts.append(f"L{i}-{CLUTCH_STATE_NAMES[st]}")
        return "+".join(parts)


def constraint_rows(mech: Mechanics, mode: Mode, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A, A' q') of a mode. Row order: b_x, b_y, [a_x, a_y], [L1], [L2]."""
    rows = [np.eye(5)[0], np.eye(5)[1]]
    adot = [0.0, 0.0]
    if mode.foot_a:
        ja = mech.jac_a(q)
        rows += [ja[0], ja[1]]
        adot += list(mech.jdot_qd_a(q, qd))
    if mode.lock1:
        rows.append(np.eye(5)[L1_INDEX])
        adot.append(0.0)
    if mode.lock2:
        rows.append(np.eye(5)[L2_INDEX])
        adot.append(0.0)
    return np.array(rows), np.array(adot)


def friction_force(mode: Mode, holding_force_N: float) -> np.ndarray:
    """Generalised force of slipping clutches on q (N): the holding force against the slip."""
    f = np.zeros(5)
    for idx, st in ((L1_INDEX, mode.leg1), (L2_INDEX, mode.leg2)):
        if st == SLIP_UP:
            f[idx] = -holding_force_N
        elif st == SLIP_DOWN:
            f[idx] = holding_force_N
    return f


def accel(
    mech: Mechanics, mode: Mode, q: np.ndarray, qd: np.ndarray, holding_force_N: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """(q'', lambda) in a mode; lambda in the row order of `constraint_rows` (N)."""
    M = mech.mass_matrix(q)
    h = mech.bias(q, qd)
    A, adot = constraint_rows(mech, mode, q, qd)
    n = A.shape[0]
    K = np.zeros((5 + n, 5 + n))
    K[:5, :5] = M
    K[:5, 5:] = -A.T
    K[5:, :5] = A
    rhs = np.concatenate((-h + (friction_force(mode, holding_force_N) if holding_force_N else 0.0), -adot))
    sol = np.linalg.solve(K, rhs)
    return sol[:5], sol[5:]


def clutch_force_index(mode: Mode, leg: int) -> int:
    """Index in lambda of the clutch constraint of leg 1 or 2 (which must be STUCK)."""
    return 2 + (2 if mode.foot_a else 0) + (1 if (leg == 2 and mode.lock1) else 0)


def damping_power(mech: Mechanics, mode: Mode, qd: np.ndarray) -> float:
    """Power dissipated by the dampers of the legs that slide, W."""
    c = mech.params.damping_ns_per_m
    l1 = 0.0 if mode.lock1 else qd[3]
    l2 = 0.0 if mode.lock2 else qd[4]
    return c * (l1 * l1 + l2 * l2)


def slip_power(mode: Mode, qd: np.ndarray, holding_force_N: float) -> float:
    """Power dissipated by slipping clutches, W."""
    p = 0.0
    for idx, st in ((L1_INDEX, mode.leg1), (L2_INDEX, mode.leg2)):
        if st in (SLIP_UP, SLIP_DOWN):
            p += holding_force_N * abs(qd[idx])
    return p


def project_velocity(mech: Mechanics, q: np.ndarray, qd: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inelastic impulse enforcing A q'+ = 0: (q'+, impulse per row, N s)."""
    M = mech.mass_matrix(q)
    minv_at = np.linalg.solve(M, A.T)
    impulse = -np.linalg.solve(A @ minv_at, A @ qd)
    qd_plus = qd + minv_at @ impulse
    return qd_plus, impulse


@dataclass(frozen=True)
class Transition:
    """The outcome of an inelastic transition that holds a locked leg (a clutch engaging, or a touchdown
    with the trailing clutch still engaged): the new velocities, which contacts remain, the impulses.

    `foot_a_lifts`: foot a leaves the ground (holding it would need a pulling impulse);
    `wheel_stopped`: both feet stay down and the rigid triangle (two pinned feet, a locked leg, the fixed
    spoke angle) stops the wheel."""

    qd_plus: np.ndarray
    mode: Mode
    impulse_b: np.ndarray  # (x, y), N s
    impulse_a: np.ndarray  # (x, y), N s; zero when foot a is (or goes) off the ground
    foot_a_lifts: bool
    wheel_stopped: bool


def inelastic_transition(mech: Mechanics, mode: Mode, q: np.ndarray, qd: np.ndarray) -> Transition:
    """Apply the constraints of `mode` impulsively at q, with contact complementarity for foot a.

    With foot a in `mode`: if the impulse holding it pushes (> 0), it stays down; otherwise foot a carries
    no impulse and the transition is redone without it (it lifts). A double-support mode with a locked
    trailing leg has no freedom: q'+ = 0 (wheel_stopped) when both feet push."""
    A, _ = constraint_rows(mech, mode, q, qd)
    qd_plus, imp = project_velocity(mech, q, qd, A)
    if mode.foot_a:
        if imp[3] > 0.0:
            stopped = mode.lock2 and np.max(np.abs(qd_plus)) < 1e-9 * (1.0 + np.max(np.abs(qd)))
            return Transition(_exact(qd_plus, mode), mode, imp[0:2], imp[2:4], False, bool(stopped))
        mode = replace(mode, foot_a=False)
        A, _ = constraint_rows(mech, mode, q, qd)
        qd_plus, imp = project_velocity(mech, q, qd, A)
        return Transition(_exact(qd_plus, mode), mode, imp[0:2], np.zeros(2), True, False)
    return Transition(_exact(qd_plus, mode), mode, imp[0:2], np.zeros(2), False, False)


def _exact(qd: np.ndarray, mode: Mode) -> np.ndarray:
    qd = qd.copy()
    qd[0] = qd[1] = 0.0
    if mode.lock1:
        qd[L1_INDEX] = 0.0
    if mode.lock2:
        qd[L2_INDEX] = 0.0
    return qd


def touchdown_with_locks(
    mech: Mechanics, q_minus: np.ndarray, qd_minus: np.ndarray, *, trailing_locked: bool
) -> tuple[ImpactResult | None, np.ndarray, np.ndarray, Transition | None]:
    """Touchdown impact: (reference impact or None, q+, q'+, locked transition or None).

    Without a locked trailing leg it is the reference impact (rimless.sim.model.impact), both legs free.
    With the old stance leg (the new trailing leg) still clutched, its rate stays 0 through the impulse
    and `inelastic_transition` decides whether foot a stays down (the wheel stops) or lifts."""
    if not trailing_locked:
        imp = impact(mech, q_minus, qd_minus)
        return imp, imp.q_plus, imp.qd_plus, None
    q_t, qd_t = relabel(q_minus, qd_minus, mech.params.leg_length_m)
    qd_t[L2_INDEX] = 0.0  # the clutched stance leg had L1' = 0 before relabelling
    tr = inelastic_transition(mech, Mode(foot_a=True, leg2=STUCK), q_t, qd_t)
    return None, q_t, tr.qd_plus, tr


def foot_a_normal_velocity(mech: Mechanics, q: np.ndarray, qd: np.ndarray) -> float:
    """Foot a's velocity along the slope normal, m/s (> 0: leaving the slope)."""
    return float(mech.jac_a(q)[1] @ qd)


def foot_a_height(q: np.ndarray) -> float:
    """Foot a's height above the slope, m."""
    return float(foot_a(q)[1])
