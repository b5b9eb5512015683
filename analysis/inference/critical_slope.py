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

Every interval propagates each trial's slope uncertainty (``Verdict.slope_sigma_deg``) and the spread between
trials: the extrapolation weighs each trial by its e* and slope uncertainties and inflates by the reduced chi^2;
the logistic adds the slopes' uncertainty to its 50 % point; the bracket's ends are widened by their trials'
slope uncertainty. A bootstrap over trials that redraws each slope is reported beside each interval as a check.
Coverage of the intervals is measured by `rimless.analysis.validation.coverage` (``rimless trials coverage``).

The reported estimate is the best supported one: the extrapolation when it agrees with the bracket and is
narrower (it then uses every step of every trial); else the logistic when it agrees and is narrower; else the
bracket. Slopes in degrees at this edge, radians inside the model calls.
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
        cf, bs = getattr(self, "ci_closed_form_deg", None), getattr(self, "ci_bootstrap_deg", None)
        return {
            "method": self.method,
            "critical_slope_deg": self.value_deg,
            "ci_deg": list(self.ci_deg),
            "detail": self.detail,
            "ci_closed_form_deg": list(cf) if cf else None,
            "ci_bootstrap_deg": list(bs) if bs else None,
            "se_parts_deg": getattr(self, "se_parts_deg", None),
        }


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
    #: every wheel parameter's value, sd, unit and source (`rimless.sim.model.uncertain.WheelInput.parameters`)
    parameters: list[dict[str, Any]] | None = None
    #: the held parameters' uncertainty carried into the estimates (`rimless.analysis.inference.held`)
    held: dict[str, Any] | None = None
    #: the inertia the trials' step periods determine (`rimless.analysis.inference.stance_inertia`), when tried
    inertia: dict[str, Any] | None = None
    #: what the reader must know (a wheel input the trials contradict)
    warnings: list[str] = field(default_factory=list)

    @property
    def critical_slope_deg(self) -> float:
        return self.chosen.value_deg if self.chosen else math.nan

    def __repr__(self) -> str:
        c = self.chosen
        if c is None:
            return f"CriticalSlopeResult(no estimate: {self.why}; {len(self.per_trial)} trial(s))"
        return (
            f"CriticalSlopeResult({c.value_deg:.3f} deg, 95 % interval {c.ci_deg[0]:.3f}-{c.ci_deg[1]:.3f} deg by "
            f"{c.method}; {len(self.per_trial)} trial(s); .summary())"
        )

    def to_dict(self) -> dict[str, Any]:
        """`summary()`: the JSON object of `rimless trials critical-slope --json` (without `refused`)."""
        return self.summary()

    def summary(self) -> dict[str, Any]:
        c = self.chosen
        return {
            "critical_slope_deg": self.critical_slope_deg,
            "bracket_deg": list(self.bracket_deg) if self.bracket_deg else None,
            "ci_deg": list(c.ci_deg) if c else None,
            "method": c.method if c else None,
            "why": self.why,
            "estimates": [e.as_dict() for e in self.estimates],
            "per_trial": self.per_trial,
            "model_critical_slope_deg": self.model.get("critical_slope_deg", {}),
            "model": self.model,
            **self.held_summary(),
        }

    def held_summary(self) -> dict[str, Any]:
        """The keys ``parameters``, ``inertia_from_trials``, ``ci_with_parameters_deg`` and
        ``parameter_uncertainty`` (when computed), and ``warnings``."""
        out: dict[str, Any] = {}
        if self.parameters is not None:
            out["parameters"] = self.parameters
        if self.inertia is not None:
            out["inertia_from_trials"] = self.inertia
        out["warnings"] = list(self.warnings)
        if self.held is not None:
            tr = self.held.get("trials")
            out["ci_with_parameters_deg"] = tr["ci_deg"] if tr else None
            out["parameter_uncertainty"] = self.held
        return out


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


def _slope_sigmas(verdicts: Sequence[Verdict]) -> np.ndarray:
    """Each verdict's 1-sigma slope uncertainty, deg (0 when unknown: a trial object built without one)."""
    s = np.array([float(getattr(v, "slope_sigma_deg", math.nan)) for v in verdicts], float)
    return np.where(np.isfinite(s) & (s >= 0), s, 0.0)


def _line_root(
    x: np.ndarray, y: np.ndarray, se: np.ndarray, sx: np.ndarray
) -> tuple[float, float, float, float, float] | None:
    """Weighted line e* = c0 + c1 x and its root -c0/c1 with errors in both coordinates: the weight of a point
    is 1 / (se^2 + c1^2 sx^2) (its slope uncertainty sx moves it along the line's gradient), iterated.

    Returns (root, standard error of the root, c0, c1, reduced chi^2) or None without a rising line. The
    covariance is inflated by the reduced chi^2 when it exceeds 1 (scatter between trials beyond their stated
    uncertainties); the standard error is then scaled by t(0.975, n - 2) / 1.96 so that +-1.96 of it is the
    Student interval of a scale estimated from n - 2 degrees of freedom."""
    if np.unique(np.round(x, 6)).size < 2:
        return None
    X = np.column_stack([np.ones_like(x), x])
    c1 = 0.0
    for _ in range(4):
        w = 1.0 / (se**2 + (c1 * sx) ** 2)
        XtW = X.T * w
        try:
            cov = np.linalg.inv(XtW @ X)
        except np.linalg.LinAlgError:
            return None
        sol = cov @ (XtW @ y)
        c0, c1 = np.float64(sol[0]), np.float64(sol[1])
    r = y - (c0 + c1 * x)
    chi2 = float(np.sum(w * r**2)) / max(x.size - 2, 1)
    cov = cov * max(chi2, 1.0)
    if not c1 > 0:
        return None
    root = -c0 / c1
    g = np.array([-1.0 / c1, c0 / c1**2])
    se_root = float(math.sqrt(max(g @ cov @ g, 0.0)))
    if chi2 > 1.0 and x.size > 2:
        from scipy.stats import t as student

        se_root *= float(student.ppf(0.975, x.size - 2)) / Z95
    return float(root), se_root, float(c0), float(c1), chi2


def line_root_parts(
    x: np.ndarray, y: np.ndarray, se: np.ndarray, sx: np.ndarray, c0: float, c1: float, se_root: float
) -> dict[str, float]:
    """The root's standard error (deg) of `_line_root` split by source: ``fixed_points`` (the trials' e*
    standard errors, timing noise) and ``slopes`` (the trials' slope uncertainties moving them along the line),
    each propagated alone through the fit's final weights (their variances add up to the unscaled total), then
    ``scatter`` the factor the reduced chi^2 and Student's t put on both (1 when the points scatter less than
    their uncertainties say: never deflated)."""
    X = np.column_stack([np.ones_like(x), x])
    v_fp, v_sx = se**2, (c1 * sx) ** 2
    w = 1.0 / (v_fp + v_sx)
    B = np.linalg.solve(X.T @ (X * w[:, None]), X.T * w)  # d(c0, c1) / d(y)
    gb = np.array([-1.0 / c1, c0 / c1**2]) @ B  # d root / d(y)
    var_fp, var_sx = float(np.sum(gb**2 * v_fp)), float(np.sum(gb**2 * v_sx))
    unscaled = math.sqrt(var_fp + var_sx)
    scale = se_root / unscaled if unscaled > 0 else 1.0
    return {"fixed_points": math.sqrt(var_fp), "slopes": math.sqrt(var_sx), "scatter": scale}


def _logistic_50(slopes: np.ndarray, sus: np.ndarray) -> tuple[float, float, float, float] | None:
    """(50 % slope, its delta-method standard error, b0, b1) of the Firth logistic, or None."""
    x0 = float(np.mean(slopes))
    try:
        beta, cov = firth_logistic(slopes - x0, sus.astype(float))
    except np.linalg.LinAlgError:
        return None
    b0, b1 = float(beta[0]), float(beta[1])
    if not (b1 > 0 and np.all(np.isfinite(beta))):
        return None
    s50 = x0 - b0 / b1
    g = np.array([-1.0 / b1, b0 / b1**2])
    return s50, float(math.sqrt(max(g @ cov @ g, 0.0))), b0 - b1 * x0, b1


def _bootstrap(
    verdicts: Sequence[Verdict], sig: np.ndarray, group_tol_deg: float, n_boot: int, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """Replicates of each estimate: trials resampled with replacement (the spread between trials) and every
    resampled trial's slope moved by a normal draw of its own uncertainty (the slopes' uncertainty)."""
    n = len(verdicts)
    slope = np.array([v.slope_deg for v in verdicts], float)
    dec = np.array([v.verdict in ("sustained", "decaying") for v in verdicts])
    sus = np.array([v.verdict == "sustained" for v in verdicts])
    fp = np.array([v.fixed_point for v in verdicts], float)
    fse = np.array([v.fixed_point_se for v in verdicts], float)
    fit_ok = np.array(
        [
            math.isfinite(v.fixed_point) and math.isfinite(v.fixed_point_se) and v.fixed_point_se > 0 and not v.stalled
            for v in verdicts
        ]
    )
    out: dict[str, list[float]] = {"bracket": [], "logistic": [], "fixed-point-extrapolation": []}
    for _ in range(n_boot):
        idx = rng.integers(0, n, n)
        xs = slope[idx] + rng.normal(0.0, 1.0, n) * sig[idx]
        d = dec[idx]
        if d.any():
            gs = group_slopes(xs[d], group_tol_deg)
            su = sus[idx][d]
            b = _bracket(gs, su)
            out["bracket"].append(0.5 * (b[0] + b[1]) if b else math.nan)
            uniq, counts = np.unique(gs, return_counts=True)
            lg = _logistic_50(gs, su) if su.any() and (~su).any() and uniq.size >= 2 and np.any(counts >= 2) else None
            out["logistic"].append(lg[0] if lg else math.nan)
        f = fit_ok[idx]
        ln = _line_root(xs[f], fp[idx][f], fse[idx][f], sig[idx][f]) if f.sum() >= 2 else None
        out["fixed-point-extrapolation"].append(ln[0] if ln else math.nan)
    return {k: np.array(v, float) for k, v in out.items()}


BOOT_MIN_DEFINED = 0.8  # share of replicates an estimate must exist in for its bootstrap interval to count


def _boot_ci(reps: np.ndarray | None) -> tuple[tuple[float, float] | None, float]:
    """(2.5-97.5 % percentile interval, share of replicates where the estimate exists)."""
    if reps is None or reps.size == 0:
        return None, 0.0
    ok = reps[np.isfinite(reps)]
    share = ok.size / reps.size
    if share < BOOT_MIN_DEFINED:
        return None, share
    return (float(np.percentile(ok, 2.5)), float(np.percentile(ok, 97.5))), share


def estimate_critical_slope(
    verdicts: Sequence[Verdict], files: Sequence[str], *, group_tol_deg: float = 0.05, n_boot: int = 200, seed: int = 0
) -> CriticalSlopeResult:
    """Combine per-trial verdicts into the bracket, the logistic and the extrapolated estimates.

    Trials whose slopes differ by less than ``group_tol_deg`` form one slope group (its mean slope) for the
    bracket and the logistic fit; the extrapolation uses each trial's own slope. Each estimate's 95 % interval
    (``ci_deg``) is its closed form, which includes each trial's slope uncertainty (``Verdict.slope_sigma_deg``)
    and, through the reduced chi^2, a spread between trials beyond their stated uncertainties; the percentile
    interval of ``n_boot`` bootstrap replicates over trials with the slopes redrawn (`_bootstrap`, seeded) is
    given beside it as a check (``ci_bootstrap_deg``). Both were measured by `rimless.analysis.validation.coverage`:
    the hull of the two over-covers (100 % of 30 series), each alone is near 95 %."""
    per_trial = [{"file": f, **v.as_dict()} for f, v in zip(files, verdicts)]
    sig_all = _slope_sigmas(verdicts)
    dec_idx = [i for i, v in enumerate(verdicts) if v.verdict in ("sustained", "decaying")]
    decided = [verdicts[i] for i in dec_idx]
    slopes = group_slopes(np.array([v.slope_deg for v in decided]), group_tol_deg)
    sig_dec = sig_all[dec_idx] if dec_idx else np.zeros(0)
    sus = np.array([v.verdict == "sustained" for v in decided])
    boot = (
        _bootstrap(verdicts, sig_all, group_tol_deg, n_boot, np.random.default_rng(seed))
        if (verdicts and n_boot > 0)
        else {}
    )
    estimates: list[Estimate] = []

    def finish(method: str, value: float, ci: tuple[float, float], detail: str) -> Estimate:
        bci, share = _boot_ci(boot.get(method))
        if bci is not None:
            detail += (
                f"; bootstrap over trials with their slopes redrawn: [{bci[0]:.3f}, {bci[1]:.3f}] deg "
                f"(a check, not the reported interval)"
            )
        elif boot:
            detail += f"; no bootstrap check (the estimate exists in {share:.0%} of the replicates)"
        e = Estimate(method, float(value), (float(ci[0]), float(ci[1])), detail)
        e.ci_closed_form_deg = (float(ci[0]), float(ci[1]))  # type: ignore[attr-defined]
        e.ci_bootstrap_deg = bci  # type: ignore[attr-defined]
        return e

    bracket = _bracket(slopes, sus) if decided else None
    bracket_est = None
    if bracket is not None:
        lo, hi = bracket
        inconsistent = int(np.sum(~sus & (slopes > hi)))
        detail = f"no sustained trial at {lo:.3f} deg or below it; sustained walking at {hi:.3f} deg"
        if inconsistent:
            detail += f" ({inconsistent} decaying trial(s) above it: slow releases or noise)"
        s_lo = float(np.max(sig_dec[slopes == lo])) if sig_dec.size else 0.0
        s_hi = float(np.max(sig_dec[slopes == hi])) if sig_dec.size else 0.0
        bracket_est = finish("bracket", 0.5 * (lo + hi), (lo - Z95 * s_lo, hi + Z95 * s_hi), detail)
        estimates.append(bracket_est)

    logistic = None
    uniq, counts = np.unique(slopes, return_counts=True) if decided else (np.zeros(0), np.zeros(0))
    if decided and sus.any() and (~sus).any() and uniq.size >= 2 and np.any(counts >= 2):
        lg = _logistic_50(slopes, sus)
        if lg is not None:
            s50, se, b0, b1 = lg
            se = math.sqrt(se**2 + float(np.mean(sig_dec**2)))  # the slopes' own uncertainty on the 50 % point
            estimates.append(
                finish(
                    "logistic",
                    s50,
                    (s50 - Z95 * se, s50 + Z95 * se),
                    f"Firth logistic on {sus.size} decided trials at {uniq.size} slopes: "
                    f"P = 0.5 at {s50:.3f} deg, slope {b1:.2f} per deg",
                )
            )
            logistic = (b0, b1)

    extrap = None
    fit_idx = [
        i
        for i, v in enumerate(verdicts)
        if math.isfinite(v.fixed_point) and math.isfinite(v.fixed_point_se) and v.fixed_point_se > 0 and not v.stalled
    ]
    if len({round(verdicts[i].slope_deg, 3) for i in fit_idx}) >= 2:
        x = np.array([verdicts[i].slope_deg for i in fit_idx])
        y = np.array([verdicts[i].fixed_point for i in fit_idx])
        se_y = np.array([verdicts[i].fixed_point_se for i in fit_idx])
        ln = _line_root(x, y, se_y, sig_all[fit_idx])
        if ln is not None:
            root, se, c0, c1, chi2 = ln
            e_ex = finish(
                "fixed-point-extrapolation",
                root,
                (root - Z95 * se, root + Z95 * se),
                f"e* = {c1:.3f} (slope - {root:.3f} deg) rad²/s² per deg from {x.size} trials' return maps "
                f"(reduced chi² {chi2:.2f}, slope uncertainties in the weights)",
            )
            e_ex.se_parts_deg = line_root_parts(x, y, se_y, sig_all[fit_idx], c0, c1, se)  # type: ignore[attr-defined]
            estimates.append(e_ex)
            extrap = (c0, c1)

    by = {e.method: e for e in estimates}
    chosen, why = None, "no trial was decided: no estimate"
    ex, lg_e = by.get("fixed-point-extrapolation"), by.get("logistic")

    def inside(e: Estimate) -> bool:
        """Agrees with the bracket: its interval overlaps the bracket's (widened by the slope uncertainties) and
        its value lies within that, give or take half the bracket."""
        if bracket_est is None or bracket is None:  # both set together
            return True
        blo, bhi = bracket_est.ci_deg
        half = 0.5 * (bracket[1] - bracket[0])
        return e.ci_deg[0] <= bhi and e.ci_deg[1] >= blo and blo - half <= e.value_deg <= bhi + half

    if (
        ex is not None
        and inside(ex)
        and (ex.ci_deg[1] - ex.ci_deg[0])
        < ((bracket_est.ci_deg[1] - bracket_est.ci_deg[0]) if bracket_est else math.inf)
    ):
        chosen = ex
        why = (
            "the return-map extrapolation uses every step of every trial, agrees with the bracket and has the "
            "narrowest interval"
        )
    elif (
        lg_e is not None
        and inside(lg_e)
        and (lg_e.ci_deg[1] - lg_e.ci_deg[0])
        < ((bracket_est.ci_deg[1] - bracket_est.ci_deg[0]) if bracket_est else math.inf)
    ):
        chosen = lg_e
        why = "the logistic fit agrees with the bracket and is narrower" + (
            "; the return-map extrapolation does not (or is wider)" if ex is not None else ""
        )
    elif bracket_est is not None:
        chosen = bracket_est
        why = (
            "the bracket between decaying and sustained slopes, widened by their slope uncertainties (the other "
            "estimates are missing, disagree with it or are wider)"
        )
    elif ex is not None:
        chosen = ex
        why = "no slope has both verdicts: only the return-map extrapolation is available (not checked by a bracket)"
    if chosen is None and decided:
        if sus.all():
            why = f"every decided trial is sustained: the critical slope is below {slopes.min():.3f} deg"
        elif (~sus).all():
            why = f"no decided trial is sustained: the critical slope is above {slopes.max():.3f} deg"
    return CriticalSlopeResult(per_trial, bracket, estimates, chosen, why, logistic, extrap)


def model_critical_slope(
    params: Any, model: str = "er", *, rtol: float = 1e-9, refine_tol_rad: float = 1e-6
) -> dict[str, Any]:
    """The model's critical slope (deg) with the branch end reason, or the classified failure as a message."""
    from rimless.sim.continuation.algorithm1 import START_SLOPE_RAD, critical_slope
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.step.poincare import default_guess

    start = params.replace(slope_rad=START_SLOPE_RAD)
    pmap = make_map(start, model, rtol=rtol)
    try:
        cs = critical_slope(
            pmap, default_guess(start, model), refine_tol_rad=refine_tol_rad, jacobian_factory=jacobian_factory("auto")
        )
    except StepFailure as err:
        return {"model": model, "critical_slope_deg": math.nan, "reason": "failed", "detail": str(err)}
    return {
        "model": model,
        "critical_slope_deg": cs.critical_slope_deg,
        "reason": cs.reason,
        "detail": cs.detail,
        "algorithm1_slope_deg": math.degrees(cs.algorithm1_slope_rad),
    }


def run_critical_slope(
    trials: Sequence[Any],
    files: Sequence[str],
    params: Any = None,
    *,
    models: Sequence[str] = ("er",),
    calibrated: Any = None,
    group_tol_deg: float = 0.05,
    progress: Callable[[str], None] | None = None,
) -> CriticalSlopeResult:
    """Verdicts for every trial, the estimates, and the model's critical slopes at ``params`` (and at
    ``calibrated`` parameters when given)."""
    from rimless.analysis.inference.sustained import trial_verdicts
    from rimless.sim.model.params import WheelParams

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
        add_calibrated_model(res, calibrated, models=models)
    res.verdicts = verdicts  # type: ignore[attr-defined]
    return res


def add_calibrated_model(res: CriticalSlopeResult, calibrated: Any, *, models: Sequence[str] = ("er",)) -> None:
    """Add the model's critical slope at the ``calibrated`` parameters (keys ``<model>_calibrated``) to a
    `run_critical_slope` result."""
    for m in models:
        outc = model_critical_slope(calibrated, m)
        res.model["critical_slope_deg"][f"{m}_calibrated"] = outc["critical_slope_deg"]
        res.model["detail"][f"{m}_calibrated"] = outc
