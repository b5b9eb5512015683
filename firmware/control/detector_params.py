"""The detector's parameters (`DetectorParams`): SI, unit-suffixed, validated, each changeable at run time with
`set` (`with_value`). What each one does is said beside it; `rimless.firmware.control.detector` uses them (and
re-exports the class, its import name before it had a module of its own)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class DetectorParams:
    """Detector parameters (SI, unit-suffixed). All may be changed at run time with `set`."""

    velocity_window_s: float = 0.02  # span of the quadratic velocity fit
    touch_velocity_m_s: float = 0.05  # compression velocity that means a leg touched down
    touch_debounce_samples: int = 2  # consecutive samples above it
    touch_compression_m: float = 0.0005  # and the leg must really have moved this much since onset
    lock_velocity_m_s: float = 0.0  # lock when the predicted compression velocity is <= this
    lock_debounce_samples: int = 1  # consecutive samples at or below it
    lock_lead_s: float = 0.0  # extra prediction (e.g. the clutch's engage delay)
    min_compression_m: float = 0.001  # compression needed before a lock may happen (hysteresis)
    double_support_s: float = 0.02  # how long after touchdown the phase reads double support
    min_step_s: float = 0.08  # refractory time between touchdowns (debounce)
    max_compression_s: float = 0.5  # no zero crossing this long after touchdown: back to wait
    max_step_s: float = 1.0  # no touchdown this long after the previous one: the count is lost
    step_period_tolerance: float = 0.4  # a step outside (1 -/+ this) x the running period loses the count
    # A counted sensor locks only after this many step intervals since (re)sync matched the measured period (the
    # first interval measures it and confirms nothing; 0: lock from the first touchdown; the robot's default is 2).
    confirm_steps: int = 0
    # A counted sensor loses the count when this many touchdowns since (re)sync, or since a bounce restarted the
    # confirmation, have not brought `confirm_steps` matching intervals: a step unseen while the first interval
    # measured the period makes it twice the real one and every other touchdown a bounce, and nothing would ever
    # lock (0: off; at least confirm_steps + 2, the touchdowns a clean (re)sync needs; the robot's default is 5).
    confirm_within_steps: int = 0
    # A counted sensor loses the count when the leg compresses by this much (m) and stops without a confirmed
    # touchdown: a gentle step the touchdown test missed (0: off; the robot's default is 0.0003).
    doubt_compression_m: float = 0.0
    # A counted sensor's doubt threshold relative to the measured noise: this many standard deviations of the
    # smoothed position's rise (noise measured at rest, in WAIT), at least two position quanta; it replaces
    # doubt_compression_m as the threshold, which then bounds it: a sensor too noisy to see a rise of
    # doubt_compression_m withholds every lock (0: off, the fixed doubt_compression_m; the robot's default is 6).
    doubt_noise_sigmas: float = 0.0
    doubt_smooth_s: float = 0.04  # the doubt test follows the mean position over this span (s)
    # A counted sensor with a measured period accepts a touchdown no earlier than this fraction of the measured
    # touchdown-to-lock time before the predicted one (a compression earlier in the step is a bounce: ignored, it
    # does not move the count), and never locks before the predicted touchdown time (0: off, an early touchdown
    # is an extra one, sync lost; the robot's default is 0.5).
    touch_window_early_fraction: float = 0.0
    # 1: a counted sensor locks only after `resync` (arm with stance_leg) named the leg on the ground: one sensor
    # cannot tell the legs apart, so a configured start leg is never trusted (0: trusted; the robot's default is 1).
    named_stance_required: int = 0

    def validated(self) -> DetectorParams:
        """Return self, or raise ValueError naming the bad field."""
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{f.name} must be a finite number, got {value!r}")
            if f.name.endswith("_samples"):
                if not isinstance(value, int) or not 1 <= value <= 1000:
                    raise ValueError(f"{f.name} must be an integer in 1..1000, got {value!r}")
            elif f.name in ("lock_velocity_m_s",):
                if not -1.0 <= value < self.touch_velocity_m_s:
                    raise ValueError(f"{f.name} must be in [-1, touch_velocity_m_s), got {value!r}")
            elif f.name in ("lock_lead_s", "double_support_s"):
                if not 0.0 <= value <= 1.0:
                    raise ValueError(f"{f.name} must be in [0, 1], got {value!r}")
            elif f.name == "confirm_steps":
                if not isinstance(value, int) or not 0 <= value <= 20:
                    raise ValueError(f"{f.name} must be an integer in 0..20, got {value!r}")
            elif f.name == "confirm_within_steps":
                if not isinstance(value, int) or not (value == 0 or self.confirm_steps + 2 <= value <= 100):
                    raise ValueError(
                        f"{f.name} must be 0 (off) or an integer in confirm_steps + 2 ({self.confirm_steps + 2})..100, "
                        f"got {value!r}"
                    )
            elif f.name == "doubt_compression_m":
                if not 0.0 <= value <= 0.1:
                    raise ValueError(f"{f.name} must be in [0, 0.1] m, got {value!r}")
            elif f.name == "doubt_noise_sigmas":
                if not 0.0 <= value <= 100.0:
                    raise ValueError(f"{f.name} must be in [0, 100], got {value!r}")
            elif f.name == "named_stance_required":
                if value not in (0, 1):
                    raise ValueError(f"{f.name} must be 0 or 1, got {value!r}")
            elif f.name == "touch_window_early_fraction":
                if not 0.0 <= value <= 1.0:
                    raise ValueError(f"{f.name} must be in [0, 1], got {value!r}")
            elif f.name == "step_period_tolerance":
                if not 0.05 <= value <= 0.9:
                    raise ValueError(f"{f.name} must be in [0.05, 0.9], got {value!r}")
            elif f.name == "max_step_s":
                if not self.min_step_s < value <= 10.0:
                    raise ValueError(f"{f.name} must be in (min_step_s, 10], got {value!r}")
            elif not 0.0 < value <= 10.0:
                raise ValueError(f"{f.name} must be in (0, 10], got {value!r}")
        return self

    def with_value(self, name: str, value: Any) -> DetectorParams:
        """A copy with `name` set to `value` (validated); raises ValueError naming the parameter."""
        names = {f.name: f for f in fields(self)}
        if name not in names:
            raise ValueError(f"unknown detector parameter {name!r}; known: {', '.join(sorted(names))}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{name} must be a number, got {value!r}")
        if name.endswith("_samples") or name in ("confirm_steps", "confirm_within_steps", "named_stance_required"):
            if float(value) != int(value):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            value = int(value)
        else:
            value = float(value)
        try:
            return replace(self, **{name: value}).validated()
        except ValueError as err:
            other = str(err).split(" ", 1)[0]
            if other == name or other not in names:
                raise
            # another parameter's rule refuses the new value: say which was set, and what to set first
            raise ValueError(
                f"{name} = {value!r} is refused with {other} = {getattr(self, other)!r}: {err} (set {other} first)"
            ) from None
