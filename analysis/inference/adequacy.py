"""Model adequacy of a calibration: do the calibrated model's residuals look like the recording's own noise?

The measurement noise is estimated from the recording, apart from the model: the CoM height's white-noise sigma
from its third differences on runs of evenly spaced samples (the estimator of
`rimless.analysis.kinematics.steps.noise_sigma`, run by run: smooth motion cancels, so what is left is the markers' noise), and the impact times' sigma from what each trial's periods
leave about their own trend (a geometric approach to the fixed point and a persistent alternation:
`timing_noise_sd`; a limp is a pattern, not noise), pooled over the trials and floored (`timing_noise`; trials of
6 periods or more, or when every trial is shorter those of 5 at 1 degree of freedom each, the F test carrying how
few; with 4 or fewer the periods are not judged). Against
them, per trial and overall:

- CoM height: chi^2 = sum(residual^2) / sigma_h^2 with n - 2 degrees of freedom (the trial's time shift and
  height offset are fitted), less what the import's errors take (below);
- step periods: chi^2 = r^T S^-1 r, r the period residuals (s) and S = sigma_t^2 D D^T their covariance (a
  period is the difference of two impact times: neighbours share one), with n - 1 degrees of freedom (the
  release speed is fitted).

Each trial is held at its measured slope, whose error is shared by all its residuals and is not noise the
recording shows. A block's chi^2 therefore allows the trial's slope to lie anywhere within its stated
uncertainty: with b the block's residual change per 1-sigma of the slope (``period_slope_s``, ``com_slope_m``;
central differences at the solution) the covariance is N + b b^T (the chi^2 at the best slope with the measured
one as a Gaussian prior; no degree of freedom is taken). Without b the block is judged at the measured slope.

The import makes errors that are not white noise, and the third differences do not see them (measured against
the simulator's ER truth through the Vicon writer and the importer, `rimless trials adequacy-coverage`): the CoM
height's error is white noise plus a once-a-turn sinusoid of the wheel's angle, 0.05-0.43 mm (the hub's offset
in the wheel is fitted from the height itself, `kinematics.hub.estimate_hub_offset`, and a body point off the
hub rises and falls once a turn) and a tilt (the slope frame's, a height proportional to the distance
travelled); once these are taken out what is left is white, of the third differences' sigma. These are
carried as shapes of any amplitude (`block_chi2`: generalised least squares, one degree of freedom each): sin and
cos of the wheel's angle and the angle itself (`importer_columns`; the angle from the impacts, alpha a step,
`turn_angle`) beside the offset: n - 1 - 4 degrees of freedom (the time shift).

The first period is not excused (session 16 allowed it at any amplitude, one degree of freedom per trial): the
calibration then started each walk from a rigid touchdown one step before the first measured impact, a state a
compliant wheel entering its gait does not pass through, and its first period missed by up to 4 ms on soft,
damped wheels. It now fits the first measured impact's post-impact angle as well as the release speed
(`rimless.analysis.inference.calibrate`), so the first period fits within the impact times' noise; the check
moves that angle with the calibration's own shape (``period_angle_s``, ``com_angle_m``: one degree of freedom of
the periods, the angle fitted), never the first period alone (``allowed["periods"]`` says so).

Each trial is judged as a whole when the calibration gives its residuals' change with the release speed and the
time shift (``period_release_s``, ``com_release_m``, ``com_shift_m``; `joint_chi2`): the slope (within its
uncertainty), the release speed, the time shift and the import's shapes move together in both blocks, as the
calibration fitted them. Freed in the period block alone, the release speed let the periods choose their own and
hid every misfit (the held-k and friction scenarios fitted); the calibration sets it mostly by the CoM, whose
hub-offset error biases it, which is what made the periods cry wolf when judged at the fit's release speed.

The impact times' noise measured about each trial's trend is the importer's: on the diagnosed series it matched
the imported impacts' scatter against the truth (0.22 ms estimated for 0.23 ms on object exports, 0.51 for 0.51
on marker exports); their constant offset per trial is the calibration's time shift.

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
#: fewest periods of a trial that enters the impact times' noise (its trend takes 4 degrees of freedom)
TIMING_MIN_PERIODS = 6
#: when no trial has `TIMING_MIN_PERIODS`, trials of this many periods enter instead, 1 degree of freedom each (the
#: F test then carries how few: measured on 2000 pure-noise trials of 5 periods, the pooled estimate 1.00 of the
#: truth under a transient, 1.12 without one: high, so lenient, not a false alarm); 4 periods leave none
TIMING_SHORT_MIN_PERIODS = 5
#: `timing_noise`'s ``source`` when only short trials measured it
TIMING_SHORT_SOURCE = "periods about their trend, short trials"
#: the impact times' noise is never taken below this fraction of the recording's frame interval (a sanity floor:
#: the importer places an impact to about a fortieth of a frame on clean object exports, docs/trials.md)
TIMING_FLOOR_FRAMES = 0.01
#: the choice of lambda per trial, counted as one more fitted direction of the periods: the trace it takes is
#: D D^T's mean eigenvalue, 2 (measured, 400 pure-noise trials of 6-12 periods with and without a transient: the
#: pooled estimate 0.74-0.97 of the truth without it, 0.94-1.06 with it)
LAMBDA_CHOICE_TRACE = 2.0


def timing_noise_sd(
    impacts_per_trial: Sequence[np.ndarray], min_periods: int = TIMING_MIN_PERIODS
) -> tuple[float, int]:
    """(sigma s, degrees of freedom) of the impact times' noise, from what each trial's periods leave about their
    own trend p_i = p* + a lambda^i + b (-1)^i: the step-to-step map's approach to its fixed point (lambda on
    `LAMBDA_GRID`, the best per trial) and a persistent alternation (b: a limp, unequal legs; session 22). A
    pattern the trend can take is not noise: the alternation is not, so a wheel that limps is judged against the
    recording's noise, not against its own limp (session 21: 5.7 ms estimated for 0.5 ms on c = 11 ER walks
    limping by 5 %, and the check said "fits"). The periods' noise is sigma^2 D D^T (differences of impact times),
    so the residual sum of squares of the linear fit (hat matrix H) has expectation sigma^2 tr((I - H) D D^T):
    sigma^2 = sum RSS / sum (tr - `LAMBDA_CHOICE_TRACE`), pooled over the trials with at least ``min_periods``
    periods (`TIMING_MIN_PERIODS`; `timing_noise` falls back to `TIMING_SHORT_MIN_PERIODS`); n - 4 degrees of
    freedom each (the choice of lambda counted as one: without it the estimate was
    low by 3-26 % on 6-12 periods). A negative lambda alternates (lambda^i). NaN when no trial has enough
    periods."""
    rss, tr_sum, dof = 0.0, 0.0, 0
    for imp in impacts_per_trial:
        p = np.diff(np.asarray(imp, float))
        n = p.size
        if n < max(min_periods, 5):  # the trend's 4 columns need a fifth period
            continue
        val, tr = _trend_residual(p)
        rss += val
        tr_sum += max(tr - LAMBDA_CHOICE_TRACE, 0.0)
        dof += n - 4
    if dof <= 0 or tr_sum <= 0:
        return math.nan, 0
    return math.sqrt(rss / tr_sum), dof


def _trend_residual(p: np.ndarray) -> tuple[float, float]:
    """(RSS s^2, tr((I - H) D D^T)) of periods p (s) about their best trend p* + a lambda^i + b (-1)^i."""
    n = p.size
    i = np.arange(n, dtype=float)
    alt = (-1.0) ** i
    dd = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    best = None
    for lam in LAMBDA_GRID:
        geo = lam**i if lam != 0 else (i == 0).astype(float)  # alternates for lam < 0
        X = np.column_stack([np.ones(n), geo, alt])
        coef, *_ = np.linalg.lstsq(X, p, rcond=None)
        r = p - X @ coef
        val = float(r @ r)
        if best is None or val < best[0]:
            best = (val, X)
    assert best is not None
    val, X = best
    H = X @ np.linalg.pinv(X)
    return val, float(np.trace((np.eye(n) - H) @ dd))


def timing_noise(impacts_per_trial: Sequence[np.ndarray], frame_s: float = math.nan) -> dict[str, Any]:
    """The impact times' noise the periods are judged against: `timing_noise_sd` (``sigma_s``, ``dof``), floored
    at `TIMING_FLOOR_FRAMES` of the frame interval ``frame_s`` (s; the floor not applied when NaN); ``source``
    says which was used ("periods about their trend"; `TIMING_SHORT_SOURCE` when no trial has `TIMING_MIN_PERIODS`
    periods and those of `TIMING_SHORT_MIN_PERIODS` measured it, 1 degree of freedom each; "floor"; "none" when
    no trial has `TIMING_SHORT_MIN_PERIODS`: the periods are then not judged), ``estimate_s`` the estimate before
    the floor, ``trials_used`` how many trials entered it, ``min_periods`` the fewest periods that entered."""
    min_periods = TIMING_MIN_PERIODS
    sig, dof = timing_noise_sd(impacts_per_trial, min_periods)
    if not math.isfinite(sig):
        min_periods = TIMING_SHORT_MIN_PERIODS
        sig, dof = timing_noise_sd(impacts_per_trial, min_periods)
    used = sum(np.asarray(imp).size - 1 >= min_periods for imp in impacts_per_trial)
    floor = TIMING_FLOOR_FRAMES * frame_s if math.isfinite(frame_s) and frame_s > 0 else math.nan
    out: dict[str, Any] = {"sigma_s": sig, "dof": dof, "estimate_s": sig, "floor_s": floor, "trials_used": used}
    out["min_periods"] = min_periods
    if math.isfinite(sig) and math.isfinite(floor) and sig < floor:
        out.update(sigma_s=floor, source="floor")
    elif not math.isfinite(sig):
        out.update(source="none", trials_used=0)
    else:
        out["source"] = "periods about their trend" if min_periods == TIMING_MIN_PERIODS else TIMING_SHORT_SOURCE
    return out


def timing_noise_phrase(noise: dict[str, Any]) -> str:
    """Where the impact times' noise came from, in words, from `adequacy`'s ``noise`` (its ``timing_noise_*``
    keys): for the text of `rimless trials calibrate`."""
    src = noise.get("timing_noise_source")
    if src == "floor":
        est = noise.get("timing_noise_estimate_ms")
        return f"the floor; the periods gave {est:.3f} ms" if est is not None else "the floor"
    if src == "periods about their trend":
        return f"from the periods about their trend, {noise.get('timing_noise_trials')} trials"
    if src == TIMING_SHORT_SOURCE:
        return (
            f"from the periods about their trend, {noise.get('timing_noise_trials')} short trials of "
            f"{TIMING_SHORT_MIN_PERIODS} periods (1 degree of freedom each: a wide estimate)"
        )
    if src == "none":
        return f"no trial has {TIMING_SHORT_MIN_PERIODS} periods to measure it: the periods are not judged"
    return "source not stated"


def period_chi2(
    residuals_s: np.ndarray,
    sigma_t: float,
    slope_s: np.ndarray | None = None,
    free_s: np.ndarray | None = None,
) -> float:
    """chi^2 of period residuals (s) whose periods are differences of impact times of noise sigma_t:
    r^T (sigma_t^2 D D^T)^-1 r, D D^T tridiagonal (2 on the diagonal, -1 beside); with ``slope_s`` (the
    residuals' change per 1-sigma of the trial's slope, s) the slope's uncertainty allowed, with ``free_s`` ((n, m)
    columns, s) those shapes allowed at any amplitude (`block_chi2`)."""
    r = np.asarray(residuals_s, float)
    n = r.size
    if n == 0:
        return 0.0
    cov = (2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)) * sigma_t**2
    return block_chi2(r, cov, slope_s, free_s)[0]


def com_chi2(
    residuals_m: np.ndarray,
    sigma_h: float,
    slope_m: np.ndarray | None = None,
    free_m: np.ndarray | None = None,
) -> float:
    """chi^2 of CoM-height residuals (m) against white noise sigma_h; with ``slope_m`` (their change per 1-sigma
    of the trial's slope, m) the slope's uncertainty allowed, with ``free_m`` ((n, m) columns, m) those shapes
    allowed at any amplitude (`block_chi2`)."""
    r = np.asarray(residuals_m, float)
    return block_chi2(r, sigma_h**2, slope_m, free_m)[0]


def block_chi2(
    r: np.ndarray, cov: np.ndarray | float, prior: np.ndarray | None = None, free: np.ndarray | None = None
) -> tuple[float, int]:
    """(chi^2, rank of ``free``): min over a of (r - F a)^T M^-1 (r - F a), M = N + b b^T (N = ``cov``, a matrix
    or a variance for white noise; b = ``prior``, a shape of 1-sigma amplitude: its coefficient free under a unit
    Gaussian prior), F = ``free`` (columns at any amplitude: generalised least squares, each independent column
    one degree of freedom); never below 0; a ``prior`` that is not finite or not of r's size is left out."""
    r = np.asarray(r, float)
    b = None if prior is None else np.asarray(prior, float)
    if b is not None and not (b.shape == r.shape and bool(np.all(np.isfinite(b)))):
        b = None
    if np.ndim(cov) == 0:  # white: N^-1 x = x / var, and M^-1 by Sherman-Morrison (n may be hundreds)
        var = float(cov)

        def solve(x: np.ndarray) -> np.ndarray:
            y = x / var
            return y if b is None else y - np.multiply.outer(b, b @ y) / (var + float(b @ b))

    else:
        m = np.asarray(cov, float) + (0.0 if b is None else np.outer(b, b))

        def solve(x: np.ndarray) -> np.ndarray:
            return np.linalg.solve(m, x)

    m_r = solve(r)
    c2 = float(r @ m_r)
    if free is None:
        return max(c2, 0.0), 0
    f = np.asarray(free, float).reshape(r.size, -1)
    f = f[:, np.all(np.isfinite(f), axis=0) & np.any(f != 0.0, axis=0)]
    if f.shape[1] == 0:
        return max(c2, 0.0), 0
    m_f = solve(f)
    a, g = f.T @ m_f, f.T @ m_r
    rank = int(np.linalg.matrix_rank(a, tol=1e-10 * float(np.max(np.abs(np.diag(a))))))
    return max(c2 - float(g @ np.linalg.pinv(a, rcond=1e-10) @ g), 0.0), rank


def turn_angle(t_s: np.ndarray, impacts_s: np.ndarray, alpha_rad: float) -> np.ndarray:
    """The wheel's angle (rad) at the times t_s, from its impacts alone: alpha per step, linear in time within
    a step (and extrapolated by the first and last step outside them). Its error within a step (the stance's
    speed changes) is a few hundredths of a radian: enough for the once-a-turn shapes of `importer_columns`."""
    t, imp = np.asarray(t_s, float), np.asarray(impacts_s, float)
    k = np.clip(np.searchsorted(imp, t, side="right") - 1, 0, imp.size - 2)
    return alpha_rad * (k + (t - imp[k]) / (imp[k + 1] - imp[k]))


def importer_columns(t_s: np.ndarray, impacts_s: np.ndarray, alpha_rad: float) -> np.ndarray | None:
    """(n, 4) shapes of the imported CoM height's error that are not noise: its offset (the calibration fits it,
    or it is the importer's plane's); an error of the hub's offset in the wheel (the importer fits it from the
    height itself, `kinematics.hub.estimate_hub_offset`) is a body point's height, sin and cos of the wheel's
    angle; an error of the slope frame's tilt is a height proportional to the distance travelled (the angle).
    None with fewer than two impacts."""
    imp = np.asarray(impacts_s, float)
    if imp.size < 2 or np.asarray(t_s).size == 0:
        return None
    th = turn_angle(t_s, imp, alpha_rad)
    return np.column_stack([np.ones(th.size), np.sin(th), np.cos(th), th - float(np.mean(th))])


def joint_chi2(
    rp: np.ndarray,
    cov_p: np.ndarray,
    rh: np.ndarray,
    var_h: float,
    prior: tuple[np.ndarray, np.ndarray] | None,
    free: tuple[np.ndarray, np.ndarray],
) -> tuple[float, float, int]:
    """(periods' chi^2, CoM's chi^2, rank of the free columns) of one trial judged as a whole: the periods' residuals
    ``rp`` (covariance ``cov_p``) and the CoM's ``rh`` (white, variance ``var_h``) with the same nuisances in both
    blocks: ``free`` = (Fp, Fh), columns at any amplitude (the release speed and time shift the calibration fitted,
    the import's errors: `importer_columns`), and ``prior`` = (bp, bh), the slope's shape per 1-sigma under its unit
    Gaussian prior (its penalty counted with the periods). Generalised least squares on the whitened blocks."""
    lp = np.linalg.cholesky(np.linalg.inv(cov_p)).T  # lp^T lp = cov_p^-1
    sh = 1.0 / math.sqrt(var_h)
    fp, fh = (np.asarray(f, float).reshape(n, -1) for f, n in zip(free, (rp.size, rh.size)))
    x = np.vstack([lp @ fp, fh * sh])
    y = np.concatenate([lp @ rp, rh * sh])
    n_free = fp.shape[1]
    if prior is not None:
        bcol = np.concatenate([lp @ prior[0], prior[1] * sh])
        x = np.vstack([np.column_stack([x, bcol]), np.eye(1, n_free + 1, n_free)])
        y = np.concatenate([y, [0.0]])
    scale = np.maximum(np.sqrt(np.sum(x**2, axis=0)), 1e-300)
    coef, _, rank, _ = np.linalg.lstsq(x / scale, y, rcond=1e-10)
    e = y - (x / scale) @ coef
    c2p = float(e[: rp.size] @ e[: rp.size]) + (float(e[-1] ** 2) if prior is not None else 0.0)
    c2h = float(e[rp.size : rp.size + rh.size] @ e[rp.size : rp.size + rh.size])
    return c2p, c2h, int(rank) - (prior is not None)


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


def adequacy(blocks: Sequence[dict[str, Any]], n_global: int, *, alpha_rad: float = math.pi / 4) -> dict[str, Any]:
    """The adequacy figures. ``blocks``: per trial ``trial``, ``com_t_s``, ``com_m`` (measured), ``com_res_m``
    (model minus measured, at the solution), ``impacts_s`` (measured), ``period_res_s`` (simulated minus
    measured, steps reached) and, optionally, ``com_slope_m`` and ``period_slope_s`` (the residuals' change per
    1-sigma of the trial's slope: that uncertainty is then allowed) and ``period_release_s``, ``com_release_m``,
    ``com_shift_m`` (their change with the fitted release speed and time shift, any scale: the trial is then
    judged as a whole, `joint_chi2`), ``period_angle_s`` and ``com_angle_m`` (their change with the first
    impact's angle the calibration fitted: one degree of freedom of the periods; nothing excuses the first period
    alone). ``alpha_rad``: the angle between legs. Returns ``noise`` (the sigmas with how they were measured), ``allowed`` (what each trial's
    residuals may hold besides the noise), ``per_trial`` (each with ``com`` and ``periods`` figures and ``fits``),
    ``overall`` (``com``, ``periods``, ``total``) and ``fits`` with ``statement``."""
    frames = [float(np.median(np.diff(b["com_t_s"]))) for b in blocks if np.asarray(b["com_t_s"]).size > 1]
    tn = timing_noise([b["impacts_s"] for b in blocks], float(np.median(frames)) if frames else math.nan)
    sig_t, dof_t = tn["sigma_s"], tn["dof"]
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
        c2h, dof_c = math.nan, rh.size - 2
        c2p, dof_p = math.nan, rp.size - 1
        joint = _joint_columns(b, rp.size, rh.size, alpha_rad)
        if joint is not None and s_h > 0 and sig_t > 0:  # the trial as a whole: its nuisances shared by both blocks
            cov = (2.0 * np.eye(rp.size) - np.eye(rp.size, k=1) - np.eye(rp.size, k=-1)) * sig_t**2
            bpp, bhh = _sized(bp, rp.size), _sized(bh, rh.size)
            c2p, c2h, k = joint_chi2(rp, cov, rh, s_h**2, None if bpp is None or bhh is None else (bpp, bhh), joint)
            n_angle = joint[0].shape[1] - 6  # the first impact's angle's column, when given
            dof_p -= n_angle
            dof_c -= max(k - 3 - n_angle, 0)  # release speed, time shift, offset and angle counted: the import's
        elif rh.size and s_h > 0:
            free_h = importer_columns(b["com_t_s"], b["impacts_s"], alpha_rad) if rh.size == len(b["com_t_s"]) else None
            c2h, k_h = block_chi2(rh, s_h**2, _sized(bh, rh.size), free_h)
            dof_c -= max(k_h - 1, 0)  # the offset's column was fitted already (or is the importer's plane's)
        if joint is None and rp.size and sig_t > 0:
            cov = (2.0 * np.eye(rp.size) - np.eye(rp.size, k=1) - np.eye(rp.size, k=-1)) * sig_t**2
            ap = _sized(b.get("period_angle_s"), rp.size)
            c2p, k_p = block_chi2(rp, cov, _sized(bp, rp.size), None if ap is None else ap[:, None])
            dof_p -= k_p  # the first impact's angle the calibration fitted
        fh, fp = _figure(c2h, dof_c, nd_h), _figure(c2p, dof_p, dof_t)
        for key, c2, dof in (("com", c2h, dof_c), ("periods", c2p, dof_p)):
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
            "timing_noise_source": tn["source"],
            "timing_noise_estimate_ms": tn["estimate_s"] * 1e3 if math.isfinite(tn["estimate_s"]) else None,
            "timing_noise_floor_ms": tn["floor_s"] * 1e3 if math.isfinite(tn["floor_s"]) else None,
            "timing_noise_trials": tn["trials_used"],
            "method": "from the recordings apart from the model: CoM height from its third differences on evenly "
            "spaced runs (median absolute deviation); impact times from each trial's periods about their own "
            "trend (a geometric approach to the fixed point and a persistent alternation, so a limp is not taken "
            f"for noise; trials of {TIMING_MIN_PERIODS} periods or more, or when there are none of "
            f"{TIMING_SHORT_MIN_PERIODS} at 1 degree of freedom each), pooled, floored at "
            f"{TIMING_FLOOR_FRAMES:g} of a frame (`timing_noise_source` says which was used); each trial's slope "
            "free within its stated uncertainty; the import's errors "
            "that are not noise allowed (`allowed`); p-values by the F test against these "
            "estimates",
        },
        "allowed": {
            "com": "per trial, besides its time shift and height offset: at any amplitude an error of the importer's "
            "hub offset (sin, cos of the wheel's angle) and of its slope frame's tilt (a height proportional to the "
            "distance travelled): 3 degrees of freedom",
            "periods": "per trial, its release speed and first impact's angle as the calibration fitted them, moved "
            "with the calibration's shapes: 1 degree of freedom each. The first period is no longer excused at any "
            "amplitude (not needed: the first impact's angle is fitted, and the first period fits within the impact "
            "times' noise)",
            "both": "each trial's slope within its stated uncertainty; with the calibration's shapes of the release "
            "speed and time shift, each trial judged as a whole: the slope, the release speed, the time shift and "
            "the import's errors moved together in both blocks",
        },
        "per_trial": per_trial,
        "overall": {"com": oc, "periods": op, "total": total},
        "thresholds": {"p_value": ADEQUACY_P, "ratio": ADEQUACY_RATIO},
        "fits": fits,
        "statement": statement,
    }


def _joint_columns(b: dict[str, Any], n_p: int, n_h: int, alpha_rad: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(Fp, Fh): the free columns of a trial judged as a whole (`joint_chi2`), or None without the calibration's
    shapes of the release speed (``period_release_s``, ``com_release_m``) and time shift (``com_shift_m``); with
    the first impact's angle's (``period_angle_s``, ``com_angle_m``) as a last column when given."""
    wp, wh, th = (
        _sized(b.get("period_release_s"), n_p),
        _sized(b.get("com_release_m"), n_h),
        _sized(b.get("com_shift_m"), n_h),
    )
    imp = importer_columns(b["com_t_s"], b["impacts_s"], alpha_rad) if n_h == len(b["com_t_s"]) else None
    if wp is None or wh is None or th is None or imp is None or n_p < 2:
        return None
    fp = np.column_stack([wp, np.zeros((n_p, 1 + imp.shape[1]))])
    fh = np.column_stack([wh, th, imp])
    ap, ah = _sized(b.get("period_angle_s"), n_p), _sized(b.get("com_angle_m"), n_h)
    if ap is not None and ah is not None:  # the first impact's angle the calibration fitted, in both blocks
        fp, fh = np.column_stack([fp, ap]), np.column_stack([fh, ah])
    return fp, fh


def _sized(v: Any, n: int) -> np.ndarray | None:
    """v as an array when it has n finite entries, else None (a shape that does not match is not used)."""
    if v is None:
        return None
    a = np.asarray(v, float)
    return a if a.shape == (n,) and bool(np.all(np.isfinite(a))) else None


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.3g}"
