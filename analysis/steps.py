"""Step detection: impacts from the wheel rotation (one step per alpha = 45 deg), else from CoM-height minima.

In the model the stance leg rotates by alpha between impacts, so the wheel angle at impacts is an
arithmetic sequence ``phase + k * alpha``; the phase is taken from the CoM-height minima, which coincide
with impacts (two legs touch, the hub is lowest). A trial too noisy or gappy to support a detection is
refused (`StepResult.refused` holds the reason), never guessed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["StepResult", "noise_sigma", "find_com_minima", "refine_cusp", "detect_steps", "ALPHA_RAD"]

#: Inter-leg angle of the eight-legged wheel, rad.
ALPHA_RAD = np.pi / 4


@dataclass(frozen=True, eq=False)
class StepResult:
    """Impacts and step periods.

    Attributes
    ----------
    impact_time_s : (m,) impact times, s (sub-frame, interpolated).
    step_period_s : (m - 1,) time between consecutive impacts, s; step k (1-based) ends at impact k.
    method : ``"rotation"``, ``"com-minima"`` or ``"none"``.
    refused : None, or why no detection is given.
    phase_rad : wheel angle of the first impact (rotation method), rad, or None.
    """

    impact_time_s: np.ndarray
    step_period_s: np.ndarray
    method: str
    refused: str | None = None
    phase_rad: float | None = None

    @property
    def step_number(self) -> np.ndarray:
        """1-based number of each step in ``step_period_s``."""
        return np.arange(1, self.step_period_s.size + 1)

    @classmethod
    def refuse(cls, reason: str) -> StepResult:
        """A result carrying no steps and the reason."""
        return cls(np.zeros(0), np.zeros(0), "none", reason)


def noise_sigma(y: np.ndarray) -> float:
    """Robust white-noise sigma from third differences (smooth signals cancel), same unit as ``y``."""
    d = np.diff(y[~np.isnan(y)], 3)
    if d.size < 5:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d)) / np.sqrt(20.0))


def refine_cusp(t: np.ndarray, y: np.ndarray, i: int, half: int) -> tuple[float, float]:
    """Sub-frame cusp minimum near sample i: where parabolas fitted on each side meet (time, value).

    Parabolas, not lines, so that the curvature of each side (the hub swings on an arc) does not bias the
    value. Falls back to the sample itself when a side is too short or the meeting point is not within
    one sample of i.
    """
    lo, hi = max(i - half, 0), min(i + half, y.size - 1)
    if i - lo < 3 or hi - i < 3 or np.isnan(y[lo:hi + 1]).any():
        return float(t[i]), float(y[i])
    tl, tr = t[lo:i + 1] - t[i], t[i:hi + 1] - t[i]
    pl = np.polyfit(tl, y[lo:i + 1], 2)
    pr = np.polyfit(tr, y[i:hi + 1], 2)
    roots = np.roots(pl - pr) if np.any(pl - pr) else np.zeros(0)
    roots = roots[np.isreal(roots)].real
    roots = roots[(roots >= t[i - 1] - t[i]) & (roots <= t[i + 1] - t[i])]
    if roots.size == 0:
        return float(t[i]), float(y[i])
    tc = float(roots[np.argmin(np.abs(roots))])
    if np.polyval(np.polyder(pl), tc) > 0 or np.polyval(np.polyder(pr), tc) < 0:
        return float(t[i]), float(y[i])
    return float(t[i] + tc), float(np.polyval(pl, tc))


def find_com_minima(time_s: np.ndarray, height_m: np.ndarray, *, min_period_s: float | None = None,
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
    lo, hi = np.percentile(y[ok], [2, 98])
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
    times = np.array([refine_cusp(time_s, yf, int(i), half)[0] for i in idx])
    return idx.astype(np.int64), times, sigma


def _gap_between(gap: np.ndarray, time_s: np.ndarray, t0: float, t1: float) -> bool:
    m = (time_s >= t0) & (time_s <= t1)
    return bool(gap[m].any())


def detect_steps(
    time_s: np.ndarray,
    com_height_m: np.ndarray,
    wheel_angle_rad: np.ndarray | None = None,
    *,
    alpha_rad: float = ALPHA_RAD,
) -> StepResult:
    """Impacts and step periods of a trial.

    Parameters
    ----------
    time_s : (n,) s.
    com_height_m : (n,) CoM height normal to the slope, m; NaN at gaps.
    wheel_angle_rad : (n,) unwrapped wheel angle, rad, or None when orientation is unknown.
    alpha_rad : rotation per step, rad (45 deg for the eight-legged wheel).

    Returns
    -------
    StepResult; ``refused`` says why when the data cannot support a detection.
    """
    t = np.asarray(time_s, dtype=np.float64)
    y = np.asarray(com_height_m, dtype=np.float64)
    gap = np.isnan(y)
    if wheel_angle_rad is not None:
        gap = gap | np.isnan(wheel_angle_rad)
    if (~gap).sum() < 10:
        return StepResult.refuse("fewer than 10 valid samples")

    if wheel_angle_rad is not None:
        ang = np.asarray(wheel_angle_rad, dtype=np.float64)
        total = float(np.nanmax(ang) - np.nanmin(ang))
        if total < 2 * alpha_rad:
            return StepResult.refuse(
                f"the wheel turns only {np.degrees(total):.1f} deg: fewer than two steps of "
                f"{np.degrees(alpha_rad):.0f} deg")
        rate = total / (t[~gap][-1] - t[~gap][0])
        period_guess = alpha_rad / rate
        idx, tmin, sigma = find_com_minima(t, y, min_period_s=period_guess)
        if idx.size < 2:
            return StepResult.refuse(
                f"the CoM height shows {idx.size} clear minima (noise {sigma * 1e3:.2f} mm): cannot place the "
                "impacts on the rotation")
        ok = ~gap
        a_min = np.interp(tmin, t[ok], ang[ok])
        res = np.mod(a_min, alpha_rad) / alpha_rad * 2 * np.pi
        mean = np.angle(np.mean(np.exp(1j * res)))
        spread = np.abs(np.angle(np.exp(1j * (res - mean))))
        if np.max(spread) > 2 * np.pi / 5:
            return StepResult.refuse(
                f"CoM minima do not repeat every {np.degrees(alpha_rad):.0f} deg of rotation "
                f"(worst misfit {np.degrees(np.max(spread)) / 360 * np.degrees(alpha_rad):.1f} deg)")
        phase = float(np.mod(mean, 2 * np.pi) / (2 * np.pi) * alpha_rad)
        tv, av = t[ok], np.maximum.accumulate(ang[ok])
        k0 = int(np.ceil((av[0] - phase) / alpha_rad))
        k1 = int(np.floor((av[-1] - phase) / alpha_rad))
        targets = phase + alpha_rad * np.arange(k0, k1 + 1)
        if targets.size < 2:
            return StepResult.refuse("fewer than two impacts inside the valid data")
        j = np.searchsorted(av, targets, side="left")
        j = np.clip(j, 1, av.size - 1)
        a0, a1 = av[j - 1], av[j]
        frac = np.where(a1 > a0, (targets - a0) / np.where(a1 > a0, a1 - a0, 1.0), 0.0)
        times = tv[j - 1] + frac * (tv[j] - tv[j - 1])
        if _gap_between(gap, t, times[0], times[-1]):
            return StepResult.refuse("a gap lies between the first and last impact: periods across it would be guessed")
        return StepResult(times, np.diff(times), "rotation", None, float(targets[0]))

    idx, tmin, sigma = find_com_minima(t, y)
    if idx.size < 2:
        return StepResult.refuse(f"the CoM height shows {idx.size} clear minima (noise {sigma * 1e3:.2f} mm)")
    periods = np.diff(tmin)
    med = float(np.median(periods))
    if np.any(periods < 0.6 * med) or np.any(periods > 1.5 * med):
        return StepResult.refuse(
            f"CoM minima are irregular (periods {periods.min():.3f}-{periods.max():.3f} s around {med:.3f} s): "
            "missed or spurious minima")
    if _gap_between(gap, t, tmin[0], tmin[-1]):
        return StepResult.refuse("a gap lies between the first and last CoM minimum")
    return StepResult(tmin, periods, "com-minima", None, None)
