"""What the ``rimless trials`` commands share before the work: the trials loaded (with the refusals, returned,
not printed) and the wheel's input (its parameters with their uncertainties, a wheel file's or the defaults'),
and that input after a calibration or with leg-test priors. The runs themselves (`rimless.analysis.api.runs`)
call the public API.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.analysis.inference.calibrate import CalibrationResult
from rimless.analysis.kinematics.inputs import load_input
from rimless.errors import InputFileError, ParameterError

__all__ = [
    "LoadedTrials",
    "load_trials",
    "wheel_params",
    "wheel_input",
    "no_fit_here",
    "calibrated_input",
    "prior_input",
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


def no_fit_here(
    win: Any, allowed: tuple[str, ...], what: str, remedy: str = "give a value (and sd) or use `trials calibrate`"
) -> None:
    """A wheel file marking a parameter "fit" where the command cannot fit it: a `ParameterError` naming both,
    and what to do instead (`remedy`)."""
    from rimless.sim.model.uncertain import SYMBOLS

    extra = [n for n in win.fit if n not in allowed]
    if extra:
        names = ", ".join(SYMBOLS[n] for n in extra)
        raise ParameterError(f'{win.path}: key {names} = "fit": {what}; {remedy}')


def calibrated_input(win: Any, cal: CalibrationResult) -> Any:
    """``win`` with the fitted parameters' values and standard errors (source ``fitted``): each value the
    calibrated model's (``cal.calibrated_params``), which is the simpler fit's where the model choice did not
    support an extra parameter (then the basis says so, and the sd is the fit's with it)."""
    for e in cal.params:
        if e.identifiable or e.effective_only:
            ok = math.isfinite(e.se)
            basis = "fitted on these trials" if ok else "fitted on these trials (no standard error: sd shown as 0)"
            used = getattr(cal.calibrated_params, e.field, None)
            value = e.value if used is None else float(used)
            if value != e.value:
                basis += (
                    f" (the model without the extra parameter the model choice did not support; the fit with it "
                    f"gave {e.value:.4g}, whose sd is shown)"
                )
            win = win.with_entry(e.field, value, e.se if ok else 0.0, "fitted", basis)
    return win


def prior_input(win: Any, prior: Any) -> Any:
    """``win`` with the leg test's values and uncertainties where the calibration holds them (source
    ``leg_test_prior``)."""
    for q in prior.priors:
        if q.use == "fixed" and q.field in win.entries:
            win = win.with_entry(q.field, q.mean, q.sd, "leg_test_prior", f"leg test {prior.path}")
    return win
