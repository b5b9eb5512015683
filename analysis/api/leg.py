"""The leg-test fit from Python: `leg_fit(logs)` fits one leg's stiffness k, damping c and guide friction F_c to
its `rimless robot leg-test` logs (`rimless.analysis.inference.leg_fit`) and returns the `LegFitResult` whose
`to_dict()` is the JSON object of ``rimless trials leg-fit --json``; `read_leg_log(path)` reads and checks one log.

    >>> from rimless.analysis import leg_fit
    >>> fit = leg_fit(["leg0_a.jsonl", "leg0_b.jsonl"], moving_mass_kg=0.0378, moving_mass_sd_kg=0.0005)
    >>> fit.to_dict()["k_n_per_m"], fit.to_dict()["k_n_per_m_ci"]
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from rimless.analysis.inference.leg_fit import DEFAULT_MOVING_MASS_KG
from rimless.errors import ParameterError

if TYPE_CHECKING:
    from rimless.analysis.inference.leg_fit import LegFitResult, LegLog

__all__ = ["leg_fit"]


def leg_fit(
    logs: Sequence[str | Path | LegLog] | str | Path,
    *,
    moving_mass_kg: float = DEFAULT_MOVING_MASS_KG,
    moving_mass_sd_kg: float = 0.0,
    counts_per_m: float | None = None,
    plot: str | Path | None = None,
) -> LegFitResult:
    """Fit one leg's k (N/m), c (N s/m) and Coulomb guide friction F_c (N), with 95 % intervals, to its free motion
    in the leg-test ``logs`` (paths, or logs read by `read_leg_log`; several releases of one leg fit together).

    ``moving_mass_kg`` and its 1-sigma ``moving_mass_sd_kg``: the leg's moving mass (k and c scale with it; its
    sd is carried into the intervals). ``counts_per_m``: the sensor's scale, overriding each log's (only F_c
    depends on it). ``plot``: a figure of the fit and its residuals (PNG, PDF, SVG).

    A bad log raises `InputFileError` naming the file, line and field; a motion the model cannot fit raises
    `RunFailure`. ``to_dict()`` of the result is ``rimless trials leg-fit --json``."""
    from rimless.analysis.inference.leg_fit import LegLog, fit_leg, plot_leg_fit, read_leg_log, run_leg_fit

    items = [logs] if isinstance(logs, (str, Path, LegLog)) else list(logs)
    if not items:
        raise ParameterError("logs: none given")
    bad = [type(i).__name__ for i in items if not isinstance(i, (str, Path, LegLog))]
    if bad:
        raise ParameterError(f"logs: expected paths or LegLog objects, got {bad[0]}")
    if all(isinstance(i, (str, Path)) for i in items):  # the command's path: options checked before any reading
        return run_leg_fit(
            [Path(i) for i in items if isinstance(i, (str, Path))],
            moving_mass_kg=moving_mass_kg,
            moving_mass_sd_kg=moving_mass_sd_kg,
            counts_per_m=counts_per_m,
            plot=None if plot is None else Path(plot),
        )
    if counts_per_m is not None:
        raise ParameterError("counts_per_m: give it to read_leg_log for logs already read")
    read = [i if isinstance(i, LegLog) else read_leg_log(i) for i in items]
    fit = fit_leg(read, moving_mass_kg=moving_mass_kg, moving_mass_sd_kg=moving_mass_sd_kg)
    if plot is not None:
        plot_leg_fit(fit, plot)
    return fit
