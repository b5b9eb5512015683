"""The runs behind ``rimless trials critical-slope`` and ``trials calibrate``: load the trials, calibrate,
estimate the critical slope, and return the JSON-ready summary the commands print.

Progress goes to one bar on stderr (`rimless.progress.progress_bar`); the refusals of the inputs are
returned, not printed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.analysis.inference.calibrate import CalibrationResult, NoTrialCalibrated, calibrate
from rimless.analysis.inference.critical_slope import CriticalSlopeResult, run_critical_slope
from rimless.analysis.inference.held import carry_critical
from rimless.analysis.kinematics.inputs import load_input
from rimless.errors import InputFileError, ParameterError
from rimless.progress import progress_bar

__all__ = [
    "LoadedTrials",
    "CriticalSlopeRun",
    "CalibrationRun",
    "load_trials",
    "wheel_params",
    "wheel_input",
    "critical_slope_run",
    "calibration_run",
]


@dataclass
class LoadedTrials:
    """The trials that could be read, their names (as given, relative to the working folder) and the refusals."""

    trials: list[Any] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)


def _rel(p: Path) -> str:
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


def load_trials(files: Sequence[Path], import_kwargs: dict[str, Any]) -> LoadedTrials:
    """Read or import every input; a missing file stops before any work (`InputFileError`)."""
    missing = [str(p) for p in files if not p.is_file()]
    if missing:
        raise InputFileError(f"{', '.join(missing)}: no such file")
    out = LoadedTrials()
    for p in files:
        row = load_input(p, import_kwargs)
        if row.trial is None:
            out.refused.append(row.reason or f"{p}: refused")
        else:
            out.trials.append(row.trial)
            out.names.append(_rel(p))
    return out


def wheel_params(path: Path | None) -> Any:
    """The wheel's parameters from a TOML file (``--params``), default the paper's Table 1."""
    from rimless.sim.model.params import WheelParams, load_params

    if path is None:
        return WheelParams()
    if not path.is_file():
        raise InputFileError(f"--params {path}: no such file")
    return load_params(path)


def wheel_input(path: Path | None) -> Any:
    """The wheel's parameters with their uncertainties and sources (`rimless.sim.model.uncertain.WheelInput`)
    from a wheel file (``--params``; plain numbers are exact), default Table 1 with the default uncertainties."""
    from rimless.sim.model.uncertain import default_wheel_input, read_wheel_input

    if path is None:
        return default_wheel_input()
    if not path.is_file():
        raise InputFileError(f"--params {path}: no such file")
    return read_wheel_input(path)


def _no_fit_here(win: Any, allowed: tuple[str, ...], what: str) -> None:
    """A wheel file marking a parameter "fit" where the command cannot fit it: a `ParameterError` naming both."""
    from rimless.sim.model.uncertain import SYMBOLS

    extra = [n for n in win.fit if n not in allowed]
    if extra:
        names = ", ".join(SYMBOLS[n] for n in extra)
        raise ParameterError(
            f'{win.path}: key {names} = "fit": {what}; give a value (and sd) or use `trials calibrate`'
        )


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
    _no_fit_here(win, ("damping_ns_per_m",) if calibrate_c else (), "trials critical-slope fits only c (--calibrated)")
    wheel = win.params
    with progress_bar("importing") as bar:
        run = CriticalSlopeRun(load_trials(files, import_kwargs))
        if not run.loaded.trials:
            return run
        calibrated = None
        if calibrate_c:
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
        run.result = run_critical_slope(
            run.loaded.trials,
            run.loaded.names,
            wheel,
            models=models,
            calibrated=calibrated,
            group_tol_deg=group_tol_deg,
            progress=lambda s: bar.update(description=s),
        )
        carry_critical(  # the models at the held values (c too): the calibrated model's is not carried
            run.result,
            run.loaded.trials,
            run.loaded.names,
            win,
            models=models,
            group_tol_deg=group_tol_deg,
            progress=lambda s: bar.update(description=s),
        )
    return run


def calibrated_input(win: Any, cal: CalibrationResult) -> Any:
    """``win`` with the fitted parameters' values and standard errors (source ``fitted``)."""
    for e in cal.params:
        if e.identifiable or e.effective_only:
            ok = math.isfinite(e.se)
            basis = "fitted on these trials" if ok else "fitted on these trials (no standard error: sd shown as 0)"
            win = win.with_entry(e.field, e.value, e.se if ok else 0.0, "fitted", basis)
    return win


def prior_input(win: Any, prior: Any) -> Any:
    """``win`` with the leg test's values and uncertainties where the calibration holds them (source
    ``leg_test_prior``)."""
    for q in prior.priors:
        if q.use == "fixed" and q.field in win.entries:
            win = win.with_entry(q.field, q.mean, q.sd, "leg_test_prior", f"leg test {prior.path}")
    return win


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
) -> CalibrationRun:
    """Calibrate ``fit`` on the trials; with ``critical`` also the calibrated model's critical slope and the
    trials'; with ``prior_path`` (a `trials leg-fit --json` output) the leg test's results as priors."""
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
        run = CalibrationRun(load_trials(files, import_kwargs), prior=prior, fit=list(fit), wheel=win)
        if not run.loaded.trials:
            return run
        try:
            run.calibration = calibrate(
                run.loaded.trials,
                run.loaded.names,
                fit,
                params=wheel,
                model=model,
                progress=lambda n: bar.update(description=f"calibrating ({n} simulations)"),
                prior=prior,
                held=[(e.name, e.sd) for e in win.held()],
            )
        except NoTrialCalibrated as e:
            run.failure = str(e)
            return run
        run.wheel = win = calibrated_input(win, run.calibration)
        run.calibration.parameters = win.parameters()
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
