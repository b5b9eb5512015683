"""The trial analysis from Python: recordings in, `Trial`s, comparison with the simulator, calibration, critical
slope, report. Every function takes the simulator's `rimless.sim.Wheel` (one simulator object) and returns the
object whose `to_dict()` (or `summary()`) is the matching `rimless trials` command's `--json` object.

    >>> from rimless.analysis import import_trial, compare
    >>> trial = import_trial("analysis/data/SYNTHETIC_er_slope2.0deg_run1.csv")
    >>> trial.to_frame()[["time_s", "com_height_m"]]
    >>> compare(trial).to_dict()["rms_com_error_mm"]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rimless.analysis.inference.sim_budget import DEFAULT_MAX_SIMULATIONS
from rimless.errors import ParameterError

if TYPE_CHECKING:
    from rimless.analysis.inference.calibrate import CalibrationResult
    from rimless.analysis.inference.compare import TrialComparison
    from rimless.analysis.inference.critical_slope import CriticalSlopeResult
    from rimless.analysis.io.trial import Trial
    from rimless.analysis.report.html import ReportResult
    from rimless.sim.api.wheel import Wheel

__all__ = ["load_trials", "compare", "calibrate", "critical_slope", "write_report"]

TrialLike = Any  # a `Trial`, or the path of a Vicon export (.csv, .c3d) or of an imported trial (.parquet)


def _wheel(wheel: Wheel | None) -> Wheel:
    from rimless.sim.api.wheel import Wheel

    if wheel is None:
        return Wheel()
    if not isinstance(wheel, Wheel):
        raise ParameterError(f"wheel must be a rimless.sim.Wheel, got {type(wheel).__name__}")
    return wheel


def _named(names: Sequence[str] | None, file_names: list[str]) -> list[str]:
    if names is None:
        return file_names
    if len(names) != len(file_names):
        raise ParameterError(f"names: {len(names)} given for {len(file_names)} trials")
    return list(names)


def load_trials(trials: Sequence[TrialLike] | TrialLike, **import_options: Any) -> tuple[list[Trial], list[str]]:
    """Trials and their names from `Trial` objects or paths (Vicon exports are imported with `import_options`,
    the keyword arguments of `import_trial`; `.parquet` files are read as imported trials)."""
    from rimless.analysis.io.trial import Trial, read_trial
    from rimless.analysis.kinematics.build import import_trial

    items = [trials] if isinstance(trials, (str, Path, Trial)) else list(trials)
    if not items:
        raise ParameterError("trials: none given")
    out: list[Trial] = []
    names: list[str] = []
    for item in items:
        if isinstance(item, Trial):
            out.append(item)
            names.append(Path(item.meta.source_file).name)
        elif isinstance(item, (str, Path)):
            path = Path(item)
            trial = read_trial(path) if path.suffix.lower() == ".parquet" else import_trial(path, **import_options)
            out.append(trial)
            names.append(path.name)
        else:
            raise ParameterError(f"trials: expected a Trial or a path, got {type(item).__name__}")
    return out, names


def compare(trial: TrialLike, wheel: Wheel | None = None, *, rtol: float = 1e-8) -> TrialComparison:
    """Measured against simulated for one trial (`rimless trials report`'s per-trial row): the release speed
    fitted to the first measured step on the trial's slope, the CoM height and step periods compared.

    wheel : the simulated wheel (model and parameters; its slope is replaced by the trial's). Default Table 1, ER.
    rtol : the comparison's integrator tolerance (the report's default).
    `to_dict()` adds ``parameters``: every parameter the simulation held, with its value and source (`Wheel.input`)."""
    from rimless.analysis.inference.compare import Simulator, compare_trial

    w = _wheel(wheel)
    (t,), (name,) = load_trials([trial], wheel=w)
    sim = Simulator(model=w.compliant_model("compare()"), params=w.params, rtol=rtol)
    res = compare_trial(t, sim, name=name)
    res.parameters = w.input.parameters()  # what the simulation held, with its source
    return res


def calibrate(
    trials: Sequence[TrialLike],
    fit: Sequence[str] = ("c",),
    wheel: Wheel | None = None,
    *,
    prior: Any = None,
    progress: Callable[[int], None] | None = None,
    names: Sequence[str] | None = None,
    max_simulations: int | None = DEFAULT_MAX_SIMULATIONS,
) -> CalibrationResult:
    """Fit model parameters (`fit`: names among c, k, guide_friction_n, ...) to the trials' step periods and CoM
    heights (`rimless trials calibrate`); the others are held at the wheel's values. `summary()` is the
    command's JSON object (`converged`, estimates with intervals, what was held; ``parameters``: every
    parameter's value, uncertainty and source, the wheel's `Wheel.input`). `names`: the trials' names in the
    output (default the file names). `max_simulations`: at most this many simulations over the whole calibration
    (None: no bound); when they run out the remaining stages are stopped or skipped, JSON ``budget`` says which
    and the affected estimates' status says what it means (a budget spent before a first solution raises
    `NoTrialCalibrated`)."""
    from rimless.analysis.api.slope_passes import IMPORTED, calibrate_in_passes
    from rimless.analysis.inference.calibrate import parse_fit
    from rimless.analysis.io.trial import Trial

    w = _wheel(wheel)
    w.compliant_model("calibrate()")
    fit_names = parse_fit(",".join(fit)) if not isinstance(fit, str) else parse_fit(fit)
    items = [trials] if isinstance(trials, (str, Path, Trial)) else list(trials)
    # the importer bounds the legs' drift with the wheel's k, or (k to be fitted: not known) its own bound; then
    # the trials are imported again with the fitted k (`calibrate_in_passes`) when they are Vicon exports
    first = None if "k" in fit_names else w
    loaded, file_names = load_trials(items, wheel=first)
    exports = all(isinstance(i, (str, Path)) and Path(i).suffix.lower() != ".parquet" for i in items)
    res = calibrate_in_passes(
        loaded,
        _named(names, file_names),
        fit_names,
        w,
        first_legs=first if exports else IMPORTED,
        reimport=(lambda legs: load_trials(items, wheel=legs)[0]) if exports else None,
        prior=prior,
        progress=progress,
        max_simulations=max_simulations,
    )
    from rimless.analysis.inference.runs import calibrated_input

    res.parameters = calibrated_input(w.input, res).parameters()
    return res


def critical_slope(
    trials: Sequence[TrialLike],
    wheel: Wheel | None = None,
    *,
    models: Sequence[str] | None = None,
    calibrated: Any = None,
    group_tol_deg: float = 0.05,
    progress: Callable[[str], None] | None = None,
    names: Sequence[str] | None = None,
) -> CriticalSlopeResult:
    """The critical slope from trials (`rimless trials critical-slope`): a verdict per trial (sustained walk or
    not, from its motion), the estimate with its 95 % interval, and the models' critical slopes at the wheel's
    parameters (`models`, default the wheel's model) beside it; `calibrated` parameters add those models'.
    The wheel's parameters are held with their uncertainties (`Wheel.input`: a wheel file's ``{value, sd}``, the
    ``uncertainty=`` given, else the defaults), listed (``parameters``) and carried into the intervals
    (``parameter_uncertainty``, ``ci_with_parameters_deg``; `rimless.analysis.inference.held`). When the wheel
    does not state its inertia (Table 1's default), the trials' own inertia ratio I_hub / (M L0^2), fitted to
    their consecutive step periods (`rimless.analysis.inference.stance_inertia`), takes its place (source
    "trials", ``inertia_from_trials``); a stated inertia is compared with it (``warnings``). `names`: the
    trials' names in the output (default the file names)."""
    from rimless.analysis.inference.critical_slope import run_critical_slope
    from rimless.analysis.inference.held import carry_critical

    w = _wheel(wheel)
    loaded, file_names = load_trials(trials, wheel=w)
    names = _named(names, file_names)
    ms = tuple(models) if models is not None else (w.model,)
    res = run_critical_slope(
        loaded,
        names,
        w.params,
        models=ms,
        calibrated=calibrated,
        group_tol_deg=group_tol_deg,
        progress=progress,
    )
    carry_critical(res, loaded, names, w.input, models=ms, group_tol_deg=group_tol_deg, progress=progress)
    return res


def write_report(
    files: Sequence[str | Path],
    out: str | Path,
    wheel: Wheel | None = None,
    *,
    slope_bin_deg: float | None = 0.5,
    title: str = "Vicon trials vs simulation",
    **import_options: Any,
) -> ReportResult:
    """Compare Vicon exports (paths) with the simulation and write the HTML report, figures and metrics to the
    folder `out` (`rimless trials report`). Returns the report (`summary()` is the command's JSON object).
    ``slope_bin_deg``: the step periods' slope bins within a series, deg (``--slope-bin-deg``); None pools only
    trials whose slope intervals overlap, as `rimless demo` does."""
    from rimless.analysis.report.batch import run_report

    w = _wheel(wheel)
    paths = [Path(f) for f in ([files] if isinstance(files, (str, Path)) else files)]
    return run_report(
        paths,
        Path(out),
        json_out=True,
        import_kwargs=import_options,
        model=w.compliant_model("write_report()"),
        slope_bin_deg=slope_bin_deg,
        title=title,
        params=w.params,
        wheel_input=w.input,
    )
