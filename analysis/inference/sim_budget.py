"""The simulation budget of one calibration: a bound on the walks and step maps it runs, and what it stopped.

`rimless.analysis.inference.calibrate.calibrate` counts every simulation (a recorded walk or a step map; a
cached walk is free) against one `SimulationBudget`, shared by its passes (`rimless.analysis.api.slope_passes`)
and the whole recalibrations of the held parameters' refits. The budget keeps a reserve for the closing stages,
whose cost is fixed by the problem's size (`closing_reserve`: the central Jacobian at the solution, the slopes'
walks, the adequacy check's, the minima's costs), so that the result always has its uncertainties; the
search stages (the least squares from each start, the first-angle offsets, the minima's re-solves, the polish,
the held parameters' refits, the model choice, the held-exact probe) stop or are skipped when the rest is spent.
What was stopped is stated (`SimulationBudget.as_dict`, JSON ``budget``) and turned into the affected estimates'
status by the caller: never a silent truncation.

On a wheel the model cannot fit (stated by the calibration's start, `calibrate._misfit_at_start`), the search is
capped further (`SimulationBudget.cap_search`): its estimates are effective only whatever it finds, so a few
hundred simulations settle what hours would not change; the cap is stated beside the budget (``misfit``,
``search_cap``, ``stopped_by``).

``used`` counts every simulation of the command (all slope passes, the held parameters' whole recalibrations);
the calibration result's ``simulations`` (JSON) counts the kept calibration's own (``own``), as before.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

__all__ = ["DEFAULT_MAX_SIMULATIONS", "BudgetSpent", "SimulationBudget", "closing_reserve"]

#: simulations one calibration may run unless told otherwise (`calibrate(max_simulations=...)`,
#: `trials calibrate --max-simulations`): a bound on a runaway, not a setting of the fit. A calibration of c and
#: F_c on four trials with five held parameters carried runs about 3000 (docs/trials.md, "Bounded work"); a held
#: parameter whose warm refit sticks adds a whole recalibration (up to two per held parameter, each about the
#: search's 1000-2500), so the worst such case is near 30000: this is above it.
DEFAULT_MAX_SIMULATIONS = 50000


class BudgetSpent(Exception):
    """Raised by a simulation that the budget does not allow; the stage that runs it stops there."""


def closing_reserve(n_trials: int, n_globals: int, n_starts: int = 4) -> int:
    """The simulations the closing stages run at most, by the stage structure, counting each residual evaluation
    of a trial as two walks (`calibrate._residuals` walks again, longer, when the simulated walk is faster than
    the measured window): the minima's costs with the kept offsets (one evaluation per trial per start, at most
    ``n_starts``), the central Jacobian (per trial: the evaluation at the solution, two per global, one for the
    release speed; the shift is interpolated on the cached walk), the slopes' evaluations at +-1 sd (two per
    trial), the loss separation's walk (one per trial), the adequacy check's (release speed and first angle at
    +-, four per trial; the shift interpolated, the slopes' walks reused), and as much again for walks the cache
    let go: 2 n_trials (n_starts + 10 + 2 n_globals)."""
    return 2 * n_trials * (n_starts + 10 + 2 * n_globals)


@dataclass
class SimulationBudget:
    """At most ``max_simulations`` simulations (None: no bound); ``used`` so far. During the search the limit
    is ``max_simulations - reserve`` (`search`); the closing stages run within the whole (`closing`)."""

    max_simulations: int | None
    used: int = 0
    reserve: int = 0
    stage: str = "start"
    #: the stage the first refused simulation was in (None while the budget holds)
    stopped_in: str | None = None
    #: the stages stopped or skipped for the budget, in order, each with what it means for the result
    skipped: list[dict[str, str]] = field(default_factory=list)
    on_stage: Callable[[str], None] | None = None
    #: put before the stages' names (a held parameter's whole recalibration names its stages as its)
    prefix: str = ""
    #: the statement that the model does not fit these trials (None: not stated), and the count at which the
    #: search stops for it (`cap_search`; the closing stages keep the reserve above it)
    misfit: str | None = None
    search_cap: int | None = None
    #: the misfit's short form, shown beside every stage on the progress line once stated (`shown`)
    misfit_brief: str | None = None
    #: what refused the first simulation: "budget" or "misfit cap" (None while neither did)
    stopped_by: str | None = None
    #: the kept calibration's own simulations (the result's ``simulations``), when the caller set it
    own: int | None = None
    _closing: int = 0

    @property
    def spent(self) -> bool:
        return self.stopped_in is not None

    def limit(self) -> int | None:
        whole = self.max_simulations
        if self._closing:
            return whole
        search = None if whole is None else whole - self.reserve
        if self.search_cap is not None and (search is None or self.search_cap < search):
            return self.search_cap
        return search

    def spend(self) -> None:
        """Count one simulation, or raise `BudgetSpent` (recording the stage) when the limit is reached."""
        lim = self.limit()
        if lim is not None and self.used >= lim:
            if self.stopped_in is None:
                self.stopped_in = self.stage
                capped = not self._closing and self.search_cap is not None and lim == self.search_cap
                self.stopped_by = "misfit cap" if capped else "budget"
            raise BudgetSpent(self.stage)
        self.used += 1

    def cap_search(self, simulations: int, misfit: str, brief: str | None = None) -> None:
        """The model does not fit these trials (``misfit``, the statement; ``brief``, its short form for the
        progress line): the search may run ``simulations`` more (never beyond the budget's own limit); the
        closing stages keep their reserve. The progress line says so from now on (`shown`)."""
        self.misfit = misfit
        if self.search_cap is None:
            self.search_cap = self.used + simulations
        self.misfit_brief = (brief or "the model does not fit these trials") + (
            f"; effective only, search capped at {self.search_cap} simulations"
        )
        if self.on_stage:
            self.on_stage(self.shown())

    def shown(self) -> str:
        """The stage as ``on_stage`` (the progress line) gets it: its name, then the misfit's short form in
        brackets once the start stated one (`cap_search`). ``stage``, ``stopped_in`` and the JSON keep the name."""
        return self.stage + (f" [{self.misfit_brief}]" if self.misfit_brief else "")

    def enter(self, name: str) -> None:
        """The calibration reached stage ``name`` (progress shows it, `shown`)."""
        self.stage = self.prefix + name
        if self.on_stage:
            self.on_stage(self.shown())

    def skip(self, what: str, consequence: str) -> None:
        """Record that ``what`` was stopped or not run for the budget, and what that means for the result."""
        if self.stopped_in is None:
            self.stopped_in = self.stage
            self.stopped_by = "budget"
        self.skipped.append({"stage": what, "consequence": consequence})

    @contextlib.contextmanager
    def closing(self) -> Iterator[None]:
        """Within the block the whole budget counts (the reserve is for these stages)."""
        self._closing += 1
        try:
            yield
        finally:
            self._closing -= 1

    @contextlib.contextmanager
    def searching(self) -> Iterator[None]:
        """Within the block only the search's part counts (a search stage run from within a closing one)."""
        closing, self._closing = self._closing, 0
        try:
            yield
        finally:
            self._closing = closing

    def as_dict(self) -> dict[str, Any]:
        """JSON ``budget``: ``max_simulations`` (null: no bound), ``used`` (every simulation of the command: the
        passes', the recalibrations'), ``reserve`` (kept for the closing stages), ``stopped_in`` (null when nothing
        was stopped), ``stopped_by`` (``"budget"``, ``"misfit cap"`` or null), ``skipped``, ``misfit`` (the
        statement that the model does not fit these trials, or null) with ``search_cap`` (the count the search
        stopped at for it, or null), and a ``statement``."""
        return {
            "max_simulations": self.max_simulations,
            "used": self.used,
            "reserve": self.reserve,
            "stopped_in": self.stopped_in,
            "stopped_by": self.stopped_by,
            "skipped": list(self.skipped),
            "misfit": self.misfit,
            "search_cap": self.search_cap,
            "statement": self.statement(),
        }

    def statement(self) -> str:
        bound = f"of at most {self.max_simulations}" if self.max_simulations is not None else "(no bound)"
        own = (
            f" (JSON simulations, {self.own}, counts the kept calibration's own)"
            if self.own is not None and self.own != self.used
            else ""
        )
        misfit = (
            f"{self.misfit}; the search was capped at {self.search_cap} simulations for it: " if self.misfit else ""
        )
        if not self.spent:
            return f"{misfit}{self.used} simulations {bound} in all{own}; every stage ran"
        parts = "; ".join(f"{s['stage']}: {s['consequence']}" for s in self.skipped)
        ran_out = "the search reached its cap" if self.stopped_by == "misfit cap" else "the simulation budget ran out"
        return f"{misfit}{ran_out}: {self.used} simulations {bound} in all{own}, stopped in {self.stopped_in}" + (
            f"; {parts}" if parts else ""
        )
