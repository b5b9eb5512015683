"""The report's calibration of c beside its comparisons: a second process (`rimless.analysis.inference.background`)
that imports and loads the compiled kernels while the trial files load, then calibrates while the trials are
compared and the figures drawn; or, on a cold cache, one started after the first comparison has compiled the
kernels (so that they are compiled once). While it runs, BLAS keeps to one thread here.
"""

from __future__ import annotations

import contextlib
from functools import partial
from typing import Any

from rimless.analysis.inference.background import Background


def one_blas_thread() -> contextlib.AbstractContextManager[Any]:
    """BLAS on one thread in this process for the block (`calibrate.one_blas_thread`)."""
    from rimless.analysis.inference.calibrate import one_blas_thread as limit

    return limit()


def prepared_calibration(params: Any) -> Background | None:
    """The calibration's process started now, loading the kernels of ``params``' mass model; `submit`
    `calibration_args` once the trials are read. None on a cold cache: the process would compile the kernels
    a second time beside the report (`start_calibration` after the first comparison then)."""
    from rimless.sim.fast import compiled

    if not compiled(params):
        return None
    from rimless.analysis.inference.calibrate import calibrate_or_none

    return Background.started(calibrate_or_none, prepare=partial(_load_kernels, params))


def _load_kernels(params: Any) -> None:
    """Load (from numba's cache) the compiled kernels of ``params``' mass model: the process's preparation."""
    from rimless.sim.fast import warm_up

    warm_up(("er",), params)


def calibration_args(params: Any, model: str, trials: list[Any], names: list[str]) -> tuple[Any, ...]:
    """`calibrate_or_none`'s arguments: c on ``trials`` at ``params``."""
    return trials, names, ["c"], params, model


def start_calibration(params: Any, model: str, trials: list[Any], names: list[str]) -> Background | None:
    """The calibration of c on ``trials``, in a second process from now on (None: no trial)."""
    if not trials:
        return None
    from rimless.analysis.inference.calibrate import calibrate_or_none

    return Background(calibrate_or_none, *calibration_args(params, model, trials, names))
