"""The calibration in passes when it fits k: the trials' slopes imported again with the fitted legs.

The importer sizes each trial's slope interval with the legs' drift, sqrt(m / k) times the trial's change of
impact speed (`rimless.analysis.kinematics.slope_evidence.leg_compliance`). A calibration that fits k cannot tell
the importer k first: its first pass imports with the importer's bound (`UNKNOWN_LEG_TIME_S`, 45 ms, the
heaviest wheel on the softest legs it is validated on), so every slope interval is as wide as for that wheel,
and the calibration carries them (`se_slope`). Each further pass imports the same files again told the previous
pass's fitted k with its standard error (with the held parameters' part; `leg_compliance` sizes the drift on
E[m/k] over that spread, as for a stated k), and calibrates again on them from the wheel input's values (the same search, only the slopes differ).
The passes stop when the re-imported slopes' intervals no longer change (`SLOPE_PASS_RTOL`), after
`MAX_SLOPE_PASSES` calibrations, when the fit did not determine k, or when a trial cannot be imported again.

k comes from the same trials whose slopes it sizes: its spread, not only its value, is handed on. JSON ``slope_passes`` says what was done (`SlopePasses`).
Each pass runs its own held-exact probe (`rimless.analysis.inference.calibrate._held_exact_probe`): each
``history`` row carries its pass's (``held_exact_probe``, None when none ran, also on a pass the budget cut and
that was not kept); the result's ``held_exact_probe`` is the kept pass's, its ``pass`` named there and in
``slope_passes.held_exact_probe_pass``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

from rimless.analysis.inference.calibrate import CalibrationResult, NoTrialCalibrated
from rimless.analysis.inference.sim_budget import DEFAULT_MAX_SIMULATIONS
from rimless.errors import RimlessError

__all__ = ["MAX_SLOPE_PASSES", "SLOPE_PASS_RTOL", "CalibrationInPasses", "calibrate_in_passes", "IMPORTED"]

#: at most this many calibrations when k is fitted (the first on slopes imported with the importer's bound)
MAX_SLOPE_PASSES = 3
#: the slopes' intervals have stopped changing when, on every trial, the half width and the slope moved by at
#: most this fraction of the previous half width
SLOPE_PASS_RTOL = 0.05
#: ``first_legs`` for trials handed over already imported (`Trial` objects, .parquet): how is not known here
IMPORTED = "imported"

Z95 = 1.959963984540054
K_FIELD = "stiffness_n_per_m"


@dataclass
class CalibrationInPasses(CalibrationResult):
    """A `CalibrationResult` with ``slope_passes``: the passes run and the legs each import was told."""

    slope_passes: dict[str, Any] = field(default_factory=dict)
    #: the trials the kept pass calibrated on (their slopes re-imported or not), in the order of ``names``
    trials: list[Any] = field(default_factory=list, repr=False)

    def summary(self) -> dict[str, Any]:
        return {**super().summary(), "slope_passes": self.slope_passes}


def _slopes(trials: Sequence[Any], names: Sequence[str]) -> list[dict[str, Any]]:
    """Each trial's slope and 95 % interval as imported, deg."""
    out = []
    for t, n in zip(trials, names):
        lo, hi = (math.degrees(v) for v in t.meta.slope_ci_rad)
        ok = math.isfinite(lo) and math.isfinite(hi)
        out.append({"trial": n, "slope_deg": float(t.meta.slope_deg), "ci95_deg": [lo, hi] if ok else None})
    return out


def _half(row: dict[str, Any]) -> float:
    ci = row["ci95_deg"]
    return (ci[1] - ci[0]) / 2 if ci else math.nan


def slope_change(before: list[dict[str, Any]], after: list[dict[str, Any]]) -> float:
    """The largest move, over the trials, of a slope's half width or value, as a fraction of its previous half
    width (0 when neither has an interval; inf when only one has)."""
    worst = 0.0
    for b, a in zip(before, after, strict=True):
        hb, ha = _half(b), _half(a)
        if not (math.isfinite(hb) and math.isfinite(ha)):
            worst = worst if math.isfinite(hb) == math.isfinite(ha) else math.inf
            continue
        move = max(abs(ha - hb), abs(a["slope_deg"] - b["slope_deg"]))
        worst = max(worst, move / hb if hb > 0 else (0.0 if move == 0 else math.inf))
    return worst


def fitted_legs(res: CalibrationResult, wheel: Any) -> tuple[Any, str]:
    """The wheel to import with after ``res``: ``wheel`` (a `rimless.sim.Wheel`) with the fitted parameters
    (`calibrated_input`), k's sd the one of its interval with the held parameters' part, no longer "to be
    fitted"; or (None, why) when the fit did not determine k."""
    from rimless.analysis.inference.runs import calibrated_input
    from rimless.sim.api.wheel import Wheel

    est = next((e for e in res.params if e.field == K_FIELD), None)
    if est is None:
        return None, "k is not fitted"
    sd = est.se_with_held if est.se_with_held is not None else est.se
    if not (est.identifiable or est.effective_only) or not (math.isfinite(est.value) and math.isfinite(sd)):
        return None, "the fit did not determine k (not identifiable, no standard error): the importer's bound kept"
    win = calibrated_input(wheel.input, res).with_entry(
        K_FIELD, est.value, sd, "fitted", "fitted on these trials, with the held parameters' part"
    )
    win = replace(win, fit=tuple(f for f in win.fit if f != K_FIELD))
    return Wheel.from_input(win, wheel.model), ""


def _legs_source(legs: Any) -> dict[str, Any]:
    from rimless.analysis.kinematics.slope_evidence import leg_compliance

    if isinstance(legs, str):
        return {"legs_time_s": None, "legs": "the trials were given imported: their slopes as imported", "legs_k": None}
    lc = leg_compliance(legs)
    told = None
    if legs is not None and legs.model != "rigid" and K_FIELD not in legs.input.fit:
        told = {"value_n_per_m": float(legs.params.stiffness_n_per_m), "sd_n_per_m": float(legs.uncertainty[K_FIELD])}
    return {"legs_time_s": lc.time_s, "legs": lc.source, "legs_k": told}


def calibrate_in_passes(
    trials: Sequence[Any],
    names: Sequence[str],
    fit: Sequence[str],
    wheel: Any,
    *,
    first_legs: Any,
    reimport: Callable[[Any], list[Any]] | None,
    prior: Any = None,
    progress: Callable[[int], None] | None = None,
    max_simulations: int | None = DEFAULT_MAX_SIMULATIONS,
    on_stage: Callable[[str], None] | None = None,
) -> CalibrationInPasses:
    """`rimless.analysis.inference.calibrate.calibrate` of ``fit`` on ``trials`` (imported told ``first_legs``:
    a `rimless.sim.Wheel`, None for the importer's bound, or `IMPORTED`) at ``wheel``'s parameters, holding and
    carrying the others (``wheel.input``); with k in ``fit`` and ``reimport(legs)`` (the same trials imported
    again told the wheel ``legs``, in the same order), the further passes of the module doc. ``progress(n)``:
    the simulations so far over every pass. ``max_simulations``: the simulations of every pass together
    (`rimless.analysis.inference.sim_budget`: one budget; a further pass is not started when it is spent, a
    pass it stops is not kept); ``on_stage(name)``: the stage reached, its pass named. Raises `NoTrialCalibrated`
    when the first pass calibrates nothing (`CalibrationBudgetSpent` when the budget ran out before)."""
    from rimless.analysis.inference.calibrate import FIT_FIELDS
    from rimless.analysis.inference.calibrate import calibrate as run_calibration
    from rimless.analysis.inference.sim_budget import SimulationBudget

    done = [0]
    this_pass = [1]

    def staged(name: str) -> None:
        if on_stage:
            on_stage(name if this_pass[0] == 1 else f"pass {this_pass[0]}: {name}")

    budget = SimulationBudget(max_simulations, on_stage=staged)
    fitted = {FIT_FIELDS[n][0] for n in fit}  # held exactly: a stated value without uncertainty, not fitted

    def calibrate_once(loaded: Sequence[Any]) -> CalibrationResult:
        def tick(n: int) -> None:
            done[0] = budget.used  # every pass's simulations, the refits' recalibrations too
            if progress:
                progress(done[0])

        return run_calibration(
            loaded,
            names,
            fit,
            params=wheel.params,
            model=wheel.compliant_model("calibrate()"),
            progress=tick,
            prior=prior,
            held=[(e.name, e.sd) for e in wheel.input.held()],
            held_exact=[n for n, e in wheel.input.entries.items() if e.sd == 0 and n not in fitted],
            budget=budget,
        )

    res = calibrate_once(trials)
    slopes = _slopes(trials, names)
    history: list[dict[str, Any]] = [
        {"pass": 1, **_legs_source(first_legs), "calibrated": True, "slopes": slopes, **_probe(res)}
    ]
    stop = "k is not fitted: the slopes were imported with the wheel's k" if "k" not in fit else ""
    if not stop and reimport is None:
        stop = "the trials were given imported (not Vicon exports): not imported again"
    stable = False
    while not stop:
        legs, why = fitted_legs(res, wheel)
        if legs is None or reimport is None:
            stop = why
            break
        try:
            again = reimport(legs)
        except RimlessError as err:
            stop = f"a trial could not be imported again ({str(err).splitlines()[0]}): the previous pass kept"
            break
        new = _slopes(again, names)
        change = slope_change(slopes, new)
        calibrated = sum(h["calibrated"] for h in history)
        finite = change if math.isfinite(change) else None  # (a trial that gained or lost its interval: JSON null)
        row = {"pass": len(history) + 1, **_legs_source(legs), "change": finite, "calibrated": False, "slopes": new}
        history.append(row)
        if change <= SLOPE_PASS_RTOL:
            stable = True
            stop = f"the slopes' intervals stopped changing (at most {change:.1%} of a half width)"
            break
        if calibrated >= MAX_SLOPE_PASSES:
            moved = f"moved {change:.1%} of a half width" if finite is not None else "gained or lost an interval"
            stop = f"at most {MAX_SLOPE_PASSES} calibrations; the slopes still {moved}"
            break
        if budget.spent:
            stop = "the simulation budget ran out: no further pass; the previous pass kept"
            budget.skip(f"pass {len(history)}", "not run: the slopes as the previous pass imported them")
            break
        this_pass[0] = len(history)
        stated = len(budget.skipped)
        try:
            again_res = calibrate_once(again)
        except NoTrialCalibrated as err:
            stop = f"the calibration on the re-imported slopes failed ({err}): the previous pass kept"
            break
        row.update(_probe(again_res))
        if budget.spent:  # this pass was cut short: the previous (whole) pass is the result
            del budget.skipped[stated:]
            budget.skip(f"pass {len(history)}", "stopped: the previous pass kept")
            stop = "the simulation budget ran out in this pass: the previous pass kept"
            break
        res = again_res
        row["calibrated"], slopes, trials = True, new, again
    passes = sum(h["calibrated"] for h in history)
    used = max(i for i, h in enumerate(history) if h["calibrated"])
    info = {
        "passes": passes,
        "reimported_with_fitted_k": used > 0,
        "stable": stable,
        "legs": history[used]["legs"],
        "legs_time_s": history[used]["legs_time_s"],
        "legs_k": history[used]["legs_k"],
        "stopped": stop,
        "statement": _statement(passes, used > 0, history[used]["legs"], stop),
        "history": history,
        # the pass whose held-exact probe is the result's ``held_exact_probe`` (each pass ran its own: ``history``)
        "held_exact_probe_pass": history[used]["pass"] if res.held_exact_probe is not None else None,
    }
    out = CalibrationInPasses(
        **{f.name: getattr(res, f.name) for f in fields(res)}, slope_passes=info, trials=list(trials)
    )
    if out.held_exact_probe is not None:
        out.held_exact_probe = {**out.held_exact_probe, "pass": history[used]["pass"]}
    out.budget = budget.as_dict()  # every pass's simulations, and what the budget stopped in any of them
    return out


def _probe(res: CalibrationResult) -> dict[str, Any]:
    """A pass's row entry: its own held-exact probe (`calibrate._held_exact_probe`; None when none ran)."""
    return {"held_exact_probe": res.held_exact_probe}


def _statement(passes: int, reimported: bool, legs: str, stop: str) -> str:
    if reimported:
        return f"the slopes were re-imported with the fitted k ({legs}); {passes} calibration passes; {stop}"
    return f"the slopes as imported ({legs}); 1 calibration pass; {stop}"
