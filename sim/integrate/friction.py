"""One continuous phase with guide friction: its stick/slip sub-phases run one after the other.

`run_with_friction` integrates base phase `base` (rimless.sim.model.dynamics) of a wheel with
guide_friction_n > 0 as a sequence of friction phases (rimless.sim.model.friction): each runs with any
integrator (the reference or the compiled one; both take friction phase codes) until one of the base guards
or a stick/slip guard of the one guard table fires (located by the same event rules, with strict crossings:
a guard starting at exactly 0 does not fire at once). A stick/slip guard switches the legs' states
(`friction.switch`) and the phase goes on; a base guard or the time limit ends it. The result is one PhaseRun
over the whole base phase: end state, base guard, damper loss, friction work (F_c x the distance slid) and the
time each leg was stuck. In free compression of the ER wheel the stance leg's slip ends where the clutch
locks it (CLUTCH_LOCK, L1' rising through 0): that guard alone ends the slide, so a tie cannot leave the leg
stuck by friction with the clutch's guard sitting at exactly 0.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rimless.sim.integrate.reference import PhaseRun
from rimless.sim.model import friction as fr
from rimless.sim.model.guards import CLUTCH_LOCK, SLIP_END_1
from rimless.sim.model.mechanics import Mechanics


def run_with_friction(
    integrator: Any,
    mech: Mechanics,
    base: int,
    y0: np.ndarray,
    t0: float,
    guards: tuple[int, ...],
    t_max: float,
    *,
    record_dt: float | None = None,
    track_dissipation: bool = False,
) -> PhaseRun:
    """Integrate base phase `base` with guide friction from (t0, y0) until a guard of `guards` fires or
    t0 + t_max is reached (one PhaseRun; `failed` with a message on chattering or an integrator failure)."""
    F = mech.params.guide_friction_n
    code, y = fr.initial_phase(mech, base, np.asarray(y0, dtype=float))
    t = float(t0)
    t_stop = t0 + t_max
    nfev = 0
    dissipated = 0.0
    work = 0.0
    stick = [0.0, 0.0]
    ts: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    for _ in range(fr.MAX_SWITCHES):
        # where the clutch locks the stance leg at L1' = 0 (CLUTCH_LOCK), its slip end is that guard's business
        own = tuple(g for g in fr.friction_guards(code) if not (g == SLIP_END_1 and CLUTCH_LOCK in guards))
        run = integrator.run_phase(
            mech, code, y, t, tuple(guards) + own, t_stop - t, record_dt=record_dt, track_dissipation=track_dissipation
        )
        nfev += run.nfev
        dissipated += run.dissipated_J
        work += fr.slide_work(code, y, run.y_end, F)
        _, s1, s2 = fr.decode(code)
        for i, (leg, st) in enumerate(((1, s1), (2, s2))):
            if st == fr.STUCK and leg in fr.friction_legs(base):
                stick[i] += run.t_end - t
        if run.t is not None and run.y is not None:
            ts.append(run.t)
            ys.append(run.y)
        out = PhaseRun(
            t_end=run.t_end,
            y_end=run.y_end,
            guard=run.guard,
            nfev=nfev,
            dissipated_J=dissipated,
            friction_J=work,
            stick_s=(stick[0], stick[1]),
            message=run.message,
            failed=run.failed,
        )
        if run.failed or run.guard is None or run.guard not in own:
            if run.guard in own:
                out.guard = None
            if ts:
                out.t, out.y = _joined(ts, ys)
            return out
        code, y = fr.switch(mech, code, run.guard, run.y_end)
        t = run.t_end
    out.failed = True
    out.guard = None
    out.message = (
        f"guide friction: more than {fr.MAX_SWITCHES} stick/slip switches in one phase (chattering; F_c = {F} N)"
    )
    return out


def _joined(ts: list[np.ndarray], ys: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Samples of consecutive sub-phases in one array, the repeated switch instants dropped."""
    t_all = [ts[0]]
    y_all = [ys[0]]
    for t, y in zip(ts[1:], ys[1:]):
        keep = t > t_all[-1][-1]
        t_all.append(t[keep])
        y_all.append(y[keep])
    return np.concatenate(t_all), np.concatenate(y_all)
