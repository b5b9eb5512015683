"""Zero-velocity detection and the stance-leg state machine.

Phases follow the paper's model: after a touchdown the wheel is in double support for
`double_support_s`, then in single support with the stance spring compressing freely; at the
compression velocity's zero crossing (maximum compression) the stance clutch locks (clutched);
the next touchdown releases it and the next leg becomes the stance leg.

The stance leg of a sensor that watches several legs is counted, so the count is checked: `legs[i]`
is the leg on the ground when the detector is (re)synchronised, every touchdown advances `i`, and a
touchdown that comes too early or too late for the step period (an extra or a missed one), or no
touchdown at all within the longest plausible step, loses synchronisation: the detector reports
`sync_lost`, stops locking, and stays so until `resync` names the leg on the ground. A sensor that
watches one leg measures it and needs no count.

A counted sensor proves its count rather than assuming it (each check has a parameter, off in the library's
defaults, on in the robot's): every compression since (re)sync is explained by a touchdown it confirmed, judged
against the position noise it measured (`doubt_noise_sigmas`, `rise_watch`); once the period is measured a
touchdown is accepted only inside the window it predicts, and an earlier one is a bounce that does not move the
count (`touch_window_early_fraction`); no lock before the predicted touchdown time, nor before `confirm_steps`
intervals matched the measured period, nor (`named_stance_required`) before the operator named the stance leg.

Samples the caller does not trust (low SQUAL: the chip may report frozen motion) make no decision:
no touchdown and no lock while any untrusted sample is inside the velocity window.

Velocity comes from a local quadratic least-squares fit of the integrated displacement over the last
`velocity_window_s` of timestamped samples, evaluated at the newest sample and extrapolated by half a
sample period plus `lock_lead_s`. The fit averages count quantisation and noise, has no lag on a
parabola (the shape of the motion near maximum compression) and uses the measured timestamps, so
late or bunched samples do not bias it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum

from rimless.firmware.control.detector_params import DetectorParams
from rimless.firmware.control.rise_watch import NoiseMeter, RiseWatch


class Phase(str, Enum):
    """Stance phases; `code` is the number plotted in telemetry."""

    WAIT = "wait"  # no stance tracked yet (start, disarm, lost gait)
    DOUBLE_SUPPORT = "double_support"
    FREE_COMPRESSION = "free_compression"
    CLUTCHED = "clutched"

    @property
    def code(self) -> int:
        """0 wait, 1 double support, 2 free compression, 3 clutched."""
        return _PHASE_CODES[self]


_PHASE_CODES = {Phase.WAIT: 0, Phase.DOUBLE_SUPPORT: 1, Phase.FREE_COMPRESSION: 2, Phase.CLUTCHED: 3}


class VelocityEstimator:
    """Local quadratic least-squares velocity of timestamped positions (m, s)."""

    MIN_SAMPLES = 4

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._t: deque[float] = deque()
        self._x: deque[float] = deque()

    def reset(self) -> None:
        """Forget all samples."""
        self._t.clear()
        self._x.clear()

    def add(self, t_s: float, x_m: float) -> None:
        """Add a sample; samples older than the window are dropped (keeping at least MIN_SAMPLES)."""
        self._t.append(t_s)
        self._x.append(x_m)
        while len(self._t) > self.MIN_SAMPLES and t_s - self._t[0] > self.window_s:
            self._t.popleft()
            self._x.popleft()

    def samples(self) -> tuple[list[float], list[float]]:
        """The window's times (s) and positions (m), oldest first."""
        return list(self._t), list(self._x)

    def lowest_m(self) -> float:
        """The lowest position in the window (m); 0 when empty."""
        return min(self._x, default=0.0)

    def estimate(self, lead_s: float = 0.0) -> float | None:
        """Velocity (m/s) at the newest sample + `lead_s`, or None with too few samples."""
        n = len(self._t)
        if n < self.MIN_SAMPLES:
            return None
        t_last = self._t[-1]
        x_last = self._x[-1]
        scale = max(t_last - self._t[0], 1e-6)
        s1 = s2 = s3 = s4 = y0 = y1 = y2 = 0.0
        for t, x in zip(self._t, self._x):
            u = (t - t_last) / scale
            u2 = u * u
            y = x - x_last
            s1 += u
            s2 += u2
            s3 += u2 * u
            s4 += u2 * u2
            y0 += y
            y1 += y * u
            y2 += y * u2
        s0 = float(n)
        # Cramer's rule on the 3x3 normal equations for (a, b, c) in y = a + b u + c u^2.
        det = s0 * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2)
        if abs(det) < 1e-12:
            return None
        det_b = s0 * (y1 * s4 - s3 * y2) - y0 * (s1 * s4 - s3 * s2) + s2 * (s1 * y2 - y1 * s2)
        det_c = s0 * (s2 * y2 - y1 * s3) - s1 * (s1 * y2 - y1 * s2) + y0 * (s1 * s3 - s2 * s2)
        b = det_b / det
        c = det_c / det
        return (b + 2.0 * c * (lead_s / scale)) / scale


@dataclass(frozen=True, slots=True)
class Decision:
    """What the detector wants after one sample: clutch commands and named events."""

    engage: int | None = None
    release: int | None = None
    events: tuple[str, ...] = ()


NOTHING = Decision()


class LegDetector:
    """The state machine for one sensor watching the stance-leg mechanism of `legs` (clutch indices).

    `start_index` names the leg on the ground now (`legs[start_index]`); every touchdown advances the
    stance leg to the next one in `legs`, so the first touchdown is that of `legs[start_index + 1]`.
    """

    # what `_touchdown` changed, for `dismiss_touchdown` to undo: (leg_index, _last_touchdown_s, _period_s,
    # _touchdown_s, _touchdown_x_m, _confirmed, _unconfirmed_touchdowns, awaiting_clean_touchdown); unset until the
    # first touchdown
    _before_touchdown: tuple[int, float | None, float | None, float, float, int, int, bool] | None
    # set by `reset` (and `_recount`, defined before it)
    _last_touchdown_s: float | None
    _period_s: float | None
    _t0_ns: int | None
    _t_last_s: float
    _touch_count: int
    velocity_m_s: float
    lock_time_s: float | None
    _predicted_touchdown_s: float | None
    _lock_delay_min_s: float | None
    _arm_s_rest_m: tuple[float, float] | None

    def __init__(self, params: DetectorParams, legs: list[int] | tuple[int, ...], *, start_index: int = 0) -> None:
        if not legs:
            raise ValueError("a detector needs at least one leg")
        self.params = params.validated()
        self.legs = list(legs)
        self._start_index = start_index % len(self.legs)
        self._est = VelocityEstimator(params.velocity_window_s)
        self.noise = NoiseMeter()  # the sensor's, kept across (re)syncs
        self.named = False  # an operator named the leg on the ground (`resync`)
        self.reset()

    @property
    def counted(self) -> bool:
        """True when the stance leg is counted (several legs), False when it is measured (one leg)."""
        return len(self.legs) > 1

    def resync(self, leg: int) -> None:
        """The leg on the ground at the last sample is clutch `leg` (one of `legs`): count from it, and lock nothing
        before a clean touchdown, one whose compression began after that sample.

        The samples seen so far are kept (velocity fit, mean position, noise), so a touchdown right after the
        resync is seen as promptly as any other. A compression under way at the last sample (a touchdown being
        confirmed, a compression or its rebound, or a position risen above the recent rest) began before the
        resync: it is the named leg's own step, followed to its end as a step (its rebound explained, not doubted)
        and never counted nor locked. The doubt test forgets what came before: the naming explains it."""
        if leg not in self.legs:
            raise ValueError(f"leg {leg} is not watched by this sensor (legs {self.legs})")
        index = self.legs.index(leg)
        if self._t0_ns is None or self._est.estimate() is None:
            self.reset(index)  # nothing seen yet that could be under way
        else:
            self._recount(index)
        self.named = True
        self.awaiting_clean_touchdown = True

    def _recount(self, index: int) -> None:
        """`resync` with samples seen: the count restarts at `legs[index]`, the phase follows the step under way."""
        p = self.params
        self.leg_index = index
        self.synced = True
        self.sync_detail = ""
        self._last_touchdown_s = None
        self._period_s = None
        self._predicted_touchdown_s = None
        self._lock_delay_min_s = None
        self._confirmed = 0
        self._unconfirmed_touchdowns = 0
        self._before_touchdown = None
        self._engaged = False  # whatever was locked on the old count is released by the controller
        self._lock_count = 0
        self._doubt_forget()
        rest_m = self._est.lowest_m()
        risen = self.position_m - rest_m > self.rest_band_m()
        rising = self._touch_count > 0 or self.velocity_m_s > p.touch_velocity_m_s
        self._arm_s_rest_m = None
        if self.phase in (Phase.WAIT, Phase.CLUTCHED) and (rising or risen):
            self._step_under_way(rest_m)
        else:
            self._arm_s_rest_m = (self._t_last_s, rest_m)  # the first touchdown is judged against it
        self._touch_count = 0

    def _step_under_way(self, rest_m: float) -> None:
        """The named leg's own step, its touchdown before the resync (being confirmed, or not seen): followed as a
        step from now (its compression and rebound explained), never counted."""
        self.phase = Phase.DOUBLE_SUPPORT
        self._touchdown_s = self._t_last_s
        self._touchdown_x_m = rest_m
        self._peak_v = max(self.velocity_m_s, math.nextafter(self.params.touch_velocity_m_s, math.inf))
        self._touchdown_unseen = True
        self._need_quiet = False
        self._touch_count = 0
        self._lock_count = 0

    def _touchdown_time_s(self, rest_m: float) -> float | None:
        """When the compression being confirmed left `rest_m` (s): the earliest sample of the newest run of samples
        risen above it by more than `rest_band_m`, extrapolated back along the line to the next sample (None when
        the newest sample has not risen)."""
        ts, xs = self._est.samples()
        band = self.rest_band_m()
        i = len(ts)
        while i > 0 and xs[i - 1] - rest_m > band:
            i -= 1
        if i == len(ts):
            return None
        t, x = ts[i], xs[i]
        if i + 1 < len(ts) and xs[i + 1] > x:
            return t - (x - rest_m) * (ts[i + 1] - t) / (xs[i + 1] - x)
        return t

    def _judge_first_touchdown(self) -> Decision | None:
        """The first touchdown after a resync at rest: one that began before the resync's sample is the named leg's
        own step (not counted); one within the time its rise takes to cross `rest_band_m` of it cannot be placed:
        the leg named is ambiguous, the count lost. None: after the resync, counted."""
        assert self._arm_s_rest_m is not None
        t_arm, rest_m = self._arm_s_rest_m
        self._arm_s_rest_m = None
        t0 = self._touchdown_time_s(rest_m)
        if t0 is None:
            return None
        v = max(self.velocity_m_s, self.params.touch_velocity_m_s)
        margin_s = max(self.rest_band_m() / v, 1e-4)
        if t0 > t_arm + margin_s:
            return None
        if t0 < t_arm - margin_s:
            self._step_under_way(rest_m)
            return Decision(events=("touchdown_before_arm",))
        return self._lose_sync(
            f"ambiguous arm: a touchdown {abs(t0 - t_arm) * 1e3:.2f} ms {'before' if t0 < t_arm else 'after'} it "
            f"(closer than {margin_s * 1e3:.2f} ms, the time its rise takes to show): which leg was on the ground is "
            "not known; arm again naming the leg on the ground"
        )

    def rest_band_m(self) -> float:
        """How far (m) above the recent lowest position the leg must be to count as risen from rest: six standard
        deviations of the measured position noise and three position quanta, else `touch_compression_m`."""
        q = self.noise.quantum_m or 0.0
        if self.noise.measured:
            return max(6.0 * self.noise.sigma_m, 3.0 * q)
        return max(self.params.touch_compression_m, 3.0 * q)

    def reset(self, start_index: int | None = None) -> None:
        """Back to WAIT and synchronised, with legs[start_index] on the ground."""
        if start_index is not None:
            self._start_index = start_index % len(self.legs)
        self.phase = Phase.WAIT
        self.leg_index = self._start_index
        self.synced = True
        self.sync_detail = ""
        self._last_touchdown_s = None
        self._period_s = None
        self._distrust_until_s = -math.inf
        self._need_quiet = True  # a compression already under way at (re)sync is not a touchdown
        self._est.reset()
        self.position_m = 0.0
        self.velocity_m_s = 0.0
        self._t0_ns = None
        self._t_last_s = 0.0
        self._dt_s = 0.0
        self._touch_count = 0
        self._lock_count = 0
        self._onset_x_m = 0.0
        self._touchdown_s = -math.inf
        self._touchdown_x_m = 0.0
        self._peak_v = 0.0
        self.lock_time_s = None
        self._confirmed = 0  # step intervals since (re)sync that matched a measured period
        self._unconfirmed_touchdowns = 0  # touchdowns since (re)sync or a bounce without confirm_steps of them
        self._engaged = False  # the CLUTCHED phase engaged its leg (False: a lock withheld)
        self._rise = RiseWatch(self.params.doubt_smooth_s, self.params.max_compression_s)
        self._predicted_touchdown_s = None  # when the stance leg's touchdown was due (s)
        self._lock_delay_min_s = None  # shortest touchdown-to-zero-crossing time measured (s)
        self._touchdown_unseen = False  # the step under way began before a resync: its touchdown time is not known
        self._arm_s_rest_m = None  # (the resync's sample time s, the rest position m) until its first touchdown
        # no lock before a touchdown whose compression began after the last resync (`resync`)
        self.awaiting_clean_touchdown = False

    def set_params(self, params: DetectorParams) -> None:
        """Apply new parameters (validated) without losing the phase."""
        self.params = params.validated()
        self._est.window_s = params.velocity_window_s
        self._rise.smooth_s, self._rise.span_s = params.doubt_smooth_s, params.max_compression_s

    @property
    def stance_leg(self) -> int:
        """Clutch index of the current (or next expected) stance leg."""
        return self.legs[self.leg_index]

    @property
    def compression_m(self) -> float:
        """Compression since the last touchdown (m), 0 in WAIT."""
        return 0.0 if self.phase is Phase.WAIT else self.position_m - self._touchdown_x_m

    def dismiss_touchdown(self) -> None:
        """The touchdown just reported was not a step (the controller knows another leg is the stance leg,
        e.g. the trailing foot coming down again): undo its count and timing, and wait, without locking,
        until this leg is quiet before it may report a touchdown again."""
        before = getattr(self, "_before_touchdown", None)
        if before is not None:
            (
                self.leg_index,
                self._last_touchdown_s,
                self._period_s,
                self._touchdown_s,
                self._touchdown_x_m,
                self._confirmed,
                self._unconfirmed_touchdowns,
                self.awaiting_clean_touchdown,
            ) = before
            self._before_touchdown = None
        self.phase = Phase.WAIT
        self._touch_count = 0
        self._lock_count = 0
        self._need_quiet = True

    def released_elsewhere(self) -> None:
        """Another sensor saw the next touchdown and released this one's clutch: back to WAIT."""
        if self.phase is Phase.CLUTCHED:
            self.phase = Phase.WAIT
            self._touch_count = 0
            self._engaged = False

    def _early_window_s(self) -> float:
        """How long before the predicted touchdown one is accepted (s): a fraction of the shortest measured
        touchdown-to-lock time, at most the period tolerance."""
        p = self.params
        assert self._period_s is not None
        w = p.step_period_tolerance * self._period_s
        if self._lock_delay_min_s is not None:
            w = min(w, p.touch_window_early_fraction * self._lock_delay_min_s)
        return w

    def _windowed(self) -> bool:
        """True when touchdowns are accepted only inside the window the measured period predicts."""
        p = self.params
        return self.counted and self.synced and p.touch_window_early_fraction > 0 and self._period_s is not None

    def doubt_threshold_m(self) -> float:
        """The rise (m) that must be explained by a touchdown: relative to the measured noise when
        `doubt_noise_sigmas` is set (+inf until measured), else `doubt_compression_m`."""
        p = self.params
        if p.doubt_noise_sigmas > 0:
            return self.noise.rise_threshold_m(p.doubt_noise_sigmas, self._rise.samples_in_mean)
        return p.doubt_compression_m

    def _step_window_s(self) -> float:
        """The longest plausible time from one touchdown to the next (s)."""
        p = self.params
        if self._period_s is None:
            return p.max_step_s
        return min(p.max_step_s, self._period_s * (1.0 + p.step_period_tolerance))

    @property
    def lock_allowed(self) -> bool:
        """True when a lock may engage the counted stance leg: synchronised, and `confirm_steps` step intervals
        since (re)sync agreed with the running period (always True for a sensor that measures its leg)."""
        if not self.counted:
            return True
        p = self.params
        if p.named_stance_required and not self.named:
            return False  # the start leg was configured, not named
        if self.awaiting_clean_touchdown:
            return False  # named, but the step under way began before: the next touchdown starts the count
        if p.doubt_noise_sigmas > 0 and not self.doubt_threshold_m() <= p.doubt_compression_m:
            return False  # noise not measured yet, or too large to see a missed step
        return self.synced and self._confirmed >= p.confirm_steps

    def _lose_sync(self, detail: str) -> Decision:
        self.synced = False
        self.sync_detail = detail
        release = self.stance_leg if self.phase is Phase.CLUTCHED else None
        self._engaged = False
        self.phase = Phase.WAIT
        self._touch_count = 0
        self._lock_count = 0
        return Decision(release=release, events=("sync_lost",))

    def update(self, t_ns: int, displacement_m: float, trusted: bool = True) -> Decision:
        """Feed one sample (`monotonic_ns` timestamp, displacement since the previous sample).

        `trusted=False` (e.g. SQUAL too low) keeps the sample out of every decision for one velocity
        window.
        """
        if self._t0_ns is None:
            self._t0_ns = t_ns
        t = (t_ns - self._t0_ns) * 1e-9
        self._dt_s = t - self._t_last_s if self._est._t else 0.0
        self._t_last_s = t
        prev_x = self.position_m
        self.position_m += displacement_m
        self._est.add(t, self.position_m)
        self._rise.add_position(t, self.position_m)
        self.noise.see(displacement_m)
        p = self.params
        if not trusted:
            self._distrust_until_s = t + p.velocity_window_s
        if (
            self.counted
            and self.synced
            and self._last_touchdown_s is not None
            and t - self._last_touchdown_s > self._step_window_s()
        ):
            return self._lose_sync(
                f"missed touchdown: none for {t - self._last_touchdown_s:.3f} s after leg {self.stance_leg}'s "
                f"(longest plausible step {self._step_window_s():.3f} s)"
            )
        v = self._est.estimate(lead_s=0.5 * self._dt_s + p.lock_lead_s)
        if v is None:
            return NOTHING
        self.velocity_m_s = v
        if t < self._distrust_until_s:
            self._touch_count = 0
            self._lock_count = 0
            return NOTHING

        # Touchdown detection (WAIT and CLUTCHED), debounced, with a refractory time.
        if self.phase in (Phase.WAIT, Phase.CLUTCHED):
            if self._need_quiet:
                self._need_quiet = v > p.touch_velocity_m_s
                self._doubt_forget()
                return NOTHING
            if self.counted and self.synced and (p.doubt_compression_m > 0 or p.doubt_noise_sigmas > 0):
                doubt = self._doubt(t, v, displacement_m)
                if doubt is not None:
                    return doubt
            if v > p.touch_velocity_m_s and t - self._touchdown_s >= p.min_step_s:
                if self._touch_count == 0:
                    self._onset_x_m = prev_x
                self._touch_count += 1
            else:
                self._touch_count = 0
            moved = self.position_m - self._onset_x_m >= p.touch_compression_m
            if self._touch_count >= p.touch_debounce_samples and moved:
                if self._windowed() and t < self._next_touchdown_s() - self._early_window_s():
                    # Too early for the next step: the stance foot coming down again. It does not move the count,
                    # and the pattern must be confirmed again (a period measured double shows as a bounce every step).
                    self._touch_count = 0
                    self._confirmed = 0
                    self._need_quiet = True
                    self._doubt_forget()
                    return Decision(events=("bounce_ignored",))
                if self.awaiting_clean_touchdown and self._arm_s_rest_m is not None:
                    judged = self._judge_first_touchdown()
                    if judged is not None:
                        return judged
                return self._touchdown(t)
            return NOTHING

        # Double support / free compression: wait for the zero crossing.
        if self.phase is Phase.DOUBLE_SUPPORT and t - self._touchdown_s >= p.double_support_s:
            self.phase = Phase.FREE_COMPRESSION
        self._peak_v = max(self._peak_v, v)
        armed = self._peak_v > p.touch_velocity_m_s and self.compression_m >= p.min_compression_m
        if armed and v <= p.lock_velocity_m_s:
            self._lock_count += 1
        else:
            self._lock_count = 0
        doubting = p.doubt_compression_m > 0 or p.doubt_noise_sigmas > 0
        if (
            self.counted
            and doubting
            and not armed
            and v <= p.lock_velocity_m_s
            and t - self._touchdown_s >= p.double_support_s
        ):
            # The compression peaked too shallow or too slow to lock: it is over, and the next rise must be a
            # touchdown or a doubt (not hidden in this phase until max_compression_s). With the doubt test on only.
            self.phase = Phase.WAIT
            self._touch_count = 0
            self._doubt_forget()
            return Decision(events=("no_lock",))
        if self._lock_count >= p.lock_debounce_samples:
            self.phase = Phase.CLUTCHED
            self._lock_count = 0
            self.lock_time_s = t
            if not self._touchdown_unseen:
                delay = t - self._touchdown_s
                self._lock_delay_min_s = delay if self._lock_delay_min_s is None else min(self._lock_delay_min_s, delay)
            self._doubt_forget()
            if not self.synced:
                self._engaged = False
                return Decision(events=("lock_unsynced",))  # detected, but the leg is not known
            if not self.lock_allowed:
                self._engaged = False
                return Decision(events=("lock_withheld",))  # the count is not confirmed yet
            if (
                self.counted
                and p.touch_window_early_fraction > 0
                and (self._predicted_touchdown_s is None or t < self._predicted_touchdown_s)
            ):
                # Before the step the measured period predicts: the touchdown may have been a bounce.
                self._engaged = False
                return Decision(events=("lock_early_withheld",))
            self._engaged = True
            return Decision(engage=self.stance_leg, events=("lock",))
        if t - self._touchdown_s > p.max_compression_s:
            self.phase = Phase.WAIT
            self._touch_count = 0
            return Decision(events=("no_zero_crossing",))
        return NOTHING

    def _doubt_forget(self) -> None:
        self._rise.forget()

    def _next_touchdown_s(self) -> float:
        assert self._last_touchdown_s is not None and self._period_s is not None
        return self._last_touchdown_s + self._period_s

    def _doubt(self, t: float, v: float, dx_m: float) -> Decision | None:
        """Follow the leg's mean position in WAIT/CLUTCHED: a rise of at least `doubt_threshold_m` above its lowest
        mean of the last `max_compression_s`, then a fall of half of it, without a confirmed touchdown in between,
        may have been a step: the count is lost. With a measured period and the touchdown window on, a rise that
        began before the window is a bounce and is forgotten. Quiet samples (slow, no rise) measure the noise."""
        p = self.params
        threshold = self.doubt_threshold_m()
        if abs(v) < 0.5 * p.touch_velocity_m_s and self._rise.rise_m() < 0.5 * threshold:
            self.noise.add_quiet(dx_m, self._dt_s)
        if self.phase is Phase.CLUTCHED and v < -0.5 * p.touch_velocity_m_s:
            self._doubt_forget()  # the locked step's own rebound (the mean lags it): explained
            return None
        if not math.isfinite(threshold):
            threshold = p.doubt_compression_m if p.doubt_compression_m > 0 else math.inf
            if not math.isfinite(threshold):
                return None
        peak = self._rise.watch(t, threshold)
        if peak is None:
            return None
        began = self._rise.cross_s
        self._doubt_forget()
        if self._windowed() and began is not None and began < self._next_touchdown_s() - self._early_window_s():
            self._confirmed = 0
            return Decision(events=("bounce_ignored",))
        return self._lose_sync(
            f"uncertain touchdown: the leg compressed {peak * 1e3:.3f} mm without a confirmed touchdown "
            f"(threshold {threshold * 1e3:.3f} mm); a step may have been missed"
        )

    def _confirmation_overdue(self) -> str:
        """Count a touchdown that left the count unconfirmed; at the `confirm_within_steps`-th of them, why the count is
        lost ("" while within)."""
        p = self.params
        confirmed = self._confirmed >= p.confirm_steps
        self._unconfirmed_touchdowns = 0 if confirmed else self._unconfirmed_touchdowns + 1
        if not p.confirm_within_steps or self._unconfirmed_touchdowns < p.confirm_within_steps:
            return ""
        return (
            f"count not confirmed: {self._unconfirmed_touchdowns} touchdowns without {p.confirm_steps} step intervals "
            f"matching the measured period ({self._period_s or 0.0:.3f} s; confirm_within_steps "
            f"{p.confirm_within_steps}): a touchdown between every two accepted ones, as when a step unseen while "
            "the period was measured makes it twice the real one; arm again naming the leg on the ground"
        )

    def _touchdown(self, t: float) -> Decision:
        self._before_touchdown = (
            self.leg_index,
            self._last_touchdown_s,
            self._period_s,
            self._touchdown_s,
            self._touchdown_x_m,
            self._confirmed,
            self._unconfirmed_touchdowns,
            self.awaiting_clean_touchdown,
        )
        release = self.stance_leg if self.phase is Phase.CLUTCHED else None
        self.awaiting_clean_touchdown = False  # seen from rest after the last resync: the count starts here
        self._touchdown_unseen = False
        self._engaged = False
        self._doubt_forget()
        self.leg_index = (self.leg_index + 1) % len(self.legs)
        last = self._last_touchdown_s
        self._predicted_touchdown_s = None if last is None or self._period_s is None else last + self._period_s
        self._last_touchdown_s = t
        lost = ""
        if self.counted and self.synced and last is not None:
            step = t - last
            tol = self.params.step_period_tolerance
            if self._period_s is not None and step < self._period_s * (1.0 - tol):
                lost = (
                    f"extra touchdown: {step:.3f} s after the previous one, expected "
                    f"{self._period_s:.3f} s +/- {100 * tol:.0f} %"
                )
            elif step > self._step_window_s():
                lost = f"missed touchdown: step of {step:.3f} s (longest plausible {self._step_window_s():.3f} s)"
            elif self._period_s is None:
                self._period_s = step  # the first interval measures the period; it confirms nothing
            else:
                self._period_s = 0.5 * (self._period_s + step)
                self._confirmed += 1
        if self.counted and self.synced and not lost:
            lost = self._confirmation_overdue()
        self.phase = Phase.DOUBLE_SUPPORT
        self._touch_count = 0
        self._lock_count = 0
        self._touchdown_s = t
        self._touchdown_x_m = self._onset_x_m
        self._peak_v = 0.0
        if lost:
            self.synced = False
            self.sync_detail = lost
            return Decision(release=release, events=("touchdown", "sync_lost"))
        return Decision(release=release, events=("touchdown",))
