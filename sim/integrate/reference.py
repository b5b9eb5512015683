"""Integrator backends: integrate one continuous phase until a guard fires.

A backend implements `run_phase`; the hybrid logic (rimless.sim.step.hybrid) never depends on which one.
`ScipyIntegrator` (solve_ivp with a Python right-hand side) is the reference implementation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.integrate import BDF, DOP853, LSODA, RK23, RK45, Radau

from rimless.sim.integrate.events import EventLocator, NonFiniteGuard
from rimless.sim.model import friction as fr
from rimless.sim.model.dynamics import accel, damping_power
from rimless.sim.model.guards import guard_value
from rimless.sim.model.mechanics import Mechanics


@dataclass
class PhaseRun:
    """The end of one phase: the state, which guard fired (None: the time limit), optional samples."""

    t_end: float
    y_end: np.ndarray
    guard: int | None
    nfev: int = 0
    dissipated_J: float = 0.0
    friction_J: float = 0.0  # guide-friction work over the phase (rimless.sim.integrate.friction), J
    stick_s: tuple[float, float] = (0.0, 0.0)  # time legs 1 and 2 were stuck by guide friction, s
    t: np.ndarray | None = None  # recorded times, s
    y: np.ndarray | None = None  # recorded states (n, 10)
    message: str = ""
    failed: bool = False


class Integrator(Protocol):
    """What the hybrid simulation needs from an integrator."""

    @property
    def name(self) -> str: ...

    @property
    def rtol(self) -> float: ...

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
SOLVERS = {"RK23": RK23, "RK45": RK45, "DOP853": DOP853, "Radau": Radau, "BDF": BDF, "LSODA": LSODA}


@dataclass
class ScipyIntegrator:
    """Reference backend: one of scipy's ODE solvers (DOP853 by default, public `scipy.integrate` classes),
    stepped as solve_ivp steps it, with the guards located by rimless.sim.integrate.events (solve_ivp's
    semantics: brentq to 4 eps on the dense output).

    Two things solve_ivp does not do:
    - the normal-force guards (lift-off of foot a or b) are also located when the force dips below zero
      and recovers between two solver steps (events.EventLocator); the span around a discrete minimum of
      the force is re-integrated with dense output for that search;
    - bounded work: a non-finite state or derivative, or more than `max_nfev` right-hand-side evaluations
      in one phase, ends the phase as failed (classified by the caller as an integration failure).

    `phase` is a base phase of rimless.sim.model.dynamics or a guide-friction stick/slip phase of
    rimless.sim.model.friction (codes >= FRICTION_PHASE0: its dynamics and guards, strict crossings), which
    rimless.sim.integrate.friction runs one after the other.
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

    def _run_phase(
        self,
        mech: Mechanics,
        phase: int,
        y0: np.ndarray,
        t0: float,
        guards: tuple[int, ...],
        t_max: float,
        record_dt: float | None,
        track_dissipation: bool,
    ) -> PhaseRun:
        from scipy.integrate import OdeSolution, solve_ivp

        n = 10
        nfev = 0
        budget = self.max_nfev
        friction = fr.is_friction_phase(phase)  # a stick/slip phase of guide friction (strict crossings)
        accel_of, power_of, guard_of = (
            (fr.accel, fr.damping_power, fr.guard_value) if friction else (accel, damping_power, guard_value)
        )

        def fun(_t: float, y: np.ndarray) -> np.ndarray:
            nonlocal nfev
            nfev += 1
            if nfev > budget:
                raise _Abort(f"more than {budget} right-hand-side evaluations in one phase (stiff legs?)")
            qdd, _ = accel_of(mech, phase, y[:5], y[5:n])
            out = (
                np.concatenate((y[5:n], qdd, [power_of(mech, phase, y[5:n])]))
                if track_dissipation
                else np.concatenate((y[5:n], qdd))
            )
            if not math.isfinite(float(np.sum(out))):
                raise _Abort("non-finite state or forces (the state is too large or the dynamics singular)")
            return out

        def dense_on(ta: float, ya: np.ndarray, tb: float):
            """The span re-integrated with dense output (for the force-dip search)."""
            sub = solve_ivp(fun, (ta, tb), ya, method=self.method, rtol=self.rtol, atol=self.atol, dense_output=True)
            return sub.sol if sub.status == 0 else None

        y_init = np.concatenate((y0, [0.0])) if track_dissipation else np.array(y0, dtype=float)

        def failed(t: float, y: np.ndarray, message: str) -> PhaseRun:
            return PhaseRun(t_end=float(t), y_end=np.array(y[:n]), guard=None, nfev=nfev, message=message, failed=True)

        if not np.all(np.isfinite(y_init)):
            return failed(t0, y_init, "non-finite start state")
        try:
            solver = SOLVERS[self.method](fun, t0, y_init, t0 + t_max, rtol=self.rtol, atol=self.atol)
            locator = EventLocator(
                guards,
                lambda code, y: guard_of(mech, phase, code, y[:n]),
                t0,
                y_init,
                dense_on=dense_on,
                strict=friction,
            )
        except _Abort as err:
            return failed(t0, y_init, str(err))
        except NonFiniteGuard:
            return failed(t0, y_init, "non-finite guard value at the start of the phase")
        ts, interpolants = [t0], []
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
                best = locator.step(
                    t_old,
                    t,
                    y,
                    lambda: sol if sol is not None else solver.dense_output(),  # noqa: B023
                    last_step=solver.status == "finished",
                )
            except (_Abort, NonFiniteGuard) as err:
                return failed(t, y, str(err))
            if record_dt is not None and sol is not None:
                interpolants.append(sol)
                ts.append(t)
            if best is not None:
                t_end, fired, y_end = best[0], guards[best[1]], best[2]
                break
            if solver.status == "finished":
                t_end, y_end = t, y
                break
        run = PhaseRun(
            t_end=float(t_end),
            y_end=np.array(y_end[:n]),
            guard=fired,
            nfev=nfev,
            dissipated_J=float(y_end[n]) if track_dissipation else 0.0,
        )
        if record_dt is not None:
            dense = OdeSolution(np.array(ts), interpolants)
            steps = np.array(ts)
            grid = np.union1d(steps[steps <= t_end], np.arange(t0, t_end, record_dt))
            grid = np.union1d(grid, [t_end])
            run.t = grid
            run.y = np.atleast_2d(dense(grid)).T[:, :n] if len(grid) > 1 else np.array([y_init[:n]])
            run.y[-1] = run.y_end
        return run
