"""Carry each trial's measured slope, and its uncertainty, into a calibration's fitted parameters.

The calibration holds every trial at its measured slope (the importer's ``meta.slope_deg``); the slope's 1-sigma
uncertainty is its 95 % interval ``meta.slope_ci_rad`` / 3.92, or the default of its source
(`rimless.analysis.inference.sustained.trial_slope_sigma_deg`). A slope error is shared by every residual of its
trial and is not noise the residuals show: the energy a step gains grows with the slope, and the damping c,
which sets the energy a step loses, absorbs the error (with only part of the loss in the damper, a 0.3 %
error in one slope moved c by about 1 % on the ER wheels of `rimless.analysis.validation.calibrate_coverage`).

Propagated by **linear response at the solution**: with J the Jacobian of the scaled residuals (globals, then each
trial's release speed and time shift) and b_i the change of trial i's scaled residuals per unit of its slope
(central difference at +-1 sd, that trial alone), a slope moved by delta moves the least-squares solution by
-J^+ b_i delta; the globals' parts add in quadrature over the trials (independent slope errors):
se_slope_j = sqrt(sum_i ((J^+ b_i)_j sigma_i)^2).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["slope_response"]


def slope_response(
    J: np.ndarray,
    n_global: int,
    scale: np.ndarray,
    slope_sd_deg: Sequence[float],
    trial_residuals: Callable[[int, float], np.ndarray],
    offs: np.ndarray,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """(se_slope per global in its units, per trial the parts per global): the globals' standard errors from
    the trials' slope uncertainties. ``trial_residuals(i, d_slope_deg)`` returns trial i's scaled residuals with
    its slope moved by ``d_slope_deg`` (rows ``offs[i]:offs[i+1]`` of J); ``scale``: the globals' units per
    column of J. A trial whose sd is not finite and positive contributes nothing."""
    Jp = np.linalg.pinv(J)
    total = np.zeros(n_global)
    parts: list[np.ndarray] = []
    for i, sd in enumerate(slope_sd_deg):
        if not (math.isfinite(sd) and sd > 0):
            parts.append(np.zeros(n_global))
            continue
        b = np.zeros(J.shape[0])
        b[offs[i] : offs[i + 1]] = (trial_residuals(i, sd) - trial_residuals(i, -sd)) / 2.0  # per sd
        du = -(Jp @ b)[:n_global] * np.asarray(scale[:n_global], float)
        parts.append(du)
        total += du * du
    return np.sqrt(total), parts
