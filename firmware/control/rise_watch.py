"""The doubt test of a counted sensor: a compression that no touchdown explains, judged against measured noise.

`NoiseMeter` measures the sensor's position noise at rest: the mean square of the per-sample displacement
(m^2) over quiet samples, an exponential average with a `tau_s` time constant, and the position quantum (the
smallest non-zero displacement seen, one count). For a position noise that does not accumulate (counts are
floored from the true position plus noise), E[dx^2] = 2 sigma^2 at rest.

`RiseWatch` follows the mean position over `smooth_s` and reports a rise of at least a threshold above its lowest
mean of the last `span_s`, followed by a fall of half the threshold from the top: a compression that came and
went. Positions bound the excursion, not the sign of a velocity estimate, which noise can flip inside one rise
when few samples fill the velocity window.
"""

from __future__ import annotations

import math
from collections import deque


class NoiseMeter:
    """Position noise (m, one standard deviation) and quantum (m) of one sensor, measured at rest."""

    MIN_SAMPLES = 20  # quiet samples before the noise counts as measured
    MIN_SPAN_S = 0.1  # and quiet time (s)

    def __init__(self, tau_s: float = 1.0) -> None:
        self.tau_s = tau_s
        self.mean_square_m2 = 0.0
        self.samples = 0
        self.quiet_s = 0.0
        self.quantum_m: float | None = None

    def see(self, dx_m: float) -> None:
        """Every sample's displacement: the smallest non-zero one is the quantum."""
        a = abs(dx_m)
        if a > 0.0 and (self.quantum_m is None or a < self.quantum_m):
            self.quantum_m = a

    def add_quiet(self, dx_m: float, dt_s: float) -> None:
        """A displacement (m) over `dt_s` while the leg is at rest; once measured, one beyond 4 sigma (and two
        quanta) is motion, not noise, and is left out."""
        if self.measured and abs(dx_m) > max(4.0 * self.sigma_m, 2.0 * (self.quantum_m or 0.0)):
            return
        self.samples += 1
        self.quiet_s += dt_s
        alpha = 1.0 / self.samples if self.quiet_s < self.tau_s else min(1.0, dt_s / self.tau_s)
        self.mean_square_m2 += alpha * (dx_m * dx_m - self.mean_square_m2)

    @property
    def measured(self) -> bool:
        return self.samples >= self.MIN_SAMPLES and self.quiet_s >= self.MIN_SPAN_S

    @property
    def sigma_m(self) -> float:
        """Position noise at rest (m)."""
        return math.sqrt(0.5 * self.mean_square_m2)

    def rise_threshold_m(self, sigmas: float, n_mean: int) -> float:
        """`sigmas` standard deviations of the difference of two means of `n_mean` positions, and at least two
        quanta (m); +inf until measured, and while no motion has shown the quantum (a sensor reading exactly 0 at
        rest has no noise to measure: a threshold of 0 would doubt every sample)."""
        if not self.measured or self.quantum_m is None:
            return math.inf
        return max(sigmas * math.sqrt(2.0 / max(1, n_mean)) * self.sigma_m, 2.0 * self.quantum_m)


class RiseWatch:
    """A rise of the mean position above its recent minimum, then a fall from its top (m, s)."""

    def __init__(self, smooth_s: float, span_s: float) -> None:
        self.smooth_s = smooth_s
        self.span_s = span_s
        self._recent: deque[tuple[float, float]] = deque()
        self._sum = 0.0
        self._lows: deque[tuple[float, float]] = deque()  # (t, mean): rising minima of the last span
        self.peak_m = 0.0  # the largest rise above that minimum so far
        self.cross_s: float | None = None  # when the rise first reached the threshold
        self._top = -math.inf  # the highest mean since then

    def forget(self) -> None:
        """Start again (after a touchdown, a lock, a bounce): the excursion so far is explained."""
        self._lows.clear()
        self.peak_m = 0.0
        self.cross_s = None
        self._top = -math.inf

    @property
    def samples_in_mean(self) -> int:
        return max(1, len(self._recent))

    def mean_m(self) -> float:
        return self._sum / max(1, len(self._recent))

    def add_position(self, t_s: float, x_m: float) -> None:
        """Every sample's position (the mean follows it whatever the phase)."""
        self._recent.append((t_s, x_m))
        self._sum += x_m
        while len(self._recent) > 1 and t_s - self._recent[0][0] > self.smooth_s:
            self._sum -= self._recent.popleft()[1]

    def rise_m(self) -> float:
        """The mean's rise above its lowest value in the watch (m)."""
        return self.mean_m() - self._lows[0][1] if self._lows else 0.0

    def watch(self, t_s: float, threshold_m: float) -> float | None:
        """Follow the mean; the peak rise (m) when a rise of `threshold_m` came and fell by half of it, else None."""
        m = self.mean_m()
        lows = self._lows
        while lows and lows[-1][1] >= m:
            lows.pop()
        lows.append((t_s, m))
        while t_s - lows[0][0] > self.span_s:
            lows.popleft()
        rise = m - lows[0][1]
        if rise >= threshold_m:
            if self.cross_s is None:
                self.cross_s = t_s
            self.peak_m = max(self.peak_m, rise)
        if self.peak_m < threshold_m:
            return None
        self._top = max(self._top, m)
        if self._top - m < 0.5 * threshold_m:
            return None
        return self.peak_m
