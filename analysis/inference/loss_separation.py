"""Can the trials tell the leg damping c from a constant loss per step (e.g. Coulomb friction in the leg guides)?

A damper of coefficient c dissipates c * integral(L1'^2 dt) per step, a Coulomb force F_c on the same stroke
F_c * integral(|L1'| dt): per unit of dissipated energy their effects on a trial are the same (both only take
energy out of the stance leg's compression), and their ratio is the trial's effective leg speed
``v_eff = integral(L1'^2 dt) / integral(|L1'| dt)`` (m/s). So, to first order, the residuals' sensitivity to a
friction force is the sensitivity to c divided by v_eff, trial by trial. When the trials' v_eff hardly differ,
that column is (nearly) parallel to c's and the fit cannot say which of the two losses it sees: a fitted c is
then an effective loss coefficient for these trials, not the leg's damping.

`loss_separation` adds that friction-like column to the calibration's Jacobian (per-trial unknowns profiled out,
`rimless.analysis.inference.identifiability.least_squares_report`): whether c would still be determined with such
a loss also free, and whether the residuals point along it (a score test). It is a first-order check (the
energy lost per step; the shape of the force within a step is not modelled), not a fit of friction.
Pure numpy on the Jacobian; used by `rimless.analysis.inference.calibrate`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from rimless.analysis.inference.identifiability import least_squares_report

__all__ = ["effective_leg_speed", "loss_separation", "SEPARATION_REL_SE", "SEPARATION_BAND_LEVEL", "SCORE_ALPHA"]

#: c counts as told apart from a constant loss when, with that loss also free, its relative standard error stays
#: within this (a 95 % interval within about +-10 %): a looser bound lets a c biased by tens of per cent by guide
#: friction pass (the bundled critical series: c 13 against a true 10 with 0.06 N of friction, 9 % with it free)
SEPARATION_REL_SE = 0.05
#: the verdict is **borderline** when this two-sided confidence interval of c's relative standard error (with the
#: friction-like loss free) holds `SEPARATION_REL_SE`: the standard error is itself estimated (from the trials'
#: scatter, ``se_dof`` = trials - 1, or from the residuals' RMS), so another noise draw of the same wheel may land on
#: the other side (session 21's audit: 4.76 % then 5.12 % on two draws). Interval: `rel_se_band` (the se's
#: chi-square scatter and c's own, a factor about 1 +- z rel, in quadrature in logarithms)
SEPARATION_BAND_LEVEL = 0.90
#: significance of the score test above which the residuals are said to show a constant loss per step
SCORE_ALPHA = 0.01


def effective_leg_speed(t_s: np.ndarray, dl1_m_s: np.ndarray) -> float:
    """integral(L1'^2 dt) / integral(|L1'| dt) in m/s over a walk's samples (sorted by time, repeated times
    dropped); NaN when the leg never moves."""
    t = np.asarray(t_s, float)
    v = np.asarray(dl1_m_s, float)
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
    t, v = t[keep], v[keep]
    if t.size < 2:
        return math.nan
    dt = np.diff(t)
    a2 = float(np.sum(0.5 * (v[1:] ** 2 + v[:-1] ** 2) * dt))
    a1 = float(np.sum(0.5 * (np.abs(v[1:]) + np.abs(v[:-1])) * dt))
    return a2 / a1 if a1 > 0 else math.nan


def loss_separation(
    J: np.ndarray,
    r: np.ndarray,
    offs: np.ndarray,
    n_global: int,
    j_c: int,
    c_value: float,
    se_inflation: float,
    v_eff: np.ndarray,
    scale: np.ndarray,
    max_rel_se: float = SEPARATION_REL_SE,
    se_dof: float | None = None,
) -> dict[str, Any]:
    """Whether c (global column ``j_c`` of the scaled-residual Jacobian J, trial i's rows offs[i]:offs[i+1],
    residuals r at the solution) can be told from a constant loss per step, given each trial's effective leg
    speed ``v_eff`` (m/s), and whether the residuals show such a loss.

    - separable: with the friction-like parameter also free, c's relative standard error (model-based, times
      ``se_inflation``, the ratio of the reported to the model-based error) stays within ``max_rel_se``;
    - borderline: ``max_rel_se`` lies inside the `SEPARATION_BAND_LEVEL` interval of that relative standard error,
      ``se_dof`` its degrees of freedom (the trials' count less one when the trials' scatter set the error; None:
      the residual rows less the columns, the RMS residuals' own);
    - constant-loss signal: the score test of the friction-like column, trial-clustered (robust to correlated
      residuals within a trial): s_i = trial i's gradient along the column with every other column projected
      out, in units of its spread (column norm times the trial's RMS residual), whose mean is zero when the
      model lacks no constant loss; a one-sample t test of the s_i (n - 1 degrees of freedom).

    Returns ``separable``, ``absorbs_constant_loss`` (p < `SCORE_ALPHA`), ``correlation`` (of c with the friction-like
    parameter, per-trial unknowns profiled out), ``c_rel_se_with_friction``, ``score_p``, ``leg_speed_m_s``
    ([min, max]) and ``note``; ``damping_identified`` is True only when separable and no signal; and
    ``c_rel_se_limit`` (``max_rel_se``), ``c_rel_se_dof``, ``c_rel_se_with_friction_ci90`` ([lo, hi] or None) and
    ``borderline`` (bool: the point verdict on ``separable`` may flip on another noise draw)."""
    from scipy import stats

    v = np.asarray(v_eff, float)
    good = np.isfinite(v) & (v > 0)
    out: dict[str, Any] = {
        "separable": False,
        "absorbs_constant_loss": None,
        "damping_identified": False,
        "correlation": None,
        "c_rel_se_with_friction": None,
        "c_rel_se_limit": max_rel_se,
        "c_rel_se_dof": None,
        "c_rel_se_with_friction_ci90": None,
        "borderline": False,
        "score_p": None,
        "leg_speed_m_s": [float(np.min(v[good])), float(np.max(v[good]))] if good.any() else None,
    }
    if not good.all():
        out["note"] = "a trial's leg never moved in the simulation: the loss mechanism cannot be checked"
        return out
    col = np.zeros(J.shape[0])
    v_ref = float(np.mean(v))
    for i in range(offs.size - 1):
        col[offs[i] : offs[i + 1]] = J[offs[i] : offs[i + 1], j_c] * (v_ref / v[i])
    Ja = np.concatenate([J[:, :n_global], col[:, None], J[:, n_global:]], axis=1)
    sc = np.concatenate([np.asarray(scale[:n_global], float), [1.0], np.asarray(scale[n_global:], float)])
    se, corr, ok, _ = least_squares_report(Ja, n_global + 1, sc)
    rc = float(corr[j_c, n_global])
    out["correlation"] = rc if math.isfinite(rc) else None
    rel = float(se[j_c]) * se_inflation / abs(c_value) if c_value else math.inf
    out["c_rel_se_with_friction"] = rel if math.isfinite(rel) else None
    sep = bool(ok[j_c] and ok[n_global] and math.isfinite(rel) and rel <= max_rel_se)
    out["separable"] = sep
    nu = float(se_dof) if se_dof is not None else float(max(Ja.shape[0] - Ja.shape[1], 1))
    out["c_rel_se_dof"] = nu
    if ok[j_c] and ok[n_global] and math.isfinite(rel):
        band = rel_se_band(rel, nu)
        out["c_rel_se_with_friction_ci90"] = list(band)
        out["borderline"] = bool(band[0] <= max_rel_se <= band[1])
    # score test: the friction-like column with every other column (globals and per-trial unknowns) projected out
    B, *_ = np.linalg.lstsq(J, col, rcond=None)
    perp = col - J @ B
    n_t = offs.size - 1
    s_i = np.zeros(n_t)
    for i in range(n_t):  # each trial's gradient in units of its own spread under no constant loss
        pi, ri = perp[offs[i] : offs[i + 1]], r[offs[i] : offs[i + 1]]
        scale_i = float(np.linalg.norm(pi)) * float(np.sqrt(np.mean(ri**2))) if ri.size else 0.0
        s_i[i] = float(pi @ ri) / scale_i if scale_i > 0 else 0.0
    den = float(np.std(s_i, ddof=1)) / math.sqrt(n_t) if n_t >= 2 else 0.0
    if n_t >= 2 and den > 0:
        t = float(np.mean(s_i)) / den
        p = float(2 * stats.t.sf(abs(t), n_t - 1))
        out["score_p"] = p
        out["absorbs_constant_loss"] = p < SCORE_ALPHA
    lo, hi = out["leg_speed_m_s"]
    speeds = f"the trials' effective leg speeds span {lo:.3f}-{hi:.3f} m/s"
    near = _borderline_text(out, sep) if out["borderline"] else ""
    if not sep:
        rs = _pct(rel) + f" (limit {_pct(max_rel_se)})" if math.isfinite(rel) else "unbounded"
        # no correlation when the two are not both determined (one trial: a NaN printed "+nan")
        corr_txt = f" (correlation {rc:+.2f})" if math.isfinite(rc) else " (the two are not both determined)"
        out["note"] = (
            f"c cannot be told from a constant loss per step such as guide friction: {speeds}, and with a "
            f"friction-like loss also free c's relative uncertainty would be {rs}{corr_txt}; the fitted c is "
            "an effective loss of these trials, not the leg's damping" + near
        )
    elif out["absorbs_constant_loss"]:
        out["note"] = (
            f"the residuals show a constant loss per step the model lacks (score test p = "
            f"{out['score_p']:.2g}; {speeds}): c absorbs it (guide friction?), so it is an effective loss "
            "of these trials, not the leg's damping"
        )
    else:
        out["damping_identified"] = True
        p_txt = f"p = {out['score_p']:.2g}" if out["score_p"] is not None else "untested"
        out["note"] = (
            f"{speeds}: enough to tell a speed-dependent from a constant loss per step (c's relative standard "
            f"error {_pct(rel)} with one free, limit {_pct(max_rel_se)}), and the residuals show no constant loss "
            f"({p_txt})" + near
        )
    return out


def rel_se_band(rel: float, dof: float, level: float = SEPARATION_BAND_LEVEL) -> tuple[float, float]:
    """The two-sided ``level`` interval (dimensionless) of a relative standard error ``rel`` = se / |c| on another
    noise draw: in logarithms, the se's own half-widths, log sqrt(dof / chi^2_dof) at the level's quantiles (its
    square taken as chi^2_dof / dof distributed), and c's scatter, z * rel (a normal z at the level; log |c| has sd
    about rel), added in quadrature side by side."""
    from scipy.stats import chi2, norm

    a = 0.5 * (1.0 - level)
    z = float(norm.ppf(1.0 - a))
    down = math.log(math.sqrt(float(chi2.ppf(1.0 - a, dof)) / dof))
    up = math.log(math.sqrt(dof / float(chi2.ppf(a, dof))))
    c_part = z * rel
    return rel * math.exp(-math.hypot(down, c_part)), rel * math.exp(math.hypot(up, c_part))


def _pct(x: float) -> str:
    """A fraction as a percentage with one decimal below 10 % ("4.8%"), none above ("12%")."""
    return f"{x:.1%}" if abs(x) < 0.1 else f"{x:.0%}"


def _borderline_text(out: dict[str, Any], sep: bool) -> str:
    """The note's borderline clause: the relative se's interval around the limit, and what another draw may say."""
    lo, hi = out["c_rel_se_with_friction_ci90"]
    dof = out["c_rel_se_dof"]
    other = "not be told apart" if sep else "be told apart"
    return (
        f"; a borderline verdict: the limit {_pct(out['c_rel_se_limit'])} lies inside that relative error's "
        f"{SEPARATION_BAND_LEVEL:.0%} interval {_pct(lo)}-{_pct(hi)} ({dof:g} degrees of freedom), so on another "
        f"noise draw of these trials the two may {other}"
    )
