"""The critical slope from trials: per-trial verdicts (`rimless.analysis.inference.sustained`), then three estimates.

- **bracket**: the highest slope whose decided trials include no sustained one, below the lowest slope with
  a sustained trial (undetermined trials do not count). The estimate is the bracket's midpoint.
- **logistic**: P(sustained) = 1 / (1 + exp(-(b0 + b1 phi))) fitted to the decided trials by maximum
  likelihood with Firth's penalty (finite even when the verdicts separate perfectly, as they do for a
  deterministic walker); the estimate is the 50 % slope -b0/b1 with a delta-method 95 % interval. Used when
  some slope has several decided trials.
- **fixed-point extrapolation**: each trial's fitted return-map fixed point e* (squared speed over the top,
  rad^2/s^2) against its slope, a weighted straight line, and the slope where e* = 0 (the fitted gait
  disappears into the stall), with a delta-method 95 % interval.

The reported estimate is the best supported one: the extrapolation when it lies inside the bracket widened by
its own interval (it then uses every step of every trial); else the logistic when it is available and inside
the bracket; else the bracket. Slopes in degrees at this edge, radians inside the model calls.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rimless.analysis.inference.sustained import Verdict

__all__ = ["Estimate", "CriticalSlopeResult", "estimate_critical_slope", "model_critical_slope", "Z95"]

Z95 = 1.959963984540054


@dataclass
class Estimate:
    method: str  # bracket | logistic | fixed-point-extrapolation
    value_deg: float
    ci_deg: tuple[float, float]
    detail: str

    def as_dict(self) -> dict[str, Any]:
        return {"method": self.method, "critical_slope_deg": self.value_deg, "ci_deg": list(self.ci_deg),
                "detail": self.detail}


@dataclass
class CriticalSlopeResult:
    """Everything `rimless trials critical-slope` reports (degrees at the edge)."""

    per_trial: list[dict[str, Any]]
    bracket_deg: tuple[float, float] | None
    estimates: list[Estimate]
    chosen: Estimate | None
    why: str
    logistic: tuple[float, float] | None = None  # (b0, b1 per deg)
    extrapolation: tuple[float, float] | None = None  # (e* intercept, slope per deg)
    model: dict[str, Any] = field(default_factory=dict)

    @property
    def critical_slope_deg(self) -> float:
        return self.chosen.value_deg if self.chosen else math.nan

    def summary(self) -> dict[str, Any]:
        c = self.chosen
        return {"critical_slope_deg": self.critical_slope_deg,
                "bracket_deg": list(self.bracket_deg) if self.bracket_deg else None,
                "ci_deg": list(c.ci_deg) if c else None, "method": c.method if c else None,
                "why": self.why, "estimates": [e.as_dict() for e in self.estimates],
                "per_trial": self.per_trial, "model_critical_slope_deg": self.model.get("critical_slope_deg", {}),
                "model": self.model}


def _bracket(slopes: np.ndarray, sustained: np.ndarray) -> tuple[float, float] | None:
    """(highest slope without a sustained trial below the lowest sustained slope, that lowest slope)."""
    if not sustained.any() or sustained.all():
        return None
    high = float(np.min(slopes[sustained]))
    below = slopes[(slopes < high)]
    no_sus = [s for s in np.unique(below) if not sustained[slopes == s].any()]
    if not no_sus:
        return None
    return float(max(no_sus)), high


def firth_logistic(x: np.ndarray, y: np.ndarray, max_iter: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Firth-penalised logistic regression of y (0/1) on x: (coefficients [b0, b1], covariance)."""
    X = np.column_stack([np.ones_like(x), x])
    beta = np.zeros(2)
    for _ in range(max_iter):
        p = 1.0 / (1.0 + np.exp(-(X @ beta)))
        W = p * (1 - p)
        info = X.T @ (X * W[:, None])
        inv = np.linalg.inv(info)
        h = np.einsum("ij,jk,ik->i", X * W[:, None], inv, X)  # leverages
        score = X.T @ (y - p + h * (0.5 - p))
        step = inv @ score
        n = float(np.max(np.abs(step)))
        if n > 5:
            step *= 5 / n
        beta = beta + step
        if n < 1e-10:
            break
    p = 1.0 / (1.0 + np.exp(-(X @ beta)))
    info = X.T @ (X * (p * (1 - p))[:, None])
    return beta, np.linalg.inv(info)


def group_slopes(slopes: np.ndarray, tol_deg: float) -> np.ndarray:
    """Each slope replaced by the mean of its group (sorted slopes closer than tol_deg chain into one group)."""
    if slopes.size == 0:
        return slopes
    order = np.argsort(slopes)
    out = np.empty_like(slopes)
    start = 0
    s = slopes[order]
    for i in range(1, s.size + 1):
        if i == s.size or s[i] - s[i - 1] > tol_deg:
            out[order[start:i]] = float(np.mean(s[start:i]))
            start = i
    return out


def estimate_critical_slope(verdicts: Sequence[Verdict], files: Sequence[str], *,
                            group_tol_deg: float = 0.05) -> CriticalSlopeResult:
    """Combine per-trial verdicts into the bracket, the logistic and the extrapolated estimates.

    Trials whose slopes differ by less than ``group_tol_deg`` form one slope group (its mean slope) for the
    bracket and the logistic fit; the extrapolation uses each trial's own slope."""
    per_trial = [{"file": f, **v.as_dict()} for f, v in zip(files, verdicts)]
    decided = [v for v in verdicts if v.verdict in ("sustained", "decaying")]
    slopes = group_slopes(np.array([v.slope_deg for v in decided]), group_tol_deg)
    sus = np.array([v.verdict == "sustained" for v in decided])
    estimates: list[Estimate] = []
    bracket = _bracket(slopes, sus) if decided else None
    bracket_est = None
    if bracket is not None:
        lo, hi = bracket
        inconsistent = int(np.sum(~sus & (slopes > hi)))
        detail = (f"no sustained trial at {lo:.3f} deg or below it; sustained walking at {hi:.3f} deg")
        if inconsistent:
            detail += f" ({inconsistent} decaying trial(s) above it: slow releases or noise)"
        bracket_est = Estimate("bracket", 0.5 * (lo + hi), (lo, hi), detail)
        estimates.append(bracket_est)

    logistic = None
    uniq, counts = np.unique(slopes, return_counts=True) if decided else (np.zeros(0), np.zeros(0))
    if decided and sus.any() and (~sus).any() and uniq.size >= 2 and np.any(counts >= 2):
        x0 = float(np.mean(slopes))
        try:
            beta, cov = firth_logistic(slopes - x0, sus.astype(float))
            b0, b1 = float(beta[0]), float(beta[1])
            if b1 > 0:
                s50 = x0 - b0 / b1
                g = np.array([-1.0 / b1, b0 / b1**2])
                se = float(math.sqrt(max(g @ cov @ g, 0.0)))
                estimates.append(Estimate("logistic", s50, (s50 - Z95 * se, s50 + Z95 * se),
                                          f"Firth logistic on {sus.size} decided trials at {uniq.size} slopes: "
                                          f"P = 0.5 at {s50:.3f} deg, slope {b1:.2f} per deg"))
                logistic = (b0 - b1 * x0, b1)
        except np.linalg.LinAlgError:
            pass

    extrap = None
    fit = [v for v in verdicts if math.isfinite(v.fixed_point) and math.isfinite(v.fixed_point_se)
           and v.fixed_point_se > 0 and not v.stalled]
    if len({round(v.slope_deg, 3) for v in fit}) >= 2:
        x = np.array([v.slope_deg for v in fit])
        y = np.array([v.fixed_point for v in fit])
        w = 1.0 / np.array([v.fixed_point_se for v in fit]) ** 2
        X = np.column_stack([np.ones_like(x), x])
        XtW = X.T * w
        cov = np.linalg.inv(XtW @ X)
        c0, c1 = cov @ (XtW @ y)
        r = y - (c0 + c1 * x)
        chi2 = float(np.sum(w * r**2)) / max(x.size - 2, 1)
        cov = cov * max(chi2, 1.0)
        if c1 > 0:
            root = -c0 / c1
            g = np.array([-1.0 / c1, c0 / c1**2])
            se = float(math.sqrt(max(g @ cov @ g, 0.0)))
            estimates.append(Estimate(
                "fixed-point-extrapolation", float(root), (root - Z95 * se, root + Z95 * se),
                f"e* = {c1:.3f} (slope - {root:.3f} deg) rad²/s² per deg from {x.size} trials' return maps "
                f"(reduced chi² {chi2:.2f})"))
            extrap = (float(c0), float(c1))

    by = {e.method: e for e in estimates}
    chosen, why = None, "no trial was decided: no estimate"
    ex, lg = by.get("fixed-point-extrapolation"), by.get("logistic")

    def inside(e: Estimate) -> bool:
        if bracket is None:
            return True
        return e.ci_deg[0] <= bracket[1] and e.ci_deg[1] >= bracket[0] and bracket[0] - 0.5 * (bracket[1] - bracket[0]) <= e.value_deg <= bracket[1] + 0.5 * (bracket[1] - bracket[0])

    if ex is not None and inside(ex) and (ex.ci_deg[1] - ex.ci_deg[0]) < (
            (bracket[1] - bracket[0]) if bracket else math.inf):
        chosen = ex
        why = ("the return-map extrapolation uses every step of every trial, agrees with the bracket and has the "
               "narrowest interval")
    elif lg is not None and inside(lg):
        chosen = lg
        why = "the logistic fit agrees with the bracket" + (
            "; the return-map extrapolation does not (or is wider)" if ex is not None else "")
    elif bracket_est is not None:
        chosen = bracket_est
        why = "the bracket between decaying and sustained slopes (the other estimates are missing or disagree)"
    elif ex is not None:
        chosen = ex
        why = "no slope has both verdicts: only the return-map extrapolation is available (not checked by a bracket)"
    if chosen is None and decided:
        if sus.all():
            why = f"every decided trial is sustained: the critical slope is below {slopes.min():.3f} deg"
        elif (~sus).all():
            why = f"no decided trial is sustained: the critical slope is above {slopes.max():.3f} deg"
    return CriticalSlopeResult(per_trial, bracket, estimates, chosen, why, logistic, extrap)


def model_critical_slope(params: Any, model: str = "er", *, rtol: float = 1e-9,
                         refine_tol_rad: float = 1e-6) -> dict[str, Any]:
    """The model's critical slope (deg) with the branch end reason, or the classified failure as a message."""
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.continuation.algorithm1 import START_SLOPE_RAD, critical_slope
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.poincare import default_guess

    start = params.replace(slope_rad=START_SLOPE_RAD)
    pmap = make_map(start, model, rtol=rtol)
    try:
        cs = critical_slope(pmap, default_guess(start, model), refine_tol_rad=refine_tol_rad,
                            jacobian_factory=jacobian_factory("auto"))
    except StepFailure as err:
        return {"model": model, "critical_slope_deg": math.nan, "reason": "failed", "detail": str(err)}
    return {"model": model, "critical_slope_deg": cs.critical_slope_deg, "reason": cs.reason, "detail": cs.detail,
            "algorithm1_slope_deg": math.degrees(cs.algorithm1_slope_rad)}


def run_critical_slope(trials: Sequence[Any], files: Sequence[str], params: Any = None, *,
                       models: Sequence[str] = ("er",), calibrated: Any = None, group_tol_deg: float = 0.05,
                       progress: Callable[[str], None] | None = None) -> CriticalSlopeResult:
    """Verdicts for every trial, the estimates, and the model's critical slopes at ``params`` (and at
    ``calibrated`` parameters when given)."""
    from rimless.sim.model.params import WheelParams

    from rimless.analysis.inference.sustained import trial_verdicts

    params = params or WheelParams()
    verdicts = trial_verdicts(list(trials), params)
    if progress:
        progress("verdicts")
    res = estimate_critical_slope(verdicts, files, group_tol_deg=group_tol_deg)
    res.model = {"critical_slope_deg": {}, "detail": {}}
    for m in models:
        if progress:
            progress(f"model {m}")
        out = model_critical_slope(params, m)
        res.model["critical_slope_deg"][m] = out["critical_slope_deg"]
        res.model["detail"][m] = out
        if calibrated is not None:
            outc = model_critical_slope(calibrated, m)
            res.model["critical_slope_deg"][f"{m}_calibrated"] = outc["critical_slope_deg"]
            res.model["detail"][f"{m}_calibrated"] = outc
    res.verdicts = verdicts  # type: ignore[attr-defined]
    return res
