"""The hub offset from the height of a rolling wheel, and its standard error.

A body point off the hub by e rises and falls by e once a turn; the hub only by the per-step bumps. `fit_offset`
finds the offset in the body (object or marker reference) frame from the tracked point's path and the body's
rotations on frames already chosen, with a covariance whose noise is the noise's level at once a turn
(`noise_level`), not the residuals' overall variance, which also holds what the bump model leaves at the steps,
plus a misfit part when an F test finds slow structure in the residuals (`misfit_covariance`). When the residuals'
power beside once a turn exceeds their white level by a test, the noise is modelled as white + AR(1) and the
covariance is its sandwich (`red_noise_level`: slow, correlated marker noise, whose power below once a turn the
offset soaks up); ``noise_model`` says which noise was assumed. The covariance is a 2 x 2 in the wheel plane
(``cov_m2``, its axes ``sd_axes_m``); ``sd_m`` is its worst axis.
`rimless.analysis.kinematics.hub.fit_hub_offset` (which chooses the frames and the wheel angle) is the public
entry; the names here are re-exported there.

All positions in m, angles in rad, arrays with time on the first axis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "HubOffsetFit",
    "describe_offset_fit",
    "fit_offset",
    "misfit_covariance",
    "near_turn_power",
    "noise_level",
    "red_noise_level",
    "white_level",
]

#: The hub offset fit uses at most this many frames (evenly spaced).
MAX_FIT_FRAMES = 50_000
#: Prior standard deviation of the hub offset from the tracked point, per in-plane component, m, and the nominal
#: height noise, m, that weighs it against the data in `estimate_hub_offset`.
HUB_PRIOR_SD_M = 0.04
PRIOR_NOISE_M = 0.5e-3
#: The offset fit's passes stop when the offset moves less than this, m, or after this many passes.
OFFSET_TOL_M = 1e-9
MAX_OFFSET_PASSES = 50
#: Least and most Fourier terms of the per-step bump in the offset fit (a fifth of the frames per step between).
BUMP_HARMONICS = (3, 6)
#: The offset fit trims frames whose height residual exceeds this many robust sigmas (1.4826 MAD), at most
#: `MAX_TRIMS` times.
OUTLIER_SIGMAS = 5.0
MAX_TRIMS = 5
#: Frequencies (cycles per turn) beside the offset's once a turn at which the offset fit measures the residuals'
#: power (`near_turn_power`).
SIDEBANDS_PER_TURN = (0.5, 1.5, 2.0, 2.5, 3.0)
#: Slow (red) noise is taken as found when the residuals' mean power at the sidebands exceeds their white level by
#: an F test at this false-alarm rate (`red_noise_level`); its AR(1) coefficient per frame is sought among these
#: (a grid: its likelihood's average over them, the log-likelihood divided by `RED_TEMPER` first, is taken).
RED_FALSE_ALARM = 0.05
RED_RHOS = (0.5, 0.7, 0.8, 0.9, 0.94, 0.97, 0.985, 0.993, 0.997)
RED_TEMPER = 4.0
#: Frequencies (cycles per turn) at which `red_noise_level` reads the slow noise's spectrum to fit its AR(1)
#: coefficient: half-integers up to 6 (two below the step frequency of eight legs, whose bump leftovers leak), once
#: a turn left out.
RED_SHAPE_PER_TURN = tuple(0.5 * i for i in range(1, 13) if i != 2)
#: `white_level`'s richer bump model has a Fourier term per this many frames of a step.
RICH_FRAMES_PER_TERM = 3
#: What the height model leaves out when the wheel's speed changes (a compliant leg compresses with the speed):
#: the offset fit is repeated with these slow terms added (the step-mean wheel speed, its square, and the
#: distance's square; `misfit_covariance`), and when the offset moves significantly the move's part beyond its
#: noise is added to its covariance.
SPEED_TERMS = ("speed", "speed^2", "distance^2")
#: The misfit part is added only when the slow terms take significantly more from the residuals than noise would:
#: an F test against the noise's level at once a turn, at this false-alarm rate on a walk the height model fits.
#: Session 20-21 added the offset's move beyond once its noise's mean square, which white noise alone does in
#: exp(-1) = 37 % of the walks.
MISFIT_FALSE_ALARM = 0.05
#: Kept for the contract (session 20): the move counted beyond this many times its noise's mean square before the
#: test above; no longer used by the fit.
MISFIT_NOISE_MULTIPLE = 1.0


@dataclass(frozen=True, eq=False)
class HubOffsetFit:
    """The hub offset fitted by `rimless.analysis.kinematics.hub.fit_hub_offset` (object / marker frame, m).

    Attributes
    ----------
    offset_m : (3,) the hub in the object frame, in the wheel plane (its component along the wheel axis is 0).
    cov_m2 : (3, 3) its covariance, m^2 (rank 2, in the wheel plane): the least-squares one with the noise's level at once
        a turn as the noise (`noise_level`), plus the misfit part (`misfit_covariance`): a 2 x 2 in the plane, its
        axes' variances differ (``sd_axes_m``).
    sd_m : its standard error along its worst axis in the wheel plane, m: an error e of the offset puts a
        once-a-turn sinusoid of amplitude |e| in the CoM height and turns the hub's path with the wheel.
    residual_m : RMS residual of the height model, m.
    rotation_rad : total rotation seen in the frames used.
    harmonics : Fourier terms of the per-step bump used.
    passes : least-squares passes made; ``converged`` whether the last one moved the offset by under
        `OFFSET_TOL_M` (else the offset is the last pass's).
    misfit_sd_m : the part of the covariance from the height model's misfit on a walk whose speed changes
        (`misfit_covariance`: the offset's move when `SPEED_TERMS` are added, less its noise part), as the rms of
        its two axes' sds, m; 0 when the move is not significant (``misfit_p_value`` >= `MISFIT_FALSE_ALARM`).
    noise_power : the noise's variance at once a turn over the residuals' variance (`noise_level`), the factor on
        the least-squares covariance.
    misfit_p_value : the p-value of the misfit's test (`misfit_covariance`; 1.0 when it cannot be made).
    noise_model : the noise the covariance assumed, in words: ``white`` (the residuals' level less the bump model's
        leftovers, `white_level`), ``white, raised to the power beside once a turn`` (`near_turn_power`), or
        ``white + AR(1) of R per frame`` (slow noise found by `red_noise_level`; the covariance its sandwich).
    """

    offset_m: np.ndarray
    cov_m2: np.ndarray
    sd_m: float
    residual_m: float
    rotation_rad: float
    harmonics: int
    passes: int
    converged: bool
    misfit_sd_m: float = 0.0
    noise_power: float = 1.0
    misfit_p_value: float = 1.0
    noise_model: str = "white"

    @property
    def sd_axes_m(self) -> tuple[float, float]:
        """Its standard errors along the principal axes of its covariance in the wheel plane, m (largest first:
        ``sd_axes_m[0]`` is ``sd_m``)."""
        w = np.sort(np.linalg.eigvalsh(0.5 * (self.cov_m2 + self.cov_m2.T)))[::-1]
        return float(np.sqrt(max(float(w[0]), 0.0))), float(np.sqrt(max(float(w[1]), 0.0)))

    @property
    def sd_per_axis_m(self) -> float:
        """The rms of its standard errors along the two axes of the wheel plane, m (sqrt(trace(cov) / 2)): an
        honest one makes |e|^2 / 2 average its square, where ``sd_m`` (the worst axis) bounds it."""
        return float(np.sqrt(max(float(np.trace(self.cov_m2)), 0.0) / 2.0))


def _step_speed(frame: np.ndarray, ang: np.ndarray, alpha_rad: float) -> np.ndarray:
    """The wheel's mean speed over about one step around each frame, rad per frame (``frame``: the frames' indices,
    increasing; ``ang`` their wheel angles): the angle's change over the frames half a step either side."""
    span = max(float(frame[-1] - frame[0]), 1.0)
    half = 0.5 * alpha_rad * span / max(float(np.ptp(ang)), 1e-9)  # half a step, frames
    lo = np.clip(frame - half, frame[0], frame[-1])
    hi = np.clip(frame + half, frame[0], frame[-1])
    return (np.interp(hi, frame, ang) - np.interp(lo, frame, ang)) / np.maximum(hi - lo, 1e-9)


def misfit_covariance(
    a: np.ndarray, z: np.ndarray, noise2: float, speed: np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, float]:
    """The offset's covariance (2, 2) in the wheel plane from what the height model misses when the speed changes,
    m^2, and the p-value of the test that decides it.

    The fit (design ``a``, its first two columns the offset, heights ``-z``, the noise's variance at once a turn
    ``noise2``) is repeated with `SPEED_TERMS` (the step-mean ``speed``, its square, the distance ``s`` squared;
    each centred and scaled; one that does not vary is left out). The test: what they take from the residuals'
    sum of squares, per term, over ``noise2`` is F with (terms, n - columns) degrees of freedom when the model
    fits; the misfit part is counted only when its p-value is under `MISFIT_FALSE_ALARM`. Then the residuals hold a
    slow structure F times the noise's level, which a walk of a turn or two does not tell from once a turn: the
    least-squares covariance is taken at that level ((F - 1) times it added), plus the offset's move when the
    terms are added beyond its noise, m m^T - D (D the difference of the two fits' covariances, a Hausman
    difference; kept positive semi-definite): the bias the slow terms take out, along the axes it lies on.
    Else zeros. (The fit's weak prior is left out here.)"""

    def unit(x: np.ndarray) -> np.ndarray | None:  # centred, scaled to 1; None when it does not vary (a constant)
        c = x - x.mean()
        top = float(np.abs(c).max()) if c.size else 0.0
        return None if top <= 1e-9 * max(float(np.abs(x).max()), 1e-300) else c / top

    none = (np.zeros((2, 2)), 1.0)
    su = unit(s)
    cols = [c for c in (unit(speed), unit(speed**2), None if su is None else unit(su**2)) if c is not None]
    big = np.column_stack([a, *cols]) if cols else a
    dof = big.shape[0] - big.shape[1]
    if not cols or dof < 10:
        return none
    fits = []
    for m in (a, big):  # least squares on scaled columns; (m^T m)^-1 back in the columns' units
        scale = np.maximum(np.abs(m).max(axis=0), 1e-12)
        cov = np.linalg.pinv((m / scale).T @ (m / scale)) / np.outer(scale, scale)
        sol = cov @ (m.T @ -z)
        res = m @ sol + z
        fits.append((sol[:2], cov[:2, :2] * noise2, float(res @ res)))
    from scipy.stats import f as f_dist

    q = len(cols)
    ratio = max(fits[0][2] - fits[1][2], 0.0) / q / max(noise2, 1e-300)
    p = float(f_dist.sf(ratio, q, dof))
    if p >= MISFIT_FALSE_ALARM:
        return np.zeros((2, 2)), p
    move = fits[1][0] - fits[0][0]
    excess = np.outer(move, move) - (fits[1][1] - fits[0][1])
    ew, ev = np.linalg.eigh(0.5 * (excess + excess.T))
    return (ev * np.maximum(ew, 0.0)) @ ev.T + (ratio - 1.0) * fits[0][1], p


def _bump_harmonics(ang: np.ndarray, alpha_rad: float) -> int:
    """Fourier terms for the per-step bump: a fifth of the frames per step, within `BUMP_HARMONICS`."""
    steps = max(float(np.ptp(ang)) / alpha_rad, 1.0)
    lo, hi = BUMP_HARMONICS
    return int(np.clip(ang.size / steps // 5, lo, hi))


def near_turn_power(a: np.ndarray, res: np.ndarray, ang: np.ndarray, s2: float) -> float:
    """The residuals' mean power beside once a turn over ``s2``.

    The residuals ``res`` are regressed on sin/cos of the wheel angle ``ang`` at `SIDEBANDS_PER_TURN` cycles per
    turn, each pair made orthogonal to the design ``a`` (which holds once a turn): under white noise of variance
    ``s2`` each pair's explained sum of squares over ``s2`` is chi^2 with 2 degrees of freedom; the mean of those
    over 2 is returned (1.0 when no pair is left). On a walk of one or two turns the pairs overlap (a few degrees
    of freedom in all), too few to be the noise's level alone: `noise_level` takes it only above the white level."""
    q, _ = np.linalg.qr(a)
    ratios = []
    turn = ang - ang.mean()
    for f in SIDEBANDS_PER_TURN:
        x = np.column_stack([np.cos(f * turn), np.sin(f * turn)])
        x -= q @ (q.T @ x)
        if np.linalg.norm(x) < 1e-9:
            continue
        coef, *_ = np.linalg.lstsq(x, res, rcond=None)
        fitted = x @ coef
        ratios.append(float(fitted @ fitted) / s2 / 2.0)
    return float(np.mean(ratios)) if ratios else 1.0


def white_level(a: np.ndarray, res: np.ndarray, ang: np.ndarray, s2: float, harmonics: int, alpha_rad: float) -> float:
    """The residuals' variance left by a richer bump model, over ``s2`` (at most 1).

    The height model's few Fourier terms per step cannot follow the kink of an impact: what they leave repeats every
    step, at the step frequency's multiples, and adds to the residuals' variance ``s2`` without reaching once a
    turn. The residuals ``res`` of the fit (design ``a``, with ``harmonics`` terms) are regressed on the terms from
    there up to one per `RICH_FRAMES_PER_TERM` frames of a step (made orthogonal to ``a``): what they leave, over
    its degrees of freedom, is the noise's level (1.0 when no term is added)."""
    steps = max(float(np.ptp(ang)) / alpha_rad, 1.0)
    top = int(ang.size / steps // RICH_FRAMES_PER_TERM)
    if top <= harmonics:
        return 1.0
    k = np.arange(harmonics + 1, top + 1) * (2 * np.pi / alpha_rad)
    x = np.column_stack([np.cos(np.outer(ang, k)), np.sin(np.outer(ang, k))])
    q, _ = np.linalg.qr(a)
    x -= q @ (q.T @ x)
    u, sv, _ = np.linalg.svd(x, full_matrices=False)
    u = u[:, sv > 1e-6 * max(float(sv.max()), 1e-300)]
    dof = ang.size - a.shape[1] - u.shape[1]
    if dof < 10:
        return 1.0
    p = u.T @ res
    return min(max(float(res @ res - p @ p), 0.0) / dof / max(s2, 1e-300), 1.0)


def _exp_smooth(b: np.ndarray, frame: np.ndarray, rho: float) -> np.ndarray:
    """R b for the AR(1) correlation R_ij = rho^|frame_i - frame_j| (``b`` (n, k), ``frame`` (n,) increasing frame
    indices): a forward and a backward exponential filter, O(n k) (`scipy.signal.lfilter` when the frames are evenly
    spaced, else a loop over the frames)."""
    decay = rho ** np.diff(frame)
    if decay.size and np.ptp(decay) <= 1e-12 * max(float(decay[0]), 1e-300):
        from scipy.signal import lfilter

        den = [1.0, -float(decay[0])]
        return lfilter([1.0], den, b, axis=0) + lfilter([1.0], den, b[::-1], axis=0)[::-1] - b
    fwd = np.empty_like(b)
    bwd = np.empty_like(b)
    acc = b[0].copy()
    fwd[0] = acc
    for i in range(1, b.shape[0]):
        acc = b[i] + decay[i - 1] * acc
        fwd[i] = acc
    acc = b[-1].copy()
    bwd[-1] = acc
    for i in range(b.shape[0] - 2, -1, -1):
        acc = b[i] + decay[i] * acc
        bwd[i] = acc
    return fwd + bwd - b


def red_noise_level(
    a: np.ndarray, res: np.ndarray, ang: np.ndarray, frame: np.ndarray, s2: float, white: float
) -> tuple[float, float, float, np.ndarray]:
    """The noise's variance along the offset's own columns over ``s2`` when the residuals show slow (red) noise, the
    AR(1) coefficient per frame fitted, the test's p-value and the offset's covariance (2, 2) under that noise, m^2:
    (ratio, rho, p, cov); (0.0, 0.0, p, zeros) when not found.

    The noise is modelled as white (variance w) plus AR(1) (variance r, correlation rho^|frame lag|): the residuals
    ``res`` of the fit (design ``a``) are read along the sidebands of `RED_SHAPE_PER_TURN` (sin/cos of the wheel
    angle ``ang``, made orthogonal to ``a``: the power there is w + r tr(U^T R U) / k) and in bulk (``white`` x
    ``s2``, the residuals' variance less the bump model's leftovers: w + r tr(M R) / (n - p), M the residual
    projector). Slow noise is taken as found when the sidebands' mean power exceeds the bulk's by an F test at
    `RED_FALSE_ALARM`; then for each rho of `RED_RHOS` w and r follow from the bulk and the sidebands' mean, the
    rhos are averaged by the sidebands' likelihood (each power model x chi^2_k / k; tempered by `RED_TEMPER`: a
    turn or two does not pin rho, and the best fit alone jumps between far rhos), and the noise's variance along
    the offset's columns (the rows of
    a^+ for its two components, which over a turn or two reach lower frequencies than any sideband left
    orthogonal to the design) is w + r tr(W R W^T) / tr(W W^T); the covariance is W (w I + r R) W^T (a sandwich:
    the correlation shapes it too). On white noise the test keeps the white level."""
    from scipy.stats import f as f_dist

    q, _ = np.linalg.qr(a)
    turn = ang - ang.mean()
    bases, powers = [], []
    for f in RED_SHAPE_PER_TURN:
        x = np.column_stack([np.cos(f * turn), np.sin(f * turn)])
        x -= q @ (q.T @ x)
        u, sv, _ = np.linalg.svd(x, full_matrices=False)
        u = u[:, sv > 1e-3 * np.sqrt(ang.size)]
        if u.shape[1]:
            bases.append(u)
            powers.append(float(np.sum((u.T @ res) ** 2)) / u.shape[1])
    k = sum(u.shape[1] for u in bases)
    n, p_cols = a.shape
    bulk = white * s2
    none = np.zeros((2, 2))
    if not bases or n - p_cols < 10 or bulk <= 0.0:
        return 0.0, 0.0, 1.0, none
    mean_power = float(np.dot(powers, [u.shape[1] for u in bases])) / k
    p_value = float(f_dist.sf(mean_power / bulk, k, n - p_cols))
    if p_value >= RED_FALSE_ALARM:
        return 0.0, 0.0, p_value, none
    w_rows = np.linalg.pinv(a)[:2].T  # (n, 2)
    dofs = np.array([u.shape[1] for u in bases], float)
    fits = []  # per rho: -log likelihood of the sideband powers, rho, the covariance
    for rho in RED_RHOS:
        c_bulk = (n - float(np.sum(q * _exp_smooth(q, frame, rho)))) / (n - p_cols)
        c_sb = np.array([float(np.sum(u * _exp_smooth(u, frame, rho))) / u.shape[1] for u in bases])
        c_mean = float(np.dot(c_sb, dofs)) / k
        if c_mean <= c_bulk * (1.0 + 1e-9):
            continue
        r = (mean_power - bulk) / (c_mean - c_bulk)
        w = max(bulk - r * c_bulk, 0.0)
        model = np.maximum(w + r * c_sb, 1e-300)  # each sideband's power is model x chi^2_k / k
        cov = w * w_rows.T @ w_rows + r * w_rows.T @ _exp_smooth(w_rows, frame, rho)
        fits.append((0.5 * float(np.dot(dofs, np.log(model) + np.asarray(powers) / model)), rho, 0.5 * (cov + cov.T)))
    if not fits:
        return 0.0, 0.0, p_value, none
    nll = np.array([f[0] for f in fits])
    weight = np.exp(-(nll - nll.min()) / RED_TEMPER)
    weight /= weight.sum()  # the rhos averaged by their likelihood (a flat prior on the grid)
    cov = sum(wt * f[2] for wt, f in zip(weight, fits))
    rho = float(np.dot(weight, [f[1] for f in fits]))
    return float(np.trace(cov)) / float(np.sum(w_rows**2)) / s2, rho, p_value, cov


def noise_level(a: np.ndarray, res: np.ndarray, ang: np.ndarray, s2: float, harmonics: int, alpha_rad: float) -> float:
    """The noise's variance at the offset's once a turn over the residuals' variance ``s2``: the white level
    (`white_level`), or the residuals' power beside once a turn (`near_turn_power`) where that is larger (a slow
    misfit, as when a compliant leg compresses more as the wheel speeds up)."""
    return max(white_level(a, res, ang, s2, harmonics, alpha_rad), near_turn_power(a, res, ang, s2))


def fit_offset(
    rot: Any,
    t: np.ndarray,
    ang: np.ndarray,
    axis: np.ndarray,
    frame: np.ndarray,
    *,
    alpha_rad: float = np.pi / 4,
    harmonics: int | None = None,
) -> HubOffsetFit:
    """The height fit of `rimless.analysis.kinematics.hub.fit_hub_offset` on chosen frames (its doc says what is
    fitted): ``rot`` (k, 3, 3) world-from-body, ``t`` (k, 3) the tracked point, m, ``ang`` (k,) the wheel angle,
    rad, ``frame`` (k,) the frames' indices (increasing), all finite; ``axis`` (3,) the world wheel axis.

    The covariance is the least-squares one with the noise's variance at once a turn (`noise_level`: the
    residuals' variance over n - p degrees of freedom, less the bump model's leftovers at the steps, or their power
    beside once a turn where larger) as the noise's variance, with the prior of
    `HUB_PRIOR_SD_M` on each in-plane component, plus what the height model misses when the wheel's speed
    changes, when a test finds it (`misfit_covariance`, ``misfit_sd_m``, ``misfit_p_value``).
    """
    r = np.asarray(rot)
    total = float(np.ptp(ang))
    # The wheel axis in the object frame and two unit vectors spanning the wheel plane.
    a_body = np.einsum("nji,j->ni", r, axis).mean(axis=0)
    a_body /= np.linalg.norm(a_body)
    e1 = np.cross(a_body, [1.0, 0.0, 0.0] if abs(a_body[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a_body, e1)
    plane = np.column_stack([e1, e2])  # (3, 2)
    n_harm = _bump_harmonics(ang, alpha_rad) if harmonics is None else int(harmonics)
    k = np.arange(1, n_harm + 1) * (2 * np.pi / alpha_rad)
    bumps = np.column_stack([np.cos(np.outer(ang, k)), np.sin(np.outer(ang, k))]) if n_harm else np.zeros((ang.size, 0))
    in_plane = r[:, 2, :] @ plane  # (n, 2): the world height of the in-plane body axes
    # the prior: the tracked point lies within a few cm of the hub (rows g / sd * noise, noise 0.5 mm)
    prior = np.zeros((2, 4 + bumps.shape[1]))
    prior[0, 0] = prior[1, 1] = PRIOR_NOISE_M / HUB_PRIOR_SD_M
    d = np.zeros(3)
    a = np.zeros((ang.size, prior.shape[1]))
    sol = np.zeros(prior.shape[1])
    s = np.zeros(ang.size)
    use = np.ones(ang.size, bool)  # frames not trimmed as outliers
    passes, trims, converged = 0, 0, False
    while passes < MAX_OFFSET_PASSES:
        passes += 1
        path = t + r @ d
        xy = path[:, :2] - path[0, :2]
        _, _, vt = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)
        s = xy @ vt[0]
        a = np.column_stack([in_plane, -np.ones(len(s)), -s, bumps])
        ap = np.vstack([a[use], prior])
        scale = np.maximum(np.abs(ap).max(axis=0), 1e-3)
        sol, *_ = np.linalg.lstsq(ap / scale, np.concatenate([-t[use, 2], np.zeros(2)]), rcond=None)
        sol = sol / scale
        d_new = plane @ sol[:2]
        converged = bool(np.linalg.norm(d_new - d) < OFFSET_TOL_M)
        d = d_new
        if converged:
            # frames the model does not describe (a hand at the release, a knock): trimmed, and the fit repeated
            res = a @ sol + t[:, 2]
            sigma = 1.4826 * float(np.median(np.abs(res[use])))
            keep = np.abs(res) <= OUTLIER_SIGMAS * max(sigma, 1e-6)
            if trims >= MAX_TRIMS or np.array_equal(keep, use) or keep.sum() < max(10, a.shape[1] + 2):
                break
            use, trims = keep, trims + 1
    a, t = a[use], t[use]
    res = a @ sol + t[:, 2]
    dof = max(a.shape[0] - a.shape[1], 1)
    s2 = max(float(res @ res) / dof, 1e-18)
    white = white_level(a, res, ang[use], s2, n_harm, alpha_rad)
    power = max(white, near_turn_power(a, res, ang[use], s2))  # `noise_level`
    red, rho, _, red_cov = red_noise_level(a, res, ang[use], frame[use], s2, white)
    noise_model = "white" if power <= white else "white, raised to the power beside once a turn"
    if red > power:
        power = red
        noise_model = f"white + AR(1) of {rho:.3f} per frame"
    noise2 = max(s2 * power, 1e-18)  # the noise's variance along the offset's columns
    info = a.T @ a / noise2
    info[0, 0] += 1.0 / HUB_PRIOR_SD_M**2
    info[1, 1] += 1.0 / HUB_PRIOR_SD_M**2
    try:
        c2 = np.linalg.inv(info)[:2, :2]
    except np.linalg.LinAlgError:
        c2 = np.eye(2) * HUB_PRIOR_SD_M**2
    c2 = 0.5 * (c2 + c2.T)
    if noise_model.startswith("white + AR(1)"):  # the sandwich under the fitted noise, the prior's share kept
        c2 = red_cov @ np.linalg.pinv(np.eye(2) + red_cov / HUB_PRIOR_SD_M**2)  # (C^-1 + P^-1)^-1
        c2 = 0.5 * (c2 + c2.T)
    speed = _step_speed(frame, ang, alpha_rad)[use]
    misfit, misfit_p = misfit_covariance(a, t[:, 2], noise2, speed, s[use])
    c2 = c2 + misfit
    sd = float(np.sqrt(max(np.linalg.eigvalsh(c2).max(), 0.0)))
    rms = float(np.sqrt(np.mean(res**2)))
    return HubOffsetFit(
        d,
        plane @ c2 @ plane.T,
        sd,
        rms,
        total,
        n_harm,
        passes,
        converged,
        float(np.sqrt(max(float(np.trace(misfit)), 0.0) / 2.0)),
        power,
        misfit_p,
        noise_model,
    )


def describe_offset_fit(fit: HubOffsetFit) -> str:
    """The offset and how it was fitted, in words (for a hub source)."""
    d = fit.offset_m * 1e3
    stop = "" if fit.converged else f", stopped on its budget of {fit.passes} passes"
    misfit = (
        f" (with {fit.misfit_sd_m * 1e3:.3f} mm in quadrature: the misfit as the speed changes)"
        if fit.misfit_sd_m
        else ""
    )
    return (
        f"[{d[0]:.1f}, {d[1]:.1f}, {d[2]:.1f}] mm (centre of rotation fitted on the walking window from the height, "
        f"standard error {fit.sd_m * 1e3:.3f} mm{misfit}, the noise near once a turn {fit.noise_power:.2f} x the "
        f"residuals' variance, noise model {fit.noise_model}, residual {fit.residual_m * 1e3:.2f} mm{stop})"
    )
