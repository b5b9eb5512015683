"""The step-to-step return map from the trials, from Python: `floquet(trials, wheel=None)` returns the
`rimless.analysis.inference.floquet.FloquetResult` whose `to_dict()` is ``rimless trials floquet --json``.

    >>> from rimless.analysis import floquet
    >>> res = floquet(["analysis/data/SYNTHETIC_er_slope2.0deg_run1.csv"])
    >>> res.to_frame()  # one row per slope group: the multiplier, its 95 % interval, the model's eigenvalue
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rimless.analysis.inference.floquet import FloquetResult
    from rimless.sim.api.wheel import Wheel

__all__ = ["floquet"]


def floquet(
    trials: Sequence[Any],
    wheel: Wheel | None = None,
    *,
    group_tol_deg: float = 0.05,
    with_model: bool = True,
    calibrate_c: bool = False,
    progress: Callable[[str], None] | None = None,
) -> FloquetResult:
    """The multiplier of the trials' return map of the post-impact angular speed, one per slope group, with the
    measurement noise's bias corrected and a 95 % interval, beside the model's dominant eigenvalue
    (`rimless trials floquet`).

    trials : `Trial`s or paths (Vicon exports or imported ``.parquet`` trials; see `load_trials`).
    wheel : the model and its parameters (default Table 1, ER); the parameters' uncertainties (``wheel.input``)
        and each group's slope uncertainty are carried into the model's interval (``model.ci95``). Vicon exports
        are imported with it (`import_trial(wheel=)`: its legs' k bounds the drift in the slope's interval).
    group_tol_deg : trials whose slopes differ by less form one group (one multiplier).
    with_model : False skips the model (its eigenvalue is then None).
    calibrate_c : the model's c calibrated on the trials first (`calibrate(trials, ("c",))`; source ``fitted``,
        its standard error carried into the model's interval; ``calibration`` in the result says how it went).
    Trials too short or transient-only are flagged with the reason (``trials[i].status``, ``reason``); a group
    without an estimate says why (``groups[j].status``, ``reason``)."""
    from rimless.analysis.api.trials import load_trials
    from rimless.analysis.inference.floquet import run_floquet
    from rimless.errors import ParameterError
    from rimless.sim.api.wheel import Wheel

    if not (isinstance(group_tol_deg, float | int) and group_tol_deg >= 0):
        raise ParameterError(f"group_tol_deg must be a number >= 0, got {group_tol_deg!r}")
    if wheel is not None and not isinstance(wheel, Wheel):
        raise ParameterError(f"wheel must be a rimless.sim.Wheel, got {type(wheel).__name__}")
    w = wheel if wheel is not None else Wheel()
    loaded, names = load_trials(trials, wheel=w)  # Vicon exports imported with the wheel (its legs' drift)
    return run_floquet(
        loaded,
        names,
        w.input,
        model=w.compliant_model("floquet()"),
        group_tol_deg=float(group_tol_deg),
        with_model=with_model,
        calibrate_c=calibrate_c,
        progress=progress,
    )
