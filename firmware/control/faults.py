"""Fault codes and the per-sample sensor health checks that trigger the fail-safe.

Every fault drives all clutches off and disarms; it is reported once when it becomes active, as an
event in telemetry and the trial log (`code` is numeric so PlotJuggler can plot it).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Fault(str, Enum):
    """Why the fail-safe fired."""

    SPI_ERROR = "spi_error"
    ID_MISMATCH = "id_mismatch"
    SENSOR_STUCK = "sensor_stuck"  # reserved Motion bits set: MISO stuck or link out of sync
    SENSOR_STALLED = "sensor_stalled"  # no sample for stall_timeout_s
    MOTION_SATURATED = "motion_saturated"  # overflow or full-scale deltas, repeatedly
    SQUAL_LOW = "squal_low"
    CLUTCH_TIMEOUT = "clutch_timeout"  # a clutch held longer than max_hold_s
    LINK_LOST = "link_lost"  # no command for link_timeout_s while armed
    EXCEPTION = "exception"  # a bug: the app stops
    SIGNAL = "signal"  # SIGINT/SIGTERM
    LEG_SYNC_LOST = "leg_sync_lost"  # a missed or extra touchdown: the stance leg is not known
    SENSOR_RESET = "sensor_reset"  # the sensor reset itself (Motion RES bit back to 400 cpi)
    LOOP_STALLED = "loop_stalled"  # the event loop did not feed the watchdog in time
    WATCHDOG_STALLED = "watchdog_stalled"  # the watchdog thread itself completed no round in time

    @property
    def code(self) -> int:
        """Stable numeric code (1-based) for telemetry plots."""
        return list(Fault).index(self) + 1


@dataclass(frozen=True, slots=True)
class HealthLimits:
    """Thresholds of the sensor-health checks (SI)."""

    squal_min: int = 10  # SQUAL below this is "no surface"
    squal_low_s: float = 0.05  # ...for this long
    saturated_samples_max: int = 3  # consecutive saturated or overflowed samples


class HealthMonitor:
    """Debounced SQUAL and saturation checks on consecutive samples."""

    def __init__(self, limits: HealthLimits) -> None:
        self.limits = limits
        self._squal_low_since_ns: int | None = None
        self._saturated = 0

    def reset(self) -> None:
        """Forget the debounce state."""
        self._squal_low_since_ns = None
        self._saturated = 0

    def check(self, t_ns: int, squal: int, saturated: bool, stuck: bool) -> tuple[Fault, str] | None:
        """Return (fault, detail) if this sample makes a fault active, else None."""
        if stuck:
            return (
                Fault.SENSOR_STUCK,
                "every byte of the motion burst reads 0xFF or SQUAL > 169 (MISO stuck or link out of sync)",
            )
        if saturated:
            self._saturated += 1
            if self._saturated >= self.limits.saturated_samples_max:
                return Fault.MOTION_SATURATED, f"{self._saturated} consecutive saturated/overflowed reads"
        else:
            self._saturated = 0
        if squal < self.limits.squal_min:
            if self._squal_low_since_ns is None:
                self._squal_low_since_ns = t_ns
            elif (t_ns - self._squal_low_since_ns) * 1e-9 >= self.limits.squal_low_s:
                return Fault.SQUAL_LOW, f"SQUAL {squal} < {self.limits.squal_min} for {self.limits.squal_low_s} s"
        else:
            self._squal_low_since_ns = None
        return None
