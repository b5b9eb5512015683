"""Integrator backends: integrate one continuous phase until a guard fires.

A backend implements `run_phase`; the hybrid logic (rimless.sim.step.hybrid) never depends on which one.
`ScipyIntegrator` (solve_ivp with a Python right-hand side) is the reference implementation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from rimless.sim.model.dynamics import accel, damping_power
from rimless.sim.model.guards import DIRECTION, FORCE_GUARDS, guard_value
from rimless.sim.model.mechanics import Mechanics


@dataclass
class PhaseRun:
    """The end of one phase: the state, which guard fired (None: the time limit), optional samples."""

    t_end: float
    y_end: np.ndarray
    guard: int | None
    nfev: int = 0
    dissipated_J: float = 0.0
    t: np.ndarray | None = None  # recorded times, s
    y: np.ndarray | None = None  # recorded states (n, 10)
    message: str = ""
    failed: bool = False


class Integrator(Protocol):
    """What the hybrid simulation needs from an integrator."""

    name: str
    rtol: float

    def run_phase(
        self,
        mech: Mechanics,
        phase: int,
        y0: np.ndarray,
        t0: float,
        guards: tuple[int, ...],
        t_max: float,
        *,
        record_dt: float | None = None,
        track_dissipation: bool = False,
    ) -> PhaseRun: ...


class _Abort(Exception):
    """Raised inside the right-hand side to stop scipy's solver (non-finite values or the evaluation budget)."""


MAX_NFEV = 2_000_000  # right-hand-side evaluations per phase before the reference backend gives up
DIP_MARGIN = 0.5  # as rimless.sim.fast.rk.DIP_MARGIN: skip a force minimum the steps resolve well
MIN_SAMPLES = 8  # dense-output samples of a normal force when looking for a dip between two solver steps


@dataclass
class ScipyIntegrator:
    """Reference backend: one of scipy's ODE solvers (DOP853 by default), stepped as solve_ivp steps it,
    with terminal event location on its dense output (brentq to 4 eps, solve_ivp's semantics).

    Two things solve_ivp does not do:
    - the normal-force guards (lift-off of foot a or b) are also located when the force dips below zero
      and recovers between two solver steps: at every discrete minimum of the force over the step ends,
      the two steps around it are re-integrated with dense output and the force minimised on it;
    - bounded work: a non-finite state or derivative, or more than `max_nfev` right-hand-side evaluations
      in one phase, ends the phase as failed (classified by the caller as an integration failure).
    """

    method: str = "DOP853"
    rtol: float = 1e-10
    atol: float = 1e-12
    max_nfev: int = MAX_NFEV
    name: str = field(init=False)

    def __post_init__(self) -> None:
        self.name = f"scipy-{self.method}"

    def run_phase(
        self,
        mech: Mechanics,
        phase: int,
        y0: np.ndarray,
        t0: float,
        guards: tuple[int, ...],
        t_max: float,
        *,
        record_dt: float | None = None,
        track_dissipation: bool = False,
    ) -> PhaseRun:
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported as a failure, not a warning
            return self._run_phase(mech, phase, y0, t0, guards, t_max, record_dt, track_dissipation)

    def _run_phase(self, mech: Mechanics, phase: int, y0: np.ndarray, t0: float, guards: tuple[int, ...],
                   t_max: float, record_dt: float | None, track_dissipation: bool) -> PhaseRun:
        from scipy.integrate import OdeSolution, solve_ivp
        from scipy.integrate._ivp.ivp import METHODS, find_active_events, solve_event_equation

        n = 10
        nfev = 0
        budget = self.max_nfev

        def fun(_t: float, y: np.ndarray) -> np.ndarray:
            nonlocal nfev
            nfev += 1
            if nfev > budget:
                raise _Abort(f"more than {budget} right-hand-side evaluations in one phase (stiff legs?)")
            qdd, _ = accel(mech, phase, y[:5], y[5:n])
            out = np.concatenate((y[5:n], qdd, [damping_power(mech, phase, y[5:n])])) if track_dissipation \
                else np.concatenate((y[5:n], qdd))
            if not math.isfinite(float(np.sum(out))):
                raise _Abort("non-finite state or forces (the state is too large or the dynamics singular)")
            return out

        def gval(code: int, y: np.ndarray) -> float:
            return guard_value(mech, phase, code, y[:n])

        events = [lambda _t, y, code=code: gval(code, y) for code in guards]
        dirs = np.array([DIRECTION[c] for c in guards], dtype=float)
        force_guards = [i for i, c in enumerate(guards) if c in FORCE_GUARDS]
        y_init = np.concatenate((y0, [0.0])) if track_dissipation else np.array(y0, dtype=float)

        def failed(t: float, y: np.ndarray, message: str) -> PhaseRun:
            return PhaseRun(t_end=float(t), y_end=np.array(y[:n]), guard=None, nfev=nfev, message=message,
                            failed=True)

        if not np.all(np.isfinite(y_init)):
            return failed(t0, y_init, "non-finite start state")
        try:
            solver = METHODS[self.method](fun, t0, y_init, t0 + t_max, rtol=self.rtol, atol=self.atol)
            g = np.array([gval(c, y_init) for c in guards])
        except _Abort as err:
            return failed(t0, y_init, str(err))
        if not np.all(np.isfinite(g)):
            return failed(t0, y_init, "non-finite guard value at the start of the phase")
        ts, interpolants = [t0], []
        hist: list[tuple[float, np.ndarray, np.ndarray]] = [(t0, y_init.copy(), g.copy())]  # last 3 step ends
        fired: int | None = None
        t_end, y_end = t0, y_init
        while True:
            try:
                solver.step()
            except _Abort as err:
                return failed(solver.t, solver.y, str(err))
            if solver.status == "failed":
                return failed(solver.t, solver.y, "the solver failed (step size too small)")
            t_old, t, y = solver.t_old, solver.t, solver.y
            sol = solver.dense_output() if record_dt is not None else None
            try:
                g_new = np.array([gval(c, y) for c in guards])
            except _Abort as err:
                return failed(t, y, str(err))
            if not np.all(np.isfinite(g_new)):
                return failed(t, y, "non-finite guard value")
            best: tuple[float, int, np.ndarray] | None = None
            active = find_active_events(g, g_new, dirs)
            if active.size:
                if sol is None:
                    sol = solver.dense_output()
                for e in active:
                    root = solve_event_equation(events[e], sol, t_old, t)
                    if best is None or root < best[0]:
                        best = (root, int(e), sol(root))
            hist.append((t, y.copy(), g_new.copy()))
            del hist[:-3]
            try:
                dip = self._force_dip(mech, phase, guards, force_guards, hist, active, solver.status == "finished",
                                      best is not None, fun, solve_ivp)
            except _Abort as err:
                return failed(t, y, str(err))
            if dip is not None and (best is None or dip[0] < best[0]):
                best = dip
            if record_dt is not None and sol is not None:
                interpolants.append(sol)
                ts.append(t)
            if best is not None:
                t_end, fired, y_end = best[0], guards[best[1]], best[2]
                break
            g = g_new
            if solver.status == "finished":
                t_end, y_end = t, y
                break
        run = PhaseRun(t_end=float(t_end), y_end=np.array(y_end[:n]), guard=fired, nfev=nfev,
                       dissipated_J=float(y_end[n]) if track_dissipation else 0.0)
        if record_dt is not None:
            dense = OdeSolution(np.array(ts), interpolants)
            steps = np.array(ts)
            grid = np.union1d(steps[steps <= t_end], np.arange(t0, t_end, record_dt))
            grid = np.union1d(grid, [t_end])
            run.t = grid
            run.y = np.atleast_2d(dense(grid)).T[:, :n] if len(grid) > 1 else np.array([y_init[:n]])
            run.y[-1] = run.y_end
        return run

    def _force_dip(self, mech: Mechanics, phase: int, guards: tuple[int, ...], force_guards: list[int],
                   hist: list, active: np.ndarray, last_step: bool, other_fired: bool,
                   fun, solve_ivp):  # noqa: ANN001, ANN202
        """The earliest time at which a normal-force guard dips through zero between step ends where it is
        positive, as (t, guard index, state), or None. Checked around every discrete minimum of the force
        over the step ends (and at the phase's first and last step)."""
        best = None
        for e in force_guards:
            if e in active:
                continue
            gs = [h[2][e] for h in hist]
            if min(gs) <= 0.0:
                continue
            if len(gs) == 3 and gs[0] > gs[1] < gs[2]:
                ts = [h[0] for h in hist]
                if _parabola_min(ts, gs) > DIP_MARGIN * gs[1]:
                    continue  # resolved by the steps: the force stays well above zero between them
                span = (hist[0], hist[2])
            elif len(gs) == 2 and gs[0] < gs[1]:
                span = (hist[0], hist[1])
            elif (last_step or other_fired) and gs[-2] > gs[-1]:
                span = (hist[-2], hist[-1])
            else:
                continue
            (ta, ya, _), (tb, _, _) = span
            sub = solve_ivp(fun, (ta, tb), ya, method=self.method, rtol=self.rtol, atol=self.atol, dense_output=True)
            if sub.status != 0:
                continue
            code = guards[e]

            def g_at(tt: float, code: int = code, sol=sub.sol) -> float:  # noqa: ANN001
                return guard_value(mech, phase, code, sol(tt)[:10])

            found = _first_dip(g_at, ta, tb)
            if found is not None and (best is None or found < best[0]):
                best = (found, e, sub.sol(found))
        return best


def _parabola_min(ts: list[float], gs: list[float]) -> float:
    """Minimum of the parabola through three (t, g) points whose middle g is below both neighbours."""
    d1 = (gs[1] - gs[0]) / (ts[1] - ts[0])
    d2 = (gs[2] - gs[1]) / (ts[2] - ts[1])
    a = (d2 - d1) / (ts[2] - ts[0])
    if not a > 0.0:
        return -np.inf
    t_min = 0.5 * (ts[0] + ts[1]) - d1 / (2.0 * a)
    return gs[1] + d1 * (t_min - ts[1]) + a * (t_min - ts[0]) * (t_min - ts[1])


def _first_dip(g_at, ta: float, tb: float) -> float | None:  # noqa: ANN001
    """The first zero crossing (downwards) of g on [ta, tb] when g(ta) > 0 dips to <= 0 inside, else None.
    g is sampled at MIN_SAMPLES interior points; the lowest sample is refined by a bounded minimisation."""
    from scipy.optimize import brentq, minimize_scalar

    ts = np.linspace(ta, tb, MIN_SAMPLES + 2)
    gs = np.array([g_at(t) for t in ts])
    neg = np.nonzero(gs <= 0.0)[0]
    if neg.size:
        t_low = ts[neg[0]]
    else:
        i = int(np.argmin(gs))
        lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, len(ts) - 1)]
        res = minimize_scalar(g_at, bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * (tb - ta)})
        if not (res.fun <= 0.0):
            return None
        t_low = float(res.x)
    if g_at(t_low) == 0.0:
        return t_low
    return float(brentq(g_at, ta, t_low, xtol=4 * np.finfo(float).eps, rtol=4 * np.finfo(float).eps))
