"""Integrator backends: integrate one continuous phase until a guard fires.

A backend implements `run_phase`; the hybrid logic (rimless.sim.hybrid) never depends on which one.
`ScipyIntegrator` (solve_ivp with a Python right-hand side) is the reference implementation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from rimless.sim.dynamics import accel, damping_power
from rimless.sim.events import DIRECTION, guard_value
from rimless.sim.model import Mechanics


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


@dataclass
class ScipyIntegrator:
    """Reference backend: scipy.integrate.solve_ivp (DOP853 by default) with event location."""

    method: str = "DOP853"
    rtol: float = 1e-10
    atol: float = 1e-12
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
        from scipy.integrate import solve_ivp

        n = 10

        def fun(_t: float, y: np.ndarray) -> np.ndarray:
            qdd, _ = accel(mech, phase, y[:5], y[5:n])
            if track_dissipation:
                return np.concatenate((y[5:n], qdd, [damping_power(mech, phase, y[5:n])]))
            return np.concatenate((y[5:n], qdd))

        events = []
        for code in guards:

            def ev(_t: float, y: np.ndarray, code: int = code) -> float:
                return guard_value(mech, phase, code, y[:n])

            ev.terminal = True  # type: ignore[attr-defined]
            ev.direction = DIRECTION[code]  # type: ignore[attr-defined]
            events.append(ev)
        y_init = np.concatenate((y0, [0.0])) if track_dissipation else np.asarray(y0, dtype=float)
        sol = solve_ivp(
            fun, (t0, t0 + t_max), y_init, method=self.method, rtol=self.rtol, atol=self.atol,
            events=events, dense_output=record_dt is not None,
        )
        if sol.status == -1:
            return PhaseRun(t_end=float(sol.t[-1]), y_end=sol.y[:n, -1], guard=None, nfev=sol.nfev,
                            message=sol.message, failed=True)
        fired = None
        t_end, y_end = float(sol.t[-1]), sol.y[:, -1]
        if sol.status == 1:
            hits = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te)]
            t_hit, i_hit = min(hits)
            fired = guards[i_hit]
            t_end, y_end = float(sol.t_events[i_hit][0]), sol.y_events[i_hit][0]
        run = PhaseRun(t_end=t_end, y_end=np.array(y_end[:n]), guard=fired, nfev=sol.nfev,
                       dissipated_J=float(y_end[n]) if track_dissipation else 0.0)
        if record_dt is not None:
            grid = np.union1d(sol.t[sol.t <= t_end], np.arange(t0, t_end, record_dt))
            grid = np.union1d(grid, [t_end])
            run.t = grid
            run.y = sol.sol(grid)[:n].T
            run.y[-1] = run.y_end
        return run
