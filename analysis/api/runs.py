"""The runs behind ``rimless trials critical-slope`` and ``trials calibrate``: load the trials, call the public
API (`rimless.analysis.api.trials`: `critical_slope`, `calibrate`) with the user's wheel, and return the
JSON-ready summary the commands print.

Progress goes to one bar on stderr (`rimless.progress.progress_bar`); the refusals of the inputs are
returned, not printed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.analysis.api.slope_passes import calibrate_in_passes
from rimless.analysis.api.trials import critical_slope
from rimless.analysis.inference.calibrate import CalibrationResult, NoTrialCalibrated, calibrate
from rimless.analysis.inference.critical_slope import CriticalSlopeResult, run_critical_slope
from rimless.analysis.inference.held import carry_critical
from rimless.analysis.inference.runs import (
    LoadedTrials,
    calibrated_input,
    load_trials,
    no_fit_here,
    prior_input,
    wheel_input,
)
from rimless.errors import RunFailure
from rimless.progress import progress_bar

__all__ = ["CriticalSlopeRun", "CalibrationRun", "critical_slope_run", "calibration_run"]


def _wheel(win: Any, model: str) -> Any:
    """The public API's `Wheel` for the user's wheel input (`win`: values, uncertainties, sources)."""
    from rimless.sim.api.wheel import Wheel

    return Wheel.from_input(win, model)  # type: ignore[arg-type]


def import_wheel(params_path: Path | None, rigid_legs: bool) -> Any:
    """The wheel ``trials import`` hands the importer (`import_trial(wheel=)`, for the legs' drift): the wheel
    file's (``--params``, default Table 1 with its stated uncertainties), rigid with ``rigid_legs``."""
    return _wheel(wheel_input(params_path), "rigid" if rigid_legs else "er")


@dataclass
class CriticalSlopeRun:
    """What ``trials critical-slope`` prints: the inputs, the estimates, and the optional calibration."""

    loaded: LoadedTrials
    result: CriticalSlopeResult | None = None  # None when no trial could be read
    calibration: CalibrationResult | None = None
    calibration_skipped: str | None = None

    def summary(self) -> dict[str, Any]:
        """The JSON object of ``trials critical-slope --json``."""
        assert self.result is not None
        out = self.result.summary()
        out["refused"] = self.loaded.refused
        if self.calibration is not None:
            out["calibration"] = self.calibration.summary()
        return out


def critical_slope_run(
    files: Sequence[Path],
    *,
    models: Sequence[str],
    calibrate_c: bool,
    params_path: Path | None,
    import_kwargs: dict[str, Any],
    group_tol_deg: float,
) -> CriticalSlopeRun:
    """Verdicts and the critical slope from the trials beside the models'; with ``calibrate_c`` also c
    calibrated on the trials (first model) and that model's critical slope."""
    win = wheel_input(params_path)
    no_fit_here(
        win,
        ("damping_ns_per_m",) if calibrate_c else (),
        '"fit" is taken only by `trials calibrate`; trials critical-slope fits c with --calibrated (no other)',
        "otherwise give a value (and sd)",
    )
    wheel = win.params
    with progress_bar("importing") as bar:
        legs = _wheel(win, "rigid" if models and all(m == "rigid" for m in models) else "er")
        run = CriticalSlopeRun(load_trials(files, {**import_kwargs, "wheel": legs}))  # (the legs' drift)
        if not run.loaded.trials:
            return run
        calibrated = None
        if calibrate_c:  # c alone, at the held values: the calibrated model's critical slope beside the others
            bar.update(description="calibrating c")
            try:
                run.calibration = calibrate(
                    run.loaded.trials,
                    run.loaded.names,
                    ["c"],
                    params=wheel,
                    model=models[0],
                    progress=lambda n: bar.update(description=f"calibrating c ({n} simulations)"),
                )
                calibrated = run.calibration.calibrated_params
            except NoTrialCalibrated as e:
                run.calibration_skipped = str(e)
        # the public API's function; the models carried at the held values (c too): the calibrated one is not
        run.result = critical_slope(
            run.loaded.trials,
            _wheel(win, models[0]),
            models=models,
            calibrated=calibrated,
            group_tol_deg=group_tol_deg,
            progress=lambda s: bar.update(description=s),
            names=run.loaded.names,
        )
    return run


@dataclass
class CalibrationRun:
    """What ``trials calibrate`` prints: the inputs, the calibration and the optional critical slopes."""

    loaded: LoadedTrials
    calibration: CalibrationResult | None = None
    failure: str | None = None  # why nothing was calibrated
    critical: CriticalSlopeResult | None = None
    prior: Any = None  # leg-test priors (`rimless.analysis.inference.priors.LegPriors`), planned
    fit: list[str] = field(default_factory=list)
    wheel: Any = None  # the wheel's parameters with their uncertainties (`rimless.sim.model.uncertain.WheelInput`)

    def summary(self) -> dict[str, Any]:
        """The JSON object of ``trials calibrate --json``."""
        assert self.calibration is not None
        out = self.calibration.summary()
        out["refused"] = self.loaded.refused
        if self.wheel is not None:
            out["parameters"] = self.wheel.parameters()  # also after a failed calibration's inputs
        if self.prior is not None:
            from rimless.analysis.inference.calibrate import FIT_FIELDS

            out["prior"] = self.prior.report(self.calibration, [FIT_FIELDS[n][0] for n in self.fit], self.fit)
        crit = self.critical
        if crit is not None:
            out["critical_slope_deg"] = {
                "trials": crit.critical_slope_deg,
                "trials_method": crit.chosen.method if crit.chosen else None,
                "trials_ci_deg": list(crit.chosen.ci_deg) if crit.chosen else None,
                "trials_ci_with_parameters_deg": crit.held_summary().get("ci_with_parameters_deg"),
                #: that interval cut at 0 deg (its linearised lower end was below): `held.carry_critical`
                "trials_ci_with_parameters_at_bound": bool(
                    ((crit.held or {}).get("trials") or {}).get("ci_at_bound", False)
                ),
                **{f"model_{k}": v for k, v in crit.model["critical_slope_deg"].items()},
            }
        return out


def calibration_run(
    files: Sequence[Path],
    fit: Sequence[str],
    *,
    model: str,
    critical: bool,
    params_path: Path | None,
    import_kwargs: dict[str, Any],
    prior_path: Path | None = None,
    max_simulations: int | None = None,
) -> CalibrationRun:
    """Calibrate ``fit`` on the trials; with ``critical`` also the calibrated model's critical slope and the
    trials'; with ``prior_path`` (a `trials leg-fit --json` output) the leg test's results as priors;
    ``max_simulations`` the calibration's budget (None: the default, `DEFAULT_MAX_SIMULATIONS`)."""
    from rimless.analysis.inference.sim_budget import DEFAULT_MAX_SIMULATIONS

    win = wheel_input(params_path)
    from rimless.analysis.inference.calibrate import FIT_FIELDS

    by_field = {f: n for n, (f, _) in FIT_FIELDS.items()}
    fit = list(fit) + [by_field[f] for f in win.fit if by_field[f] not in fit]  # the file's "fit" too
    wheel = win.params
    prior = None
    if prior_path is not None:
        from rimless.analysis.inference.calibrate import FIT_FIELDS
        from rimless.analysis.inference.priors import read_priors

        prior = read_priors(prior_path)
        wheel = prior.plan(wheel, [FIT_FIELDS[n][0] for n in fit])
        win = prior_input(win, prior)
    with progress_bar("importing") as bar:
        # the importer's legs' drift: the wheel's k, or its own bound when k is fitted (not known); then, k
        # fitted, the files imported again told the fitted k (`rimless.analysis.api.slope_passes`)
        legs = None if "k" in fit else _wheel(win, model)
        kwargs = {**import_kwargs, "wheel": legs}
        run = CalibrationRun(load_trials(files, kwargs), prior=prior, fit=list(fit), wheel=win)
        if not run.loaded.trials:
            return run
        from rimless.sim.api.wheel import Wheel

        # the leg test's planned values (fixed or penalised), `win` their sources
        planned = Wheel.from_input(win, model, params=wheel)  # type: ignore[arg-type]

        def reimport(told: Any) -> list[Any]:
            again = load_trials(files, {**kwargs, "wheel": told})
            if again.names != run.loaded.names:
                raise RunFailure("the files imported differ from the first import's: " + "; ".join(again.refused))
            return again.trials

        where = ["start"]  # the calibration's stage, shown with the count
        try:  # the held parameters carried by refits; the parameters listed
            run.calibration = calibrate_in_passes(
                run.loaded.trials,
                run.loaded.names,
                fit,
                planned,
                first_legs=legs,
                reimport=reimport,
                prior=prior,
                progress=lambda n: bar.update(description=f"calibrating: {where[0]} ({n} simulations)"),
                max_simulations=DEFAULT_MAX_SIMULATIONS if max_simulations is None else max_simulations,
                on_stage=lambda s: where.__setitem__(0, s),
            )
        except NoTrialCalibrated as e:
            run.failure = str(e)
            return run
        run.calibration.parameters = calibrated_input(win, run.calibration).parameters()
        run.loaded.trials = run.calibration.trials  # the slopes the calibration used (re-imported or not)
        run.wheel = win = calibrated_input(win, run.calibration)
        if critical:
            run.critical = run_critical_slope(
                run.loaded.trials,
                run.loaded.names,
                wheel,
                models=[model],
                calibrated=run.calibration.calibrated_params,
                progress=lambda s: bar.update(description=s),
            )
            carry_critical(run.critical, run.loaded.trials, run.loaded.names, win)  # the trials' estimate
    return run
