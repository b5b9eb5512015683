"""An independent truth of the energy-recycling (ER) wheel of docs/model.md, written apart from `rimless.sim`.

It imports nothing from `rimless.sim`, `rimless.analysis.inference` or `rimless.analysis.kinematics`; it meets the
simulator only in tests/analysis/validation/test_er_truth.py. Conventions are model.md's: slope frame (x down the
slope, y the outward normal, gravity g (sin phi, -cos phi)), theta the stance leg's angle from the normal, spoke
angle alpha = pi/4, the `eight-leg` mass model (hub m_H with inertia I_c; a point mass m at each of the 8 feet).

Formulation (projected Newton-Euler in absolute hub coordinates, derived by hand here; the simulator uses
sympy's Lagrange equations in foot-b coordinates). Coordinates r = (x_H, y_H, theta, L1, L2), m, rad:
the hub, the stance leg's angle, the stance (j = 0) and trailing (j = 1) leg lengths. Leg j points from the hub
along u_j = -(sin(theta + j alpha), cos(theta + j alpha)) with length l_j (L1, L2, else L0, rigid); its foot is
p_j = p_H + l_j u_j. With n_j = du_j/dtheta = (-cos(theta + j alpha), sin(theta + j alpha)) and dn_j/dtheta = -u_j:

    v_j = v_H + l_j theta' n_j + l_j' u_j                   (J_j: the 2x5 velocity Jacobian)
    a_j = J_j r'' + 2 l_j' theta' n_j - l_j theta'^2 u_j     (the second part: the bias b_j)

Newton for each point mass and Euler for the hub's rotation, projected on the coordinates (d'Alembert):

    M r'' + sum_j m J_j^T b_j = Q + A^T lambda,  M = m_H J_H^T J_H + I_c e_theta e_theta^T + m sum_j J_j^T J_j,
    Q = (m_H J_H + m sum_j J_j)^T g_vec - (k (L_i - L0) + c L_i' + friction_i) e_{L_i},

with the constraints A r'' + A' r' = 0: a pinned foot's acceleration is zero (rows J_j, bias b_j), a locked leg's
L'' = 0. lambda are the ground's forces on the pinned feet (their normal components: the vertical reactions)
and the locks' forces on the legs; the KKT system is solved at every evaluation.

Phases (model.md section 4): double support (feet a, b pinned) until the trailing foot's normal force falls
through 0; free single support until L1' rises through 0 (the clutch locks, maximum compression); clutched
single support until the swing foot (j = 7) touches the slope, its height y_H - L0 cos(theta - alpha) falling
through 0. Impact (model.md section 5): relabel (theta -> theta - alpha; the swing leg becomes the stance leg at
L0 with L' = 0, the old stance leg the trailing one with its length and rate, its clutch released; the old
trailing leg joins the rigid legs, snapped to L0 with zero rate), then the inelastic impact with both feet
pinned, r'+ = r'~ - M^-1 A^T (A M^-1 A^T)^-1 A r'~ (the M-orthogonal projection on the constraints: the same
law as model.md's in any coordinates). Failures raise `TruthFailure` with the reason: a stall (theta' falls
through 0), the stance foot's lift-off in single support, a touchdown before the clutch locked, a phase that
does not end.

Guide friction (F_c, N; docs/simulator.md "Guide friction"): exact Coulomb stick/slip, event-driven, on the
sliding legs (both active legs in double support and in free single support, the trailing leg when clutched):
a slipping leg feels -F_c sign(L'); a leg whose rate reaches 0 sticks (L' = 0 a constraint) if that takes a
force |lambda| <= F_c, else slips on the way the unbalanced force drives it (-sign lambda); a stuck leg slips
when |lambda| reaches F_c. In double support (one degree of freedom) a leg whose rate crosses 0 reverses its
slide. The step ends are events located by scipy's solve_ivp (DOP853).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

N_LEGS = 8
ALPHA = 2.0 * math.pi / N_LEGS
DLSP, SLSP_FREE, SLSP_CLUTCHED = "dlsp", "slsp-free", "slsp-clutched"
#: the name the coverage outputs give this truth
TRUTH_NAME = "er_truth: an ER wheel written apart from rimless.sim (Newton-Euler in hub coordinates, scipy events)"

__all__ = [
    "ALPHA",
    "ERWheel",
    "TruthFailure",
    "TruthStep",
    "TRUTH_NAME",
    "er_truth_walk",
    "fixed_point",
    "multiplier",
    "step",
]


class TruthFailure(RuntimeError):
    """A step of the truth that did not reach its impact (``reason``: stall, lift-off, ...)."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class ERWheel:
    """The wheel (SI units; model.md section 1's names). ``of`` reads any object with WheelParams' field names."""

    hub_mass_kg: float = 1.892
    leg_mass_kg: float = 0.0378
    inertia_kg_m2: float = 0.036
    leg_length_m: float = 0.237
    stiffness_n_per_m: float = 2700.0
    damping_ns_per_m: float = 8.0
    slope_rad: float = 0.05
    gravity_m_s2: float = 9.81
    guide_friction_n: float = 0.0

    @classmethod
    def of(cls, params: Any, **changes: float) -> ERWheel:
        """The wheel of ``params`` (duck-typed on the field names), with ``changes``; the eight-leg mass model only."""
        if getattr(params, "mass_model", "eight-leg") != "eight-leg":
            raise ValueError("er_truth models the eight-leg mass model only")
        kw = {f: float(getattr(params, f)) for f in cls.__dataclass_fields__}
        kw.update(changes)
        return cls(**kw)


@dataclass
class TruthStep:
    """One step from a post-impact state to the next: the post-impact state ``y_plus`` (r, r'), its period (s),
    the phase durations (s), the samples (t from the step's start, s; hub x, y in the slope frame, m; theta, rad),
    the friction work (J) and the energy the relabelling's snap of the old trailing leg added (J, model.md 8)."""

    y_plus: np.ndarray
    period_s: float
    phases: list[tuple[str, float]]
    t: np.ndarray
    hub: np.ndarray
    theta: np.ndarray
    friction_work_j: float
    snap_added_j: float


def _units(theta: float) -> tuple[np.ndarray, np.ndarray]:
    """u_j and n_j (8, 2) of every leg at stance angle theta."""
    a = theta + ALPHA * np.arange(N_LEGS)
    s, c = np.sin(a), np.cos(a)
    return np.column_stack([-s, -c]), np.column_stack([-c, s])


def _lengths(w: ERWheel, r: np.ndarray) -> np.ndarray:
    ell = np.full(N_LEGS, w.leg_length_m)
    ell[0], ell[1] = r[3], r[4]
    return ell


def _jacobians(w: ERWheel, r: np.ndarray, rd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The feet's velocity Jacobians J (8, 2, 5) and bias accelerations b (8, 2)."""
    u, n = _units(r[2])
    ell = _lengths(w, r)
    ell_d = np.zeros(N_LEGS)
    ell_d[0], ell_d[1] = rd[3], rd[4]
    J = np.zeros((N_LEGS, 2, 5))
    J[:, 0, 0] = 1.0
    J[:, 1, 1] = 1.0
    J[:, :, 2] = ell[:, None] * n
    J[0, :, 3] = u[0]
    J[1, :, 4] = u[1]
    bias = 2.0 * (ell_d * rd[2])[:, None] * n - (ell * rd[2] ** 2)[:, None] * u
    return J, bias


def _mass_matrix(w: ERWheel, J: np.ndarray) -> np.ndarray:
    M = w.leg_mass_kg * np.einsum("jai,jak->ik", J, J)
    M[0, 0] += w.hub_mass_kg
    M[1, 1] += w.hub_mass_kg
    M[2, 2] += w.inertia_kg_m2
    return M


def _gravity(w: ERWheel) -> np.ndarray:
    return w.gravity_m_s2 * np.array([math.sin(w.slope_rad), -math.cos(w.slope_rad)])


def _forces(w: ERWheel, r: np.ndarray, rd: np.ndarray, J: np.ndarray, bias: np.ndarray, slip: dict[int, int]):
    """Q - sum m J^T b: gravity, the legs' springs and dampers, the slipping legs' friction (``slip``: coordinate
    index -> +1/-1, the slide's direction)."""
    gv = _gravity(w)
    f = w.leg_mass_kg * np.einsum("jai,ja->i", J, gv[None, :] - bias)
    f[0] += w.hub_mass_kg * gv[0]
    f[1] += w.hub_mass_kg * gv[1]
    L0, k, c = w.leg_length_m, w.stiffness_n_per_m, w.damping_ns_per_m
    f[3] -= k * (r[3] - L0) + c * rd[3]
    f[4] -= k * (r[4] - L0) + c * rd[4]
    for i, s in slip.items():
        f[i] -= w.guide_friction_n * s
    return f


@dataclass(frozen=True)
class _Mode:
    """The active constraints (foot a pinned; the legs held: coordinate indices) and the slipping legs."""

    phase: str
    held: tuple[int, ...] = ()
    slip: tuple[tuple[int, int], ...] = ()


def _solve(w: ERWheel, mode: _Mode, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r'' (5,) and lambda: foot b (2), [foot a (2)], then one per held leg, in ``mode.held``'s order."""
    r, rd = y[:5], y[5:]
    J, bias = _jacobians(w, r, rd)
    M = _mass_matrix(w, J)
    f = _forces(w, r, rd, J, bias, dict(mode.slip))
    rows = [J[0]]
    rhs = [-bias[0]]
    if mode.phase == DLSP:
        rows.append(J[1])
        rhs.append(-bias[1])
    for i in mode.held:
        rows.append(np.eye(5)[i][None, :])
        rhs.append(np.zeros(1))
    A = np.vstack(rows)
    m = A.shape[0]
    K = np.zeros((5 + m, 5 + m))
    K[:5, :5] = M
    K[:5, 5:] = -A.T
    K[5:, :5] = A
    sol = np.linalg.solve(K, np.concatenate([f, *rhs]))
    return sol[:5], sol[5:]


def _held_force(mode: _Mode, lam: np.ndarray, i: int) -> float:
    base = 4 if mode.phase == DLSP else 2
    return float(lam[base + mode.held.index(i)])


def _friction_legs(phase: str) -> tuple[int, ...]:
    return (4,) if phase == SLSP_CLUTCHED else (3, 4)


def _leg_state(w: ERWheel, mode: _Mode, y: np.ndarray, i: int) -> tuple[int, _Mode]:
    """The state of friction leg ``i`` whose rate is 0 (or about to be): 0 stuck, else the slide's direction."""
    others = tuple((j, s) for j, s in mode.slip if j != i)
    if mode.phase == DLSP:  # one degree of freedom: never stuck; the slide follows the rate's sign ahead
        rdd, _ = _solve(w, _Mode(mode.phase, mode.held, others), y)
        s = 1 if rdd[i] > 0 else -1
        return s, _Mode(mode.phase, mode.held, (*others, (i, s)))
    stuck = _Mode(mode.phase, (*[h for h in mode.held if h != i], i), others)
    _, lam = _solve(w, stuck, y)
    hold = _held_force(stuck, lam, i)
    if abs(hold) <= w.guide_friction_n:
        return 0, stuck
    s = -1 if hold > 0 else 1
    return s, _Mode(mode.phase, tuple(h for h in mode.held if h != i), (*others, (i, s)))


def _enter(w: ERWheel, phase: str, y: np.ndarray, clutched_leg1: bool = False) -> _Mode:
    """The mode a phase starts in from state y: the friction legs' states from their rates."""
    mode = _Mode(phase, (3,) if clutched_leg1 else ())
    if w.guide_friction_n <= 0.0:
        return mode
    for i in _friction_legs(phase):
        v = y[5 + i]
        if abs(v) > 1e-12:
            mode = _Mode(mode.phase, mode.held, (*mode.slip, (i, 1 if v > 0 else -1)))
        elif i in mode.held:  # a stuck leg's force reached F_c: it slips the way the force drives it
            hold = _held_force(mode, _solve(w, mode, y)[1], i)
            mode = _Mode(mode.phase, tuple(h for h in mode.held if h != i), (*mode.slip, (i, -1 if hold > 0 else 1)))
        else:  # a slipping leg's rate reached 0: it sticks, or slips on (either way)
            _, mode = _leg_state(w, mode, y, i)
    return mode


def energy(w: ERWheel, y: np.ndarray) -> float:
    """T + V of a state (J): kinetic energy, gravity on every mass (world height -x sin phi + y cos phi), springs."""
    r, rd = y[:5], y[5:]
    J, _ = _jacobians(w, r, rd)
    u, _ = _units(r[2])
    feet = r[:2][None, :] + _lengths(w, r)[:, None] * u
    sp, cp = math.sin(w.slope_rad), math.cos(w.slope_rad)
    v = w.gravity_m_s2 * (
        w.hub_mass_kg * (-r[0] * sp + r[1] * cp) + w.leg_mass_kg * float(np.sum(-feet[:, 0] * sp + feet[:, 1] * cp))
    )
    v += 0.5 * w.stiffness_n_per_m * ((r[3] - w.leg_length_m) ** 2 + (r[4] - w.leg_length_m) ** 2)
    return float(0.5 * rd @ _mass_matrix(w, J) @ rd + v)


def _touchdown_height(w: ERWheel, y: np.ndarray) -> float:
    """The swing foot's (j = 7) height above the slope, m."""
    return float(y[1] - w.leg_length_m * math.cos(y[2] - ALPHA))


def _event(fun, direction: float):
    fun.terminal = True
    fun.direction = direction
    return fun


def _run_phase(w: ERWheel, mode: _Mode, y0: np.ndarray, t0: float, rtol: float, t_max: float, samples: list):
    """Integrate one phase (with its stick/slip switches) from (t0, y0) to its end event. Returns the end time,
    state, the event's name and the friction work (J)."""
    y = np.asarray(y0, float)
    t = t0
    work = 0.0
    for _ in range(2000):
        ends: list[tuple[str, Any]] = []

        def lam_of(tt, yy, mode=mode):
            return _solve(w, mode, yy)[1]

        ends.append(("stall", _event(lambda tt, yy: yy[7], -1.0)))
        if mode.phase == DLSP:
            ends.append(("liftoff", _event(lambda tt, yy: lam_of(tt, yy)[3], -1.0)))
        else:
            ends.append(("stance liftoff", _event(lambda tt, yy: lam_of(tt, yy)[1], -1.0)))
            ends.append(("touchdown", _event(lambda tt, yy: _touchdown_height(w, yy), -1.0)))
        if mode.phase == SLSP_FREE:
            ends.append(("lock", _event(lambda tt, yy: yy[8], 1.0)))
        switches: list[tuple[int, Any]] = []
        for i, s in mode.slip:
            if i == 3 and mode.phase == SLSP_FREE and s < 0:
                continue  # the stance leg's compression ends where the clutch locks it
            switches.append((i, _event(lambda tt, yy, i=i: yy[5 + i], -float(s))))
        for i in mode.held:
            if i in _friction_legs(mode.phase) and not (i == 3 and mode.phase == SLSP_CLUTCHED):
                switches.append(
                    (i, _event(lambda tt, yy, i=i, m=mode: w.guide_friction_n - abs(_held_force(m, lam_of(tt, yy), i)), -1.0))
                )  # fmt: skip
        events = [e for _, e in ends] + [e for _, e in switches]
        sol = solve_ivp(
            lambda tt, yy, mode=mode: np.concatenate([yy[5:], _solve(w, mode, yy)[0]]),
            (t, t0 + t_max),
            y,
            method="DOP853",
            rtol=rtol,
            atol=rtol * 1e-3,
            events=events,
            dense_output=True,
        )
        if sol.status == -1:
            raise TruthFailure("integration", f"solve_ivp failed in {mode.phase}: {sol.message}")
        t_end = float(sol.t[-1])
        y_end = sol.y[:, -1]
        grid = np.arange(math.ceil(t / 1e-3) * 1e-3, t_end, 1e-3)
        samples.append(
            (np.concatenate([grid, [t_end]]), np.column_stack([sol.sol(grid), y_end]) if grid.size else y_end[:, None])
        )
        work += w.guide_friction_n * sum(abs(y_end[i] - y[i]) for i, _ in mode.slip)
        fired = [k for k, te in enumerate(sol.t_events) if te.size]
        if not fired:
            raise TruthFailure("no end", f"{mode.phase} did not end within {t_max:g} s")
        k = min(fired, key=lambda k: sol.t_events[k][0])
        t, y = t_end, y_end
        if k < len(ends):
            return t, y, ends[k][0], work
        i = switches[k - len(ends)][0]
        if mode.phase == DLSP:
            mode = _Mode(mode.phase, mode.held, tuple((j, -v if j == i else v) for j, v in mode.slip))
        elif i in mode.held:  # a stuck leg's force reached F_c: it slips the way the force drives it
            hold = _held_force(mode, _solve(w, mode, y)[1], i)
            mode = _Mode(mode.phase, tuple(h for h in mode.held if h != i), (*mode.slip, (i, -1 if hold > 0 else 1)))
        else:  # a slipping leg's rate reached 0: it sticks, or slips on (either way)
            _, mode = _leg_state(w, mode, y, i)
    raise TruthFailure("chattering", f"{mode.phase}: more than 2000 stick/slip switches")


def _impact(w: ERWheel, y: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Relabel at touchdown and apply the inelastic impact with both feet pinned (model.md section 5). Returns the
    post-impact state, the energy the snap of the old trailing leg to L0 with zero rate adds (J; < 0 removes) and the ground's
    impulses on feet b and a (x, y each; N s)."""
    r, rd = y[:5].copy(), y[5:].copy()
    r_new = np.array([r[0], r[1], r[2] - ALPHA, w.leg_length_m, r[3]])
    rd_new = np.array([rd[0], rd[1], rd[2], 0.0, rd[3]])
    snap = energy(w, np.concatenate([r_new, rd_new])) - energy(w, y)
    J2, _ = _jacobians(w, r_new, rd_new)
    M = _mass_matrix(w, J2)
    A = np.vstack([J2[0], J2[1]])
    Minv_At = np.linalg.solve(M, A.T)
    impulse = np.linalg.solve(A @ Minv_At, A @ rd_new)
    rd_plus = rd_new - Minv_At @ impulse
    return np.concatenate([r_new, rd_plus]), snap, -impulse


def state_from_section(w: ERWheel, z: np.ndarray, foot_b_x_m: float = 0.0) -> np.ndarray:
    """The post-impact state (r, r') of z = (theta+ rad, theta'+ rad/s): foot b at (foot_b_x_m, 0), L1 = L0, L2
    with foot a on the slope, the velocities the double support's one freedom scaled by theta'."""
    th, thd = float(z[0]), float(z[1])
    L0 = w.leg_length_m
    L2 = L0 * math.cos(th) / math.cos(th + ALPHA)
    r = np.array([foot_b_x_m + L0 * math.sin(th), L0 * math.cos(th), th, L0, L2])
    J, _ = _jacobians(w, r, np.zeros(5))
    A = np.vstack([J[0], J[1]])
    _, _, vt = np.linalg.svd(A)
    v = vt[-1]
    return np.concatenate([r, v * thd / v[2]])


def step(w: ERWheel, y0: np.ndarray, *, rtol: float = 1e-10, t_max: float = 3.0) -> TruthStep:
    """One ER step from the post-impact state y0 = (r, r') (10,) through the next impact."""
    samples: list = []
    phases: list[tuple[str, float]] = []
    t, y, work = 0.0, np.asarray(y0, float), 0.0
    if not y[7] > 0.0:
        raise TruthFailure("stall", "theta' <= 0 at the start of the step")
    if _solve(w, _enter(w, DLSP, y), y)[1][3] > 0.0:  # else double support ends at once (foot a unloaded)
        t, y, why, wk = _run_phase(w, _enter(w, DLSP, y), y, t, rtol, t_max, samples)
        work += wk
        if why != "liftoff":
            raise TruthFailure(why, f"double support ended by {why} at {t:.4f} s")
    phases.append((DLSP, t))
    if not y[8] < 0.0:
        raise TruthFailure("clutch missed", f"L1' = {y[8]:.3g} m/s >= 0 at lift-off: no compression left to lock")
    if not _solve(w, _enter(w, SLSP_FREE, y), y)[1][1] > 0.0:
        raise TruthFailure("stance liftoff", "the stance foot is unloaded at the start of single support")
    t, y2, why, wk = _run_phase(w, _enter(w, SLSP_FREE, y), y, t, rtol, t_max, samples)
    work += wk
    phases.append((SLSP_FREE, t - phases[-1][1]))
    if why == "touchdown":
        raise TruthFailure("touchdown before lock", f"touchdown before the clutch locked at {t:.4f} s")
    if why != "lock":
        raise TruthFailure(why, f"free single support ended by {why} at {t:.4f} s")
    y2 = y2.copy()
    y2[8] = 0.0  # the lock: L1' = 0 exactly (the event's root)
    t_lock = t
    t, y3, why, wk = _run_phase(w, _enter(w, SLSP_CLUTCHED, y2, clutched_leg1=True), y2, t, rtol, t_max, samples)
    work += wk
    phases.append((SLSP_CLUTCHED, t - t_lock))
    if why != "touchdown":
        raise TruthFailure(why, f"clutched single support ended by {why} at {t:.4f} s")
    y_plus, snap, impulse = _impact(w, y3)
    if not (impulse[1] > 0.0 and impulse[3] > 0.0):
        raise TruthFailure("negative impulse", f"normal impulses b {impulse[1]:.4g}, a {impulse[3]:.4g} N s")
    ts = np.concatenate([s[0] for s in samples])
    ys = np.concatenate([s[1] for s in samples], axis=1)
    return TruthStep(y_plus, t, phases, ts, ys[:2].T, ys[2], work, snap)


def section(y: np.ndarray) -> np.ndarray:
    """z = (theta, theta') of a post-impact state."""
    return np.array([y[2], y[7]])


def step_map(w: ERWheel, z: np.ndarray, *, rtol: float = 1e-10) -> np.ndarray:
    """The Poincaré map of model.md section 6 (post-impact z -> next post-impact z)."""
    return section(step(w, state_from_section(w, z), rtol=rtol).y_plus)


def fixed_point(w: ERWheel, guess: np.ndarray | None = None, *, rtol: float = 1e-10, tol: float = 1e-9) -> np.ndarray:
    """The period-1 gait's z = (theta+, theta'+) by Newton's method on P(z) - z (central-difference Jacobian,
    steps 1e-6 rad and 1e-6 rad/s; a step into a failing map is halved), from ``guess`` or theta+ = -alpha/2 -
    0.06 rad (the trailing leg compressed) and the rigid wheel's gait speed (M = m_H + 8 m, I = I_c + 8 m L0^2),
    raised 15 % at a time while the map stalls from it."""
    if guess is None:
        m_all = w.hub_mass_kg + N_LEGS * w.leg_mass_kg
        i_foot = w.inertia_kg_m2 + N_LEGS * w.leg_mass_kg * w.leg_length_m**2 + m_all * w.leg_length_m**2
        beta = 1.0 - m_all * w.leg_length_m**2 * (1.0 - math.cos(ALPHA)) / i_foot
        gain = 4 * m_all * w.gravity_m_s2 * w.leg_length_m / i_foot * math.sin(w.slope_rad) * math.sin(ALPHA / 2)
        guess = np.array([-ALPHA / 2 - 0.06, math.sqrt(max(beta**2 * gain / (1 - beta**2), 0.25))])
    z = np.asarray(guess, float)
    for _ in range(12):
        try:
            pz = step_map(w, z, rtol=rtol)
            break
        except TruthFailure:
            z = z * np.array([1.0, 1.15])
    else:
        raise TruthFailure("no gait", f"the step map fails from {guess} and from faster starts")
    for _ in range(30):
        res = pz - z
        if np.max(np.abs(res)) < tol:
            return z
        jac = np.zeros((2, 2))
        for j, h in enumerate((1e-6, 1e-6)):
            dz = np.zeros(2)
            dz[j] = h
            jac[:, j] = (step_map(w, z + dz, rtol=rtol) - step_map(w, z - dz, rtol=rtol)) / (2 * h)
        dz = np.linalg.solve(jac - np.eye(2), res)
        for _ in range(6):
            try:
                pz = step_map(w, z - dz, rtol=rtol)
                z = z - dz
                break
            except TruthFailure:
                dz = dz / 2
        else:
            break
    raise TruthFailure("no gait", f"no period-1 gait found from {guess} (last residual {np.max(np.abs(res)):.2e})")


@functools.lru_cache(maxsize=32)
def _gait(w: ERWheel, rtol: float) -> tuple[float, float]:
    """`fixed_point` from its default guess, kept per wheel (a walk's truth is released from it; the same wheel's
    walks of a coverage study share it). A tuple: the cached value cannot be changed by a caller."""
    z = fixed_point(w, rtol=rtol)
    return float(z[0]), float(z[1])


def multiplier(w: ERWheel, z: np.ndarray | None = None, *, rtol: float = 1e-11, h: float = 1e-5) -> float:
    """The dominant Floquet multiplier of the period-1 gait (model.md section 6): the eigenvalue of largest modulus
    of the step map's Jacobian at the fixed point ``z`` (default: `fixed_point` of ``w`` at ``rtol``), by central
    differences of ``h`` rad and rad/s (the map's error rtol / h ~ 1e-6, the differences' h^2 ~ 1e-10). Real when
    the dominant pair is real (the ER gait's), else its modulus (as `trials floquet` states a multiplier)."""
    z = fixed_point(w, rtol=rtol) if z is None else np.asarray(z, float)
    jac = np.zeros((2, 2))
    for j in range(2):
        dz = np.zeros(2)
        dz[j] = h
        jac[:, j] = (step_map(w, z + dz, rtol=rtol) - step_map(w, z - dz, rtol=rtol)) / (2 * h)
    ev = np.linalg.eigvals(jac)
    dom = ev[int(np.argmax(np.abs(ev)))]
    return float(dom.real) if abs(dom.imag) < 1e-12 else float(abs(dom))


def er_truth_walk(
    params: Any, slope_deg: float, slope_sd_deg: float, steps: int, rng: np.random.Generator, *, release: float = 1.0,
    rtol: float = 1e-9,
):  # fmt: skip
    """``steps`` impacts of this truth's ER wheel (``params``: any object with WheelParams' fields) released from
    its own gait at ``slope_deg`` with theta'+ times ``release``; each step's slope drawn N(slope, slope_sd^2)
    (one standard normal of ``rng`` a step, drawn as `floquet_truth.er_walk` draws: the same seed, the same
    slopes), the gravity's direction per step (Byl and Tedrake's rough slope; the recorded geometry stays on the
    nominal slope). A `floquet_truth.Walk` (the hub in the slope frame, the body angle; the data stop 40 % into
    the last step, or at the last impact after a stall past the second impact; ``step_slope_deg``: the slope each
    step walked, deg), as `floquet_truth.er_walk` gives."""
    from rimless.analysis.validation.floquet_truth import assemble_walk

    w0 = ERWheel.of(params, slope_rad=math.radians(slope_deg))
    z = np.array(_gait(w0, rtol))
    y = state_from_section(w0, z * np.array([1.0, release]))
    t0 = 0.0
    T: list[np.ndarray] = []
    X: list[np.ndarray] = []
    H: list[np.ndarray] = []
    B: list[np.ndarray] = []
    impacts: list[float] = []
    speeds: list[float] = []
    slopes: list[float] = []
    for k in range(steps + 1):
        slope_k = slope_deg + slope_sd_deg * float(rng.standard_normal())
        w = ERWheel.of(params, slope_rad=math.radians(slope_k))
        try:
            st = step(w, y, rtol=rtol)
        except TruthFailure:
            if len(impacts) < 2:
                raise
            return assemble_walk(T, X, H, B, impacts, speeds, slope_deg, stalled=True, step_slopes=slopes)
        slopes.append(slope_k)
        T.append(t0 + st.t)
        X.append(st.hub[:, 0])
        H.append(st.hub[:, 1])
        B.append(st.theta + ALPHA / 2 + k * ALPHA)
        t0 += st.period_s
        y = st.y_plus
        if k < steps:
            impacts.append(t0)
            speeds.append(float(y[7]))
    return assemble_walk(T, X, H, B, impacts, speeds, slope_deg, step_slopes=slopes)
