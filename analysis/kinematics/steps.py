"""Step detection: impacts from the wheel rotation (one step per alpha = 45 deg), else from CoM-height minima.

In the model the stance leg rotates by alpha between impacts, so the wheel angle at impacts is an
arithmetic sequence ``phase + k * alpha``; the phase is taken from the CoM-height minima, which coincide
with impacts (two legs touch, the hub is lowest). A trial too noisy or gappy to support a detection is
refused (`StepResult.refused` holds the reason), never guessed. Impacts are found per observed segment: one
whose bracketing frames fall in a gap is not reported, and a period is reported only when both its impacts
were observed with no unbridged gap between them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rimless.analysis.io.trial import ALPHA_RAD

__all__ = [
    "StepResult",
    "noise_sigma",
    "find_com_minima",
    "refine_cusp",
    "refine_cusps",
    "refine_kinks",
    "detect_steps",
    "impact_time_sd",
    "ALPHA_RAD",
]

#: Half window of the kink fit at each impact, frames (clipped to a fifth of a step).
KINK_HALF_FRAMES = (4, 10)
#: CoM minima agree on the impacts' phase when within this much of it (a fifth of a step, in phase radians) ...
MINIMA_PHASE_TOL = 2 * np.pi / 5
#: ... and at least this fraction of them must agree.
MINIMA_AGREE_FRACTION = 0.6
#: The kink is sought this far (frames) either side of the first placement of the impact.
KINK_SEARCH_FRAMES = 1.5
#: A stance's height before its touchdown (`_first_touchdown`) is taken over the frames this far before the
#: placed impact, fractions of a step of rotation (the impact's own frame left out).
TOUCHDOWN_WINDOW = (1 / 40, 1 / 3)
#: ... from at least this many frames;
TOUCHDOWN_MIN_FRAMES = 3
#: ... and the first touchdown is not moved by more than this fraction of a step (a few mm of leg compression
#: move it by well under a tenth).
TOUCHDOWN_MAX_SHIFT = 0.1
#: Half window (frames) of the angle's rate at an impact (`impact_time_sd`).
RATE_HALF_FRAMES = 3


@dataclass(frozen=True, eq=False)
class StepResult:
    """Impacts and step periods.

    Attributes
    ----------
    impact_time_s : (m,) impact times, s (sub-frame, interpolated).
    step_period_s : (p,) time between two consecutive observed impacts with no gap between them, s.
    method : ``"rotation"``, ``"com-minima"`` or ``"none"``.
    refused : None, or why no detection is given.
    phase_rad : wheel angle of the first impact (rotation method), rad, or None.
    """

    impact_time_s: np.ndarray
    step_period_s: np.ndarray
    method: str
    refused: str | None = None
    phase_rad: float | None = None
    impact_step: np.ndarray | None = None  # (m,) steps since the first observed impact (gaps skip numbers)
    period_step: np.ndarray | None = None  # (p,) impact_step of the impact ending each period
    #: (m,) each impact's time sd, s (NaN: not estimable; `impact_time_sd`): its own error, apart from a shift
    #: common to all the trial's impacts (the phase); None: not estimated
    impact_sd_s: np.ndarray | None = None

    @property
    def step_number(self) -> np.ndarray:
        """1-based number of each step in ``step_period_s`` (counted from the first observed impact)."""
        if self.period_step is not None:
            return np.asarray(self.period_step, np.int64)
        return np.arange(1, self.step_period_s.size + 1)

    @classmethod
    def refuse(cls, reason: str) -> StepResult:
        """A result carrying no steps and the reason."""
        return cls(
            np.zeros(0), np.zeros(0), "none", reason, None, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        )


def noise_sigma(y: np.ndarray) -> float:
    """Robust white-noise sigma from third differences (smooth signals cancel), same unit as ``y``."""
    d = np.diff(y[~np.isnan(y)], 3)
    if d.size < 5:
        return float("nan")
    np.abs(d, out=d)
    return float(1.4826 * np.median(d, overwrite_input=True) / np.sqrt(20.0))


def refine_cusp(t: np.ndarray, y: np.ndarray, i: int, half: int) -> tuple[float, float]:
    """Sub-frame cusp minimum near sample i: where parabolas fitted on each side meet (time, value).

    Parabolas, not lines, so that the curvature of each side (the hub swings on an arc) does not bias the
    value. Falls back to the sample itself when a side is too short or the meeting point is not within
    one sample of i.
    """
    lo, hi = max(i - half, 0), min(i + half, y.size - 1)
    if i - lo < 3 or hi - i < 3 or np.isnan(y[lo : hi + 1]).any():
        return float(t[i]), float(y[i])
    tl, tr = t[lo : i + 1] - t[i], t[i : hi + 1] - t[i]
    pl = np.polyfit(tl, y[lo : i + 1], 2)
    pr = np.polyfit(tr, y[i : hi + 1], 2)
    roots = np.roots(pl - pr) if np.any(pl - pr) else np.zeros(0)
    roots = roots[np.isreal(roots)].real
    roots = roots[(roots >= t[i - 1] - t[i]) & (roots <= t[i + 1] - t[i])]
    if roots.size == 0:
        return float(t[i]), float(y[i])
    tc = float(roots[np.argmin(np.abs(roots))])
    if np.polyval(np.polyder(pl), tc) > 0 or np.polyval(np.polyder(pr), tc) < 0:
        return float(t[i]), float(y[i])
    return float(t[i] + tc), float(np.polyval(pl, tc))


def refine_cusps(t: np.ndarray, y: np.ndarray, idx: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """`refine_cusp` for many minima at once (same result): (times, values).

    On a uniform time grid every full window shares one Vandermonde matrix, so the parabola fits are one
    matrix product; windows at the edges, over NaN or on a non-uniform grid go through `refine_cusp`.
    """
    idx = np.asarray(idx, np.int64)
    tc = t[idx].astype(np.float64).copy()
    yc = y[idx].astype(np.float64).copy()
    if idx.size == 0:
        return tc, yc
    dt = np.diff(t)
    uniform = dt.size > 0 and np.allclose(dt, dt[0], rtol=1e-9, atol=0.0)
    full = (idx - half >= 1) & (idx + half <= y.size - 2) & (half >= 3)
    if uniform and full.any():
        sel = idx[full]
        off = np.arange(-half, 1)
        yl = y[sel[:, None] + off]
        yr = y[sel[:, None] + np.arange(0, half + 1)]
        ok = ~(np.isnan(yl).any(axis=1) | np.isnan(yr).any(axis=1))
        h = float(dt[0])
        xl, xr = off * h, np.arange(0, half + 1) * h
        pl = yl @ np.linalg.pinv(np.vander(xl, 3)).T  # (m, 3): a, b, c of a x^2 + b x + c
        pr = yr @ np.linalg.pinv(np.vander(xr, 3)).T
        d = pl - pr
        a, b, c = d[:, 0], d[:, 1], d[:, 2]
        quad = np.abs(a) > 1e-300
        disc = b * b - 4 * a * c
        sq = np.sqrt(np.where(disc >= 0, disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            r1 = np.where(quad, (-b + sq) / (2 * a), np.where(b != 0, -c / b, np.nan))
            r2 = np.where(quad, (-b - sq) / (2 * a), np.nan)
        r1 = np.where(quad & (disc < 0), np.nan, r1)
        r2 = np.where(quad & (disc < 0), np.nan, r2)
        lo, hi = -h, h
        r1 = np.where((r1 >= lo) & (r1 <= hi), r1, np.nan)
        r2 = np.where((r2 >= lo) & (r2 <= hi), r2, np.nan)
        both = np.stack([r1, r2], axis=1)
        pick = np.nanargmin(np.where(np.isnan(both), np.inf, np.abs(both)), axis=1)
        root = both[np.arange(both.shape[0]), pick]
        slope_l = 2 * pl[:, 0] * root + pl[:, 1]
        slope_r = 2 * pr[:, 0] * root + pr[:, 1]
        good = ok & np.isfinite(root) & ~(slope_l > 0) & ~(slope_r < 0)
        rows = np.flatnonzero(full)
        tc[rows[good]] = t[sel[good]] + root[good]
        yc[rows[good]] = pl[good, 0] * root[good] ** 2 + pl[good, 1] * root[good] + pl[good, 2]
        done = np.zeros(idx.size, bool)
        done[rows] = True
        # windows with NaN go to the scalar version (it falls back to the sample), as do edge windows
        rest = np.flatnonzero(~done | np.isin(np.arange(idx.size), rows[~ok]))
    else:
        rest = np.arange(idx.size)
    for k in rest:
        tc[k], yc[k] = refine_cusp(t, y, int(idx[k]), half)
    return tc, yc


def _kink_cost(u: np.ndarray, ys: np.ndarray) -> float:
    """Residual sum of squares of continuous piecewise quadratics joined at u = 0 (a jump of the slope there)
    fitted to every column of ``ys`` (already scaled by its noise)."""
    right = (u > 0).astype(np.float64)
    a = np.column_stack([np.ones_like(u), u, u * u, right * u, right * u * u])
    sol, *_ = np.linalg.lstsq(a, ys, rcond=None)
    r = ys - a @ sol
    return float(np.sum(r * r))


def refine_kinks(
    time_s: np.ndarray,
    channels: list[np.ndarray],
    times: np.ndarray,
    observed: np.ndarray,
    half_frames: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Each impact where the motion's velocity jumps: (times s, True where refined).

    At an impact the feet are pinned at once: the hub's velocity and the wheel's angular velocity jump, so each
    channel (hub coordinates m, wheel angle rad; NaN at gaps) is continuous with a kink. Around each time in
    ``times`` a window of ``half_frames`` observed frames either side is fitted with a continuous piecewise
    quadratic per channel (weighted by its noise, `noise_sigma`) whose join moves within `KINK_SEARCH_FRAMES`
    frames; the join with the least residual is the impact. A window with an unobserved frame, or whose best
    join sits on the edge of the search, keeps its time (not refined)."""
    out, done, _ = _refine_kinks(time_s, channels, times, observed, half_frames)
    return out, done


def _refine_kinks(
    time_s: np.ndarray,
    channels: list[np.ndarray],
    times: np.ndarray,
    observed: np.ndarray,
    half_frames: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`refine_kinks` with each refined time's sd (s, NaN where not refined): from the curvature of the fit's cost
    (a chi-square: the channels are scaled by their noise) in the join's time, inflated by the residuals' rms per
    degree of freedom when above 1."""
    t = np.asarray(time_s, dtype=np.float64)
    out = np.asarray(times, dtype=np.float64).copy()
    done = np.zeros(out.size, bool)
    sd = np.full(out.size, np.nan)
    if out.size == 0 or t.size < 2 * half_frames + 1 or not channels:
        return out, done, sd
    dt = float(np.median(np.diff(t)))
    scaled = []
    for c in channels:
        c = np.asarray(c, dtype=np.float64)
        sig = noise_sigma(c)
        if not np.isfinite(sig):
            continue
        # a floor: noise-free data would weigh one channel infinitely
        scale = max(sig, 1e-6 * max(float(np.nanmax(np.abs(c))), 1e-3))
        scaled.append(c / scale)
    if not scaled:
        return out, done, sd
    ys_all = np.column_stack(scaled)
    good = observed & ~np.isnan(ys_all).any(axis=1)
    grid = np.linspace(-KINK_SEARCH_FRAMES, KINK_SEARCH_FRAMES, int(round(KINK_SEARCH_FRAMES * 20)) * 2 + 1) * dt
    for j, t0 in enumerate(out):
        i = int(np.clip(np.searchsorted(t, t0), 0, t.size - 1))
        lo, hi = i - half_frames, i + half_frames + 1
        if lo < 0 or hi > t.size or not good[lo:hi].all():
            continue
        tw, yw = t[lo:hi] - t0, ys_all[lo:hi]
        cost = np.array([_kink_cost(tw - g, yw) for g in grid])
        k = int(np.argmin(cost))
        if k == 0 or k == grid.size - 1:
            continue
        c0, c1, c2 = cost[k - 1 : k + 2]
        den = c0 - 2 * c1 + c2
        step = float(grid[1] - grid[0])
        shift = 0.5 * (c0 - c2) / den * step if den > 0 else 0.0
        out[j] = t0 + float(grid[k]) + float(np.clip(shift, -step, step))
        done[j] = True
        # the cost is a chi-square in the join's time: curvature den / step^2, so Delta chi^2 = 1 at
        # sqrt(2 step^2 / den); times the residual's rms per degree of freedom when the fit is worse than the noise
        dof = max(yw.size - 5 * yw.shape[1] - 1, 1)
        if den > 0:
            sd[j] = step * math.sqrt(2.0 / den) * math.sqrt(max(float(c1) / dof, 1.0))
    return out, done, sd


def find_com_minima(
    time_s: np.ndarray,
    height_m: np.ndarray,
    *,
    min_period_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Prominent minima of the CoM height (candidate impacts).

    Returns (indices, refined times in s, noise sigma in m). A minimum must stand out of the noise by
    8 sigma and by a quarter of the height's robust range; gaps (NaN) split nothing but are never minima.
    """
    from scipy.signal import find_peaks

    y = np.asarray(height_m, dtype=np.float64)
    ok = ~np.isnan(y)
    if ok.sum() < 10:
        return np.zeros(0, np.int64), np.zeros(0), float("nan")
    sigma = noise_sigma(y)
    lo, hi = np.percentile(y[ok], [2, 98], overwrite_input=True)  # y[ok] is a copy
    prom = max(8 * sigma, 0.25 * (hi - lo), 1e-9)
    yf = np.where(ok, y, np.nanmax(y))
    dt = float(np.median(np.diff(time_s)))
    distance = max(1, int(0.5 * min_period_s / dt)) if min_period_s else 1
    idx, _ = find_peaks(-yf, prominence=prom, distance=distance)
    idx = idx[ok[idx]]
    if idx.size >= 2:
        half = max(3, int(0.25 * np.median(np.diff(idx))))
    else:
        half = 5
    # A minimum beside a gap or the edge of the data (the release from a hold, a catch) is not a cusp seen on
    # both sides: drop it.
    nan_upto = np.cumsum(~ok, dtype=np.int32 if y.size < 2**31 else np.int64)  # NaN samples in y[:k + 1]

    def nan_before(k: np.ndarray, counts: np.ndarray = nan_upto) -> np.ndarray:  # NaN samples in y[:k]
        return np.where(k > 0, counts[np.maximum(k - 1, 0)], 0)

    lo, hi = np.clip(idx - half, 0, y.size), np.clip(idx + half + 1, 0, y.size)
    whole = (idx - half >= 0) & (idx + half < y.size) & (nan_before(hi) - nan_before(lo) == 0)
    del nan_upto
    idx = idx[whole]
    times = refine_cusps(np.asarray(time_s, dtype=np.float64), yf, idx, half)[0]
    return idx.astype(np.int64), times, sigma


def _observed_impacts(
    t: np.ndarray, observed: np.ndarray, times: np.ndarray, j: np.ndarray, ok_idx: np.ndarray
) -> np.ndarray:
    """An impact is observed when the two samples bracketing it are real, adjacent frames."""
    i0, i1 = ok_idx[j - 1], ok_idx[j]
    return (i1 - i0 == 1) & observed[i0] & observed[i1]


def _periods(
    impact_k: np.ndarray, times: np.ndarray, t: np.ndarray, unbridged: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(periods, step index of each) between consecutive observed impacts with no unbridged gap between."""
    if times.size < 2:
        return np.zeros(0), np.zeros(0, np.int64)
    consecutive = np.diff(impact_k) == 1
    gap_before = np.concatenate([[0], np.cumsum(unbridged)])  # gaps in t[:i]
    i0 = np.searchsorted(t, times[:-1], side="left")
    i1 = np.searchsorted(t, times[1:], side="right")
    clean = (gap_before[i1] - gap_before[i0]) == 0
    keep = consecutive & clean
    return np.diff(times)[keep], impact_k[1:][keep]


def _at_kinks(
    t: np.ndarray, channels: list[np.ndarray] | None, times: np.ndarray, obs: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`refine_kinks` with a window of a fifth of the median step (within `KINK_HALF_FRAMES`): (sorted times s,
    each one's sd s from the kink fit, NaN where not refined)."""
    nan = np.full(times.size, np.nan)
    if channels is None or times.size < 2:
        return times, nan
    frames = float(np.median(np.diff(times))) / float(np.median(np.diff(t)))
    half = int(np.clip(round(0.2 * frames), *KINK_HALF_FRAMES))
    refined, _, sd = _refine_kinks(t, channels, times, obs, half)
    return (refined, sd) if np.all(np.diff(refined) > 0) else (times, nan)


def _rotation_at_kinks(
    t: np.ndarray,
    channels: list[np.ndarray],
    times: np.ndarray,
    obs: np.ndarray,
    tv: np.ndarray,
    av: np.ndarray,
    phase: float,
    ks: np.ndarray,
    alpha_rad: float,
) -> tuple[np.ndarray, float]:
    """Impacts on the rotation, ``phase + k alpha``, with the phase taken from where the motion kinks
    (`refine_kinks`; the median over the impacts) rather than from the CoM minima: a compliant leg keeps
    compressing after the impact, so its minimum comes late. The times stay those of the rotation when no kink
    is found. Returns (times s, phase rad)."""
    if times.size < 1:
        return times, phase
    frames = float(np.median(np.diff(times))) / float(np.median(np.diff(t))) if times.size > 1 else 20.0
    half = int(np.clip(round(0.2 * frames), *KINK_HALF_FRAMES))
    kt, done = refine_kinks(t, channels, times, obs, half)
    if not done.any():
        return times, phase
    a_kink = np.interp(kt[done], tv, av)
    resid = a_kink - (phase + alpha_rad * ks[done])
    shift = float(np.median(resid))
    # the search reaches KINK_SEARCH_FRAMES: a larger shift is not a correction of the placement
    step_rate = alpha_rad / max(float(np.median(np.diff(times))), 1e-9) if times.size > 1 else 0.0
    if abs(shift) > KINK_SEARCH_FRAMES * float(np.median(np.diff(t))) * step_rate:
        return times, phase
    targets = phase + shift + alpha_rad * ks
    j = np.clip(np.searchsorted(av, targets, side="left"), 1, av.size - 1)
    a0, a1 = av[j - 1], av[j]
    frac = np.where(a1 > a0, (targets - a0) / np.where(a1 > a0, a1 - a0, 1.0), 0.0)
    out = tv[j - 1] + frac * (tv[j] - tv[j - 1])
    if not np.all(np.diff(out) > 0):
        return times, phase
    return out, float(phase + shift)


def _stance_heights(
    t: np.ndarray,
    y: np.ndarray,
    ang: np.ndarray,
    use: np.ndarray,
    targets: np.ndarray,
    times: np.ndarray,
    leg_m: float,
    alpha_rad: float,
) -> np.ndarray:
    """Per impact, the hub's height in the stance that ends there, brought to its touchdown angle (m, up to a
    constant; NaN: too few frames): ``mean(y - L0 (cos(alpha/2 - u) - cos(alpha/2)))`` over the frames of that
    stance (after the previous impact) whose wheel angle is `TOUCHDOWN_WINDOW` of a step before ``targets``
    (u, rad), i.e. ``c + L1 cos(alpha/2)`` for a stance leg of locked length L1 turning about its foot."""
    out = np.full(targets.size, np.nan)
    lo_u, hi_u = TOUCHDOWN_WINDOW[0] * alpha_rad, TOUCHDOWN_WINDOW[1] * alpha_rad
    for j, (a_k, t_k) in enumerate(zip(targets, times)):
        t_prev = times[j - 1] if j > 0 else -np.inf
        u = a_k - ang
        m = use & (t > t_prev) & (t < t_k) & (u > lo_u) & (u < hi_u)
        if m.sum() >= TOUCHDOWN_MIN_FRAMES:
            out[j] = float(np.mean(y[m] - leg_m * (np.cos(alpha_rad / 2 - u[m]) - math.cos(alpha_rad / 2))))
    return out


def _touchdown_shift_sd(k_later: np.ndarray, h_later: np.ndarray, k0: float) -> float:
    """The sd of the first stance's height less the later stances' reference at its step (m; `_first_touchdown`):
    the later heights' scatter about their line (n - 2 degrees of freedom; with two, about their mean) taken as each
    stance's, the first one's included, plus the line's extrapolation to step ``k0``; NaN with fewer than two."""
    n = h_later.size
    if n < 2:
        return math.nan
    if n >= 3:
        kb = float(np.mean(k_later))
        sxx = float(np.sum((k_later - kb) ** 2))
        r = h_later - np.polyval(np.polyfit(k_later, h_later, 1), k_later)
        s2 = float(r @ r) / (n - 2)
        lever = 1.0 / n + (k0 - kb) ** 2 / sxx if sxx > 0 else 1.0
    else:
        s2 = float(np.var(h_later, ddof=1))
        lever = 1.0 / n
    return math.sqrt(s2 * (1.0 + lever))


def _first_touchdown(
    t: np.ndarray,
    y: np.ndarray,
    ang: np.ndarray,
    use: np.ndarray,
    tv: np.ndarray,
    av: np.ndarray,
    phase: float,
    ks: np.ndarray,
    alpha_rad: float,
    leg_m: float,
    times: np.ndarray,
) -> tuple[np.ndarray, float, float]:
    """The first impact moved to its own touchdown angle: (times s, its angle shift rad, 0 when not moved, and that
    shift's sd rad, `_touchdown_shift_sd`, NaN when not moved).

    The impacts sit where the wheel has turned to ``phase + k alpha``: where a stance leg locked at the gait's
    compression lets the next foot touch down (model.md section 4: touchdown at L1 cos(theta) = L0
    cos(alpha - theta)). Every stance but the first begins with an impact; the first begins with the release (from
    a hold, a hand), so its leg locks at another compression and its foot touches down at another angle: a leg
    locked dL1 longer touches down dL1 / (2 L0 tan(alpha/2)) later in angle (first order). That change is
    measured from the hub's height late in each stance (`_stance_heights`): the first stance's height against
    the later stances' (their line over the step number, brought to the first step; their median with two) gives
    the first touchdown's angle shift dh / (2 L0 sin(alpha/2)). Every stance's height is taken over the turn the
    first one was seen in (a release less than a third of a step before the first impact leaves only the end of
    the window; the heights brought to the touchdown angle are not flat over the window, e.g. 5 mm over it on a
    compliant wheel whose stance leg touches down short of alpha/2, so means over different turns differ by
    millimetres): when the first stance was not seen before its window (the release came inside it), the
    window's frames of all stances whose turn before their impact lies within the first stance's, widened by half
    a frame's turn each side; else the whole window. Left in place with fewer than two later stances measured, or a
    shift over `TOUCHDOWN_MAX_SHIFT` of a step (not a leg's compression)."""
    targets = phase + alpha_rad * ks
    ends = np.clip(np.searchsorted(times, t, side="left"), 0, times.size - 1)  # the impact ending each frame's stance
    u_all = targets[ends] - ang  # each frame's turn before that impact, rad
    lo_u, hi_u = TOUCHDOWN_WINDOW[0] * alpha_rad, TOUCHDOWN_WINDOW[1] * alpha_rad
    first = use & (t < times[0])
    u0 = np.sort(u_all[first & (u_all > lo_u) & (u_all < hi_u)])
    if u0.size >= 2 and not np.any(first & (u_all >= hi_u)):  # released inside the window: the later stances
        half = 0.5 * float(np.median(np.diff(u0)))  # over the first one's turn
        use = use & (u_all >= u0[0] - half) & (u_all <= u0[-1] + half)
    h = _stance_heights(t, y, ang, use, targets, times, leg_m, alpha_rad)
    later = np.isfinite(h[1:])
    if not math.isfinite(h[0]) or later.sum() < 2:
        return times, 0.0, math.nan
    k_later, h_later = ks[1:][later].astype(np.float64), h[1:][later]
    if h_later.size >= 3:
        line = np.polyfit(k_later, h_later, 1)
        ref = float(np.polyval(line, float(ks[0])))
    else:
        ref = float(np.median(h_later))
    den = 2 * leg_m * math.sin(alpha_rad / 2)
    dbeta = (float(h[0]) - ref) / den
    sd = _touchdown_shift_sd(k_later, h_later, float(ks[0])) / den
    if abs(dbeta) > TOUCHDOWN_MAX_SHIFT * alpha_rad:
        return times, 0.0, math.nan
    target = float(targets[0]) + dbeta
    j = int(np.clip(np.searchsorted(av, target, side="left"), 1, av.size - 1))
    a0, a1 = av[j - 1], av[j]
    frac = (target - a0) / (a1 - a0) if a1 > a0 else 0.0
    out = times.copy()
    out[0] = float(tv[j - 1] + frac * (tv[j] - tv[j - 1]))
    if not np.all(np.diff(out) > 0):
        return times, 0.0, math.nan
    return out, dbeta, sd


def impact_time_sd(
    time_s: np.ndarray,
    angle_rad: np.ndarray,
    times: np.ndarray,
    steps: np.ndarray,
    angle_sd_rad: float,
    alpha_rad: float,
    first_shift_sd_rad: float = math.nan,
) -> np.ndarray:
    """Each impact's time sd (s) when impacts are placed where the wheel angle crosses ``phase + k alpha``.

    The crossing is interpolated between the two frames bracketing it (``time_s``, s; ``angle_rad``, rad, the
    angle's running maximum): their angle noise (``angle_sd_rad``, rad, `noise_sigma`, independent frame to
    frame) moves it by ``angle_sd sqrt((1 - f)^2 + f^2) / omega`` (f: the crossing's fraction of the frame; omega:
    the angle's rate there, rad/s, its line over `RATE_HALF_FRAMES` frames either side; where those are not all
    there, alpha over the impact's two periods' mean, from ``times`` s and ``steps``, the impacts' step numbers).
    The first impact's own touchdown shift (`_first_touchdown`) adds its sd ``first_shift_sd_rad`` (rad) over
    omega; NaN there (not measured): the first impact's sd is NaN. The shift common to every impact (the phase) is
    not included: it moves no period. NaN everywhere with fewer than two impacts or no angle noise estimate."""
    n = times.size
    if n < 2 or not math.isfinite(angle_sd_rad) or time_s.size < 2:
        return np.full(n, np.nan)
    j = np.clip(np.searchsorted(time_s, times, side="left"), 1, time_s.size - 1)
    t0, t1 = time_s[j - 1], time_s[j]
    f = np.clip((times - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    w = alpha_rad * np.diff(steps).astype(np.float64) / np.diff(times)  # rad/s over each gap between impacts
    w_at = np.concatenate([[w[0]], 0.5 * (w[:-1] + w[1:]), [w[-1]]])
    # the rate at the crossing itself (the wheel turns fastest about its impacts): the angle's line over the
    # `RATE_HALF_FRAMES` frames either side, where they are there
    for i, ji in enumerate(j):
        lo, hi = ji - RATE_HALF_FRAMES, ji + RATE_HALF_FRAMES
        if lo >= 0 and hi <= time_s.size:
            slope = float(np.polyfit(time_s[lo:hi] - time_s[ji], angle_rad[lo:hi], 1)[0])
            if slope > 0:
                w_at[i] = slope
    var = (angle_sd_rad**2 * ((1 - f) ** 2 + f**2)) / w_at**2
    var[0] += first_shift_sd_rad**2 / w_at[0] ** 2  # NaN when not measured
    return np.sqrt(var)


def detect_steps(
    time_s: np.ndarray,
    com_height_m: np.ndarray,
    wheel_angle_rad: np.ndarray | None = None,
    *,
    alpha_rad: float = ALPHA_RAD,
    observed: np.ndarray | None = None,
    window_s: tuple[float, float] | None = None,
    min_advance_rad: float = 0.0,
    kink_channels: list[np.ndarray] | None = None,
    leg_length_m: float | None = None,
) -> StepResult:
    """Impacts and step periods of a trial, per observed segment.

    Parameters
    ----------
    time_s : (n,) s.
    com_height_m : (n,) CoM height normal to the slope, m; NaN at gaps.
    wheel_angle_rad : (n,) unwrapped wheel angle, rad, or None when orientation is unknown.
    alpha_rad : rotation per step, rad (45 deg for the eight-legged wheel).
    observed : (n,) True for frames measured (not gaps, not interpolated); default: finite samples.
    window_s : (t0, t1) s: only impacts inside are sought (the walking window).
    min_advance_rad : an impact needs the wheel to have turned this much since t0 (a release from rest on two
        feet is not an impact), rad.
    kink_channels : series (n,) whose rate jumps at an impact (the hub's slope-frame coordinates, m): with the
        rotation, the phase of the impacts is taken from where they kink (`refine_kinks`, the median over the
        impacts); without it, each CoM minimum is moved to its kink.
    leg_length_m : the wheel's leg length L0, m: with the rotation, the first impact (after a release, not an
        impact) is moved to its own touchdown angle from its stance's hub height (`_first_touchdown`); None: left
        at the gait's phase.

    Returns
    -------
    StepResult: every impact whose two bracketing frames were observed; ``step_period_s`` only between two
    consecutive such impacts with no unbridged gap between them (``period_step`` numbers them); ``refused``
    says why when the data cannot support a detection. Never a guess across a gap.
    """
    t = np.asarray(time_s, dtype=np.float64)
    y = np.asarray(com_height_m, dtype=np.float64)
    gap = np.isnan(y)
    if wheel_angle_rad is not None:
        gap = gap | np.isnan(wheel_angle_rad)
    obs = ~gap if observed is None else (np.asarray(observed, bool) & ~gap)
    unbridged = gap  # NaN after the bounded interpolation: a gap no period may span
    lo, hi = (t[0], t[-1]) if window_s is None else window_s
    inwin = (t >= lo - 1e-9) & (t <= hi + 1e-9)
    if (~gap & inwin).sum() < 10:
        return StepResult.refuse("fewer than 10 valid samples in the walking window")
    yw = np.where(inwin, y, np.nan)

    if wheel_angle_rad is not None:
        ang = np.asarray(wheel_angle_rad, dtype=np.float64)
        aw = ang[inwin & ~gap]
        total = float(aw.max() - aw.min())
        if total < alpha_rad:  # two impacts are alpha apart: a shorter turn cannot hold two
            return StepResult.refuse(
                f"the wheel turns only {np.degrees(total):.1f} deg, less than one step of "
                f"{np.degrees(alpha_rad):.0f} deg: fewer than two steps (impacts)"
            )
        tw = t[inwin & ~gap]
        # the rate of the forward turn only: a wheel that stalls and rocks back spends time without turning on
        i_top = int(np.argmax(aw))
        rate = total / max(tw[i_top] - tw[0], 1e-9)
        period_guess = alpha_rad / rate
        del aw, tw
        idx, tmin, sigma = find_com_minima(t, yw, min_period_s=period_guess)
        del yw
        if idx.size < 1:  # one clear minimum fixes the phase: the impacts then follow every alpha of rotation
            return StepResult.refuse(
                f"the CoM height shows no clear minimum (noise {sigma * 1e3:.2f} mm): cannot place the "
                "impacts on the rotation"
            )
        ok_idx = np.flatnonzero(~gap)
        a_min = np.interp(tmin, t[ok_idx], ang[ok_idx])
        res = np.mod(a_min, alpha_rad) / alpha_rad * 2 * np.pi
        mean = np.angle(np.mean(np.exp(1j * res)))
        spread = np.abs(np.angle(np.exp(1j * (res - mean))))
        # A wandering walk (a step steeper or shallower than the others) moves a compliant wheel's minimum
        # within its step: a few minima off the others' phase do not make the rotation wrong. The phase is
        # that of the minima that agree when they are at least 60 % of them (the kinks then place the impacts).
        for _ in range(2):
            agree = spread <= MINIMA_PHASE_TOL
            if agree.all() or agree.sum() < max(2, math.ceil(MINIMA_AGREE_FRACTION * res.size)):
                break
            mean = np.angle(np.mean(np.exp(1j * res[agree])))
            spread = np.abs(np.angle(np.exp(1j * (res - mean))))
        agree = spread <= MINIMA_PHASE_TOL
        if not agree.all() and agree.sum() < max(2, math.ceil(MINIMA_AGREE_FRACTION * res.size)):
            return StepResult.refuse(
                f"CoM minima do not repeat every {np.degrees(alpha_rad):.0f} deg of rotation "
                f"(worst misfit {np.degrees(np.max(spread)) / 360 * np.degrees(alpha_rad):.1f} deg; "
                f"{int(agree.sum())} of {res.size} agree)"
            )
        # the median of the agreeing minima about their mean: a flat-bottomed compliant step whose minimum comes on
        # its rebound (a tenth of a step late) no longer drags the phase past the kink search
        mean = mean + float(np.median(np.angle(np.exp(1j * (res[agree] - mean)))))
        phase = float(np.mod(mean, 2 * np.pi) / (2 * np.pi) * alpha_rad)
        sel = ok_idx[inwin[ok_idx]]
        del ok_idx
        tv, av = t[sel], np.maximum.accumulate(ang[sel])
        k0 = int(np.ceil((av[0] + min_advance_rad - phase) / alpha_rad))
        k1 = int(np.floor((av[-1] - phase) / alpha_rad))
        ks = np.arange(k0, k1 + 1)
        targets = phase + alpha_rad * ks
        if targets.size < 2:
            return StepResult.refuse("fewer than two impacts inside the valid data")
        j = np.searchsorted(av, targets, side="left")
        j = np.clip(j, 1, av.size - 1)
        a0, a1 = av[j - 1], av[j]
        frac = np.where(a1 > a0, (targets - a0) / np.where(a1 > a0, a1 - a0, 1.0), 0.0)
        times = tv[j - 1] + frac * (tv[j] - tv[j - 1])
        seen = _observed_impacts(t, obs, times, j, sel)
        # an impact needs a frame of the window on either side of it: one placed on the first or last frame is
        # the start or end of the recording crossing the phase (noise), not an observed impact
        dt_frame = float(np.median(np.diff(tv))) if tv.size > 1 else 0.0
        seen &= (times > tv[0] + 0.5 * dt_frame) & (times < tv[-1] - 0.5 * dt_frame)
        times, ks = times[seen], ks[seen]
        if times.size < 2:
            return StepResult.refuse(
                "fewer than two observed impacts (the others fall in gaps or on the first or last frame)"
            )
        if kink_channels is not None:
            times, phase = _rotation_at_kinks(t, kink_channels, times, obs, tv, av, phase, ks, alpha_rad)
        first_sd = math.nan  # the first impact's own touchdown shift's sd, rad (NaN: not measured)
        if leg_length_m is not None:
            times, _, first_sd = _first_touchdown(
                t, y, ang, obs & inwin, tv, av, phase, ks, alpha_rad, leg_length_m, times
            )
        periods, pk = _periods(ks, times, t, unbridged)
        return StepResult(
            times,
            periods,
            "rotation",
            None,
            float(phase + alpha_rad * ks[0]),
            impact_step=ks - ks[0],
            period_step=pk - ks[0],
            impact_sd_s=impact_time_sd(tv, av, times, ks, noise_sigma(ang[obs & inwin]), alpha_rad, first_sd),
        )

    idx, tmin, sigma = find_com_minima(t, yw)
    if idx.size < 2:
        return StepResult.refuse(f"the CoM height shows {idx.size} clear minima (noise {sigma * 1e3:.2f} mm)")
    d = np.diff(tmin)
    med = float(np.median(d))
    if np.any(d < 0.6 * med):
        return StepResult.refuse(
            f"CoM minima are irregular (periods {d.min():.3f}-{d.max():.3f} s around {med:.3f} s): spurious minima"
        )
    # A minimum missed in a gap shows as a period of about twice the median: count the steps.
    ks = np.concatenate([[0], np.cumsum(np.maximum(np.round(d / med), 1).astype(np.int64))])
    seen = obs[idx] & obs[np.clip(idx - 1, 0, None)] & obs[np.clip(idx + 1, None, t.size - 1)]
    times, ks = tmin[seen], ks[seen]
    if times.size < 2:
        return StepResult.refuse("fewer than two observed CoM minima")
    times, sd = _at_kinks(t, kink_channels, times, obs)
    periods, pk = _periods(ks, times, t, unbridged)
    return StepResult(
        times, periods, "com-minima", None, None, impact_step=ks - ks[0], period_step=pk - ks[0], impact_sd_s=sd
    )
