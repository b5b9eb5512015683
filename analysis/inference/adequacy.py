"""Model adequacy of a calibration: do the calibrated model's residuals look like the recording's own noise?

The measurement noise is estimated from the recording, apart from the model: the CoM height's white-noise sigma
from its third differences on runs of evenly spaced samples (the estimator of
`rimless.analysis.kinematics.steps.noise_sigma`, run by run: smooth motion cancels, so what is left is the markers' noise), and the impact times' sigma from what each trial's periods
leave about their own smooth trend (a geometric approach to the fixed point: `timing_noise_sd`), pooled over the
trials. Against them, per trial and overall:

- CoM height: chi^2 = sum(residual^2) / sigma_h^2 with n - 2 degrees of freedom (the trial's time shift and
  height offset are fitted);
- step periods: chi^2 = r^T S^-1 r, r the period residuals (s) and S = sigma_t^2 D D^T their covariance (a
  period is the difference of two impact times: neighbours share one), with n - 1 degrees of freedom (the
  release speed is fitted).

Each trial is held at its measured slope, whose error is shared by all its residuals and is not noise the
recording shows. A block's chi^2 therefore allows the trial's slope to lie anywhere within its stated
uncertainty: with b the block's residual change per 1-sigma of the slope (``period_slope_s``, ``com_slope_m``;
central differences at the solution) the covariance is N + b b^T, and by Sherman-Morrison
chi^2 = r^T N^-1 r - (b^T N^-1 r)^2 / (1 + b^T N^-1 b) (the chi^2 at the best slope with the measured one as a
Gaussian prior; no degree of freedom is taken). Without b the block is judged at the measured slope, exact.

Overall the sums, less one degree of freedom per fitted global. Each figure is the ratio chi^2 / dof (1 for a
model that fits to the noise) with the upper-tail p-value. The model **does not fit** when the overall misfit is
both significant (p < `ADEQUACY_P`) and material (ratio above `ADEQUACY_RATIO`: the residual variance exceeds
the noise's by that factor). A recording whose noise is smaller than its unmodelled systematic errors (a
marker offset, a filtered export) shows up the same way: the ratio then measures the model plus those errors.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: a misfit this significant (p-value of the overall chi-square) ...
ADEQUACY_P = 1e-3
#: ... and this material (residual variance over the noise variance, per block) means the model does not fit
ADEQUACY_RATIO = 2.0
_RUN_TOL = 1e-3  # a run of evenly spaced samples: spacing within 0.1 % of the median


#: degrees of freedom of a MAD noise estimate from m overlapping third differences: m / 2.72 for the MAD of m
#: independent normals (var(sigma^) = 1.36 sigma^2 / m), and overlapping third differences are correlated (-0.75,
#: +0.3, -0.05 at lags 1-3: their squares' correlations add a factor 2.31)
MAD_DOF_PER_DIFFERENCE = 1.0 / (2.72 * 2.31)


def com_noise_sd(t_s: np.ndarray, y_m: np.ndarray) -> tuple[float, int]:
    """(sigma m, differences used) of the CoM height's white noise, from third differences on the runs of evenly
    spaced samples (gaps and the samples left out next to impacts break the runs); NaN when too few."""
    t, y = np.asarray(t_s, float), np.asarray(y_m, float)
    if t.size < 8:
        return math.nan, 0
    dt = np.diff(t)
    h = float(np.median(dt))
    breaks = np.flatnonzero(np.abs(dt - h) > _RUN_TOL * h) + 1
    d3 = [np.diff(run, 3) for run in np.split(y, breaks) if run.size >= 4]
    d = np.concatenate(d3) if d3 else np.zeros(0)
    if d.size < 5:
        return math.nan, int(d.size)
    return noise_sigma_from_d3(d), int(d.size)


def noise_sigma_from_d3(d3: np.ndarray) -> float:
    """Robust white-noise sigma from its third differences (var = 20 sigma^2; MAD, 1.4826 for the normal)."""
    return float(1.4826 * np.median(np.abs(d3)) / math.sqrt(20.0))


LAMBDA_GRID = np.linspace(-0.9, 1.3, 45)  # multipliers of the periods' trend p* + a lambda^i tried per trial


def timing_noise_sd(impacts_per_trial: Sequence[np.ndarray]) -> tuple[float, int]:
    """(sigma s, degrees of freedom) of the impact times' noise, from what each trial's periods leave about their
    own smooth trend: p_i = p* + a lambda^i (the step-to-step map's approach to its fixed point or away from it,
    lambda on `LAMBDA_GRID`, the best per trial). The periods' noise is sigma^2 D D^T (differences of impact
    times), so the residual sum of squares of the linear fit (hat matrix H) has expectation sigma^2 tr((I - H)
    D D^T): sigma^2 = sum RSS / sum tr (pooled over the trials; the choice of lambda costs one more degree of
    freedom each, not counted in the trace: a slight underestimate). NaN when no trial has 5 periods."""
    rss, tr_sum, dof = 0.0, 0.0, 0
    for imp in impacts_per_trial:
        p = np.diff(np.asarray(imp, float))
        n = p.size
        if n < 5:
            continue
        i = np.arange(n, dtype=float)
        dd = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
        best = None
        for lam in LAMBDA_GRID:
            X = np.column_stack([np.ones(n), np.sign(lam) * np.abs(lam) ** i if lam != 0 else (i == 0).astype(float)])
            coef, *_ = np.linalg.lstsq(X, p, rcond=None)
            r = p - X @ coef
            val = float(r @ r)
            if best is None or val < best[0]:
                best = (val, X)
        assert best is not None
        val, X = best
        H = X @ np.linalg.pinv(X)
        rss += val
        tr_sum += float(np.trace((np.eye(n) - H) @ dd))
        dof += n - 3
    if dof <= 0 or tr_sum <= 0:
        return math.nan, 0
    return math.sqrt(rss / tr_sum), dof


def period_chi2(residuals_s: np.ndarray, sigma_t: float, slope_s: np.ndarray | None = None) -> float:
    """chi^2 of period residuals (s) whose periods are differences of impact times of noise sigma_t:
    r^T (sigma_t^2 D D^T)^-1 r, D D^T tridiagonal (2 on the diagonal, -1 beside); with ``slope_s`` (the
    residuals' change per 1-sigma of the trial's slope, s) the slope's uncertainty allowed (`_allow_slope`)."""
    r = np.asarray(residuals_s, float)
    n = r.size
    if n == 0:
        return 0.0
    cov = (2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)) * sigma_t**2
    ninv_r = np.linalg.solve(cov, r)
    if slope_s is None:
        return float(r @ ninv_r)
    b = np.asarray(slope_s, float)
    return _allow_slope(float(r @ ninv_r), float(b @ ninv_r), float(b @ np.linalg.solve(cov, b)))


def com_chi2(residuals_m: np.ndarray, sigma_h: float, slope_m: np.ndarray | None = None) -> float:
    """chi^2 of CoM-height residuals (m) against white noise sigma_h; with ``slope_m`` (their change per 1-sigma
    of the trial's slope, m) the slope's uncertainty allowed (`_allow_slope`)."""
    r = np.asarray(residuals_m, float)
    c2 = float(r @ r) / sigma_h**2
    if slope_m is None:
        return c2
    b = np.asarray(slope_m, float)
    return _allow_slope(c2, float(b @ r) / sigma_h**2, float(b @ b) / sigma_h**2)


def _allow_slope(rNr: float, bNr: float, bNb: float) -> float:
    """r^T (N + b b^T)^-1 r from r^T N^-1 r, b^T N^-1 r and b^T N^-1 b (Sherman-Morrison): the chi^2 with the
    trial's slope free within its 1-sigma prior; never below 0, the plain chi^2 when a term is not finite."""
    if not (math.isfinite(bNr) and math.isfinite(bNb) and bNb >= 0):
        return rNr
    return max(rNr - bNr * bNr / (1.0 + bNb), 0.0)


def _figure(chi2: float, dof: int, noise_dof: float) -> dict[str, Any]:
    """chi^2, dof, ratio chi^2/dof and its p-value: the F test of the residual variance against the noise's
    estimate (``noise_dof`` its degrees of freedom; the chi-square test when infinite), upper tail."""
    from scipy.stats import chi2 as chi2_dist
    from scipy.stats import f as f_dist

    if dof <= 0 or not math.isfinite(chi2):
        return {"chi2": chi2 if math.isfinite(chi2) else None, "dof": dof, "ratio": None, "p_value": None}
    ratio = chi2 / dof
    p = float(chi2_dist.sf(chi2, dof)) if not math.isfinite(noise_dof) else float(f_dist.sf(ratio, dof, noise_dof))
    return {"chi2": chi2, "dof": dof, "ratio": ratio, "p_value": p, "noise_dof": noise_dof}


def _misfit(fig: dict[str, Any]) -> bool:
    return fig["ratio"] is not None and fig["p_value"] < ADEQUACY_P and fig["ratio"] > ADEQUACY_RATIO


def adequacy(blocks: Sequence[dict[str, Any]], n_global: int) -> dict[str, Any]:
    """The adequacy figures. ``blocks``: per trial ``trial``, ``com_t_s``, ``com_m`` (measured), ``com_res_m``
    (model minus measured, at the solution), ``impacts_s`` (measured), ``period_res_s`` (simulated minus
    measured, steps reached) and, optionally, ``com_slope_m`` and ``period_slope_s`` (the residuals' change per
    1-sigma of the trial's slope: that uncertainty is then allowed). Returns ``noise`` (the sigmas with how they were measured), ``per_trial`` (each
    with ``com`` and ``periods`` figures and ``fits``), ``overall`` (``com``, ``periods``, ``total``) and
    ``fits`` with ``statement``."""
    sig_t, dof_t = timing_noise_sd([b["impacts_s"] for b in blocks])
    com_sd = [com_noise_sd(b["com_t_s"], b["com_m"]) for b in blocks]
    used = [(s, n) for s, n in com_sd if math.isfinite(s) and n > 0]
    sig_h = math.sqrt(sum(s * s * n for s, n in used) / sum(n for _, n in used)) if used else math.nan
    dof_h = sum(n for _, n in used) * MAD_DOF_PER_DIFFERENCE
    per_trial = []
    tot = {"com": [0.0, 0], "periods": [0.0, 0]}
    for b, (s_h, m_h) in zip(blocks, com_sd):
        own = math.isfinite(s_h)
        s_h = s_h if own else sig_h  # a trial too short for its own estimate: the pooled one
        nd_h = m_h * MAD_DOF_PER_DIFFERENCE if own else dof_h
        rh = np.asarray(b["com_res_m"], float)
        rp = np.asarray(b["period_res_s"], float)
        bh, bp = b.get("com_slope_m"), b.get("period_slope_s")
        c2h = (
            com_chi2(rh, s_h, bh if bh is not None and len(bh) == rh.size else None)
            if rh.size and s_h > 0
            else math.nan
        )
        c2p = (
            period_chi2(rp, sig_t, bp if bp is not None and len(bp) == rp.size else None)
            if rp.size and sig_t > 0
            else math.nan
        )
        fh, fp = _figure(c2h, rh.size - 2, nd_h), _figure(c2p, rp.size - 1, dof_t)
        for key, c2, dof in (("com", c2h, rh.size - 2), ("periods", c2p, rp.size - 1)):
            if math.isfinite(c2) and dof > 0:
                tot[key][0] += c2
                tot[key][1] += dof
        row = {"trial": b["trial"], "com_noise_mm": s_h * 1e3, "com": fh, "periods": fp}
        row["fits"] = not (_misfit(fh) or _misfit(fp))
        per_trial.append(row)
    # one degree of freedom per fitted global, taken from the CoM block (the larger)
    oc = _figure(tot["com"][0], int(tot["com"][1]) - n_global, dof_h)
    op = _figure(tot["periods"][0], int(tot["periods"][1]), dof_t)
    total = _figure(
        tot["com"][0] + tot["periods"][0], int(tot["com"][1] + tot["periods"][1]) - n_global, min(dof_h, dof_t)
    )
    fits = not (_misfit(oc) or _misfit(op))
    bad = [k for k, f in (("CoM height", oc), ("step periods", op)) if _misfit(f)]
    if not math.isfinite(sig_h) and not math.isfinite(sig_t):
        statement = "not assessed: the recordings are too short to measure their noise"
        fits = True
    elif fits:
        statement = (
            f"the model fits to the measured noise (chi^2/dof {_fmt(oc['ratio'])} CoM, {_fmt(op['ratio'])} periods)"
        )
    else:
        statement = "the model does NOT fit the trials: " + "; ".join(
            f"{k} residuals {math.sqrt(f['ratio']):.2g} times the recording's noise (chi^2/dof {f['ratio']:.3g}, "
            f"p = {f['p_value']:.2g})"
            for k, f in (("CoM height", oc), ("step periods", op))
            if k in bad
        )
    return {
        "noise": {
            "com_mm": sig_h * 1e3 if math.isfinite(sig_h) else None,
            "impact_time_ms": sig_t * 1e3 if math.isfinite(sig_t) else None,
            "com_dof": dof_h,
            "impact_time_dof": dof_t,
            "method": "from the recordings apart from the model: CoM height from its third differences on evenly "
            "spaced runs (median absolute deviation); impact times from each trial's periods about their own "
            "geometric trend, pooled; each trial's slope free within its stated uncertainty; p-values by the F "
            "test against these estimates",
        },
        "per_trial": per_trial,
        "overall": {"com": oc, "periods": op, "total": total},
        "thresholds": {"p_value": ADEQUACY_P, "ratio": ADEQUACY_RATIO},
        "fits": fits,
        "statement": statement,
    }


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.3g}"
