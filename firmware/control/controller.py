"""The control path: read each sensor, check its health, run its detector, switch the clutches.

Synchronous and allocation-light: it runs in the sampler thread, never touches the network or the
disk, and hands its records to the asyncio side through a bounded deque (oldest dropped when full).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

from rimless.firmware.control.detector import Decision, DetectorParams, LegDetector, Phase
from rimless.firmware.control.faults import Fault, HealthMonitor
from rimless.firmware.drivers.adns3080 import MotionSample
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.errors import SensorError, SensorNotFound, SensorReset


class MotionSensor(Protocol):
    """What the controller needs from a sensor driver (`Adns3080`)."""

    def read_motion(self) -> MotionSample:
        """One timestamped motion read."""
        ...

    def verify_id(self) -> int:
        """Check the chip's identity; raise SensorNotFound on mismatch."""
        ...


class SampleRecord(NamedTuple):
    """One sample of one channel, as logged and sent (SI; times in monotonic ns)."""

    t_ns: int
    seq: int
    channel: int
    position_m: float  # integrated displacement since start
    velocity_m_s: float  # estimated compression velocity
    compression_m: float  # since the last touchdown
    squal: int
    shutter: int
    max_pixel: int
    phase: int  # Phase.code
    stance_leg: int
    clutch_mask: int  # bit i = clutch i engaged
    armed: bool
    latency_ns: int  # sample timestamp to clutch command (or decision when none)


class EventRecord(NamedTuple):
    """A named event: touchdown, lock, release, arm, disarm, fault, param, trial..."""

    t_ns: int
    name: str
    fields: dict[str, Any]


Record = SampleRecord | EventRecord


@dataclass
class Channel:
    """One sensor and the detector of the legs it watches."""

    sensor: MotionSensor
    detector: LegDetector
    health: HealthMonitor


class Controller:
    """Owns the clutches and the detectors; applies decisions only while armed.

    :param max_hold_s: a clutch engaged longer than this trips `Fault.CLUTCH_TIMEOUT`.
    :param id_check_interval_s: how often to read back every identity and configuration register
        (`Adns3080.check_all`; 0 = never).
    :param verify_before_engage: also read them all back right before every engage (a mismatch faults
        instead of engaging).
    :param readback_every_samples: read back one of them (`check_next`, in turn) from every sensor every this
        many samples (0 = never): a wrong Product_ID or a brown-out (at any resolution) is found within
        `READBACK_REGISTERS` (5) times this many samples.
    """

    def __init__(
        self,
        channels: Sequence[Channel],
        clutches: ClutchBank,
        *,
        max_hold_s: float = 1.0,
        id_check_interval_s: float = 1.0,
        outbox_len: int = 20000,
        clock_ns: Callable[[], int] = time.monotonic_ns,
        verify_before_engage: bool = True,
        readback_every_samples: int = 1,
    ) -> None:
        self.channels = list(channels)
        self.clutches = clutches
        self.max_hold_s = max_hold_s
        self.id_check_interval_s = id_check_interval_s
        self.verify_before_engage = verify_before_engage
        self.readback_every_samples = max(0, int(readback_every_samples))
        self._steps = 0
        self.clock_ns = clock_ns
        self.outbox: deque[Record] = deque(maxlen=outbox_len)
        self.armed = False
        self.active_faults: dict[Fault, str] = {}
        self.seq = 0
        self.samples = 0
        self.clutch_commands = 0
        self._next_id_check_ns = 0
        self._mask = 0
        self.last_latency_ns = 0
        self.last_had_command = False
        # several sensors: which channel's leg is on the ground, which one was before it (the trailing leg),
        # and when the last step was seen (arm counts as one)
        self._stance_channel: int | None = None
        self._trailing_channel: int | None = None
        self._last_touchdown_ns: int | None = None
        self._order_lost = ""  # several sensors: a step measured out of order (the named stance leg was wrong)

    # --- commands (called in the sampler thread) ------------------------------------------------
    def arm(self, stance_leg: int | None = None) -> dict[str, Any]:
        """Clear latched faults and let decisions reach the clutches.

        `stance_leg` (a clutch index) names the leg on the ground now (at the last sample) and re-synchronises
        the count of the sensor watching it (`LegDetector.resync`): every clutch is released, a step under way
        is that leg's own, and nothing locks before the next clean touchdown, wherever in a step the arm lands.
        Without it the count carries on, which is refused (ValueError) when a counting sensor has lost it.
        Each sensor's motion accumulators are cleared (Motion_Clear also clears a latched overflow).
        """
        if stance_leg is not None:
            owners = [ch for ch in self.channels if stance_leg in ch.detector.legs]
            if not owners:
                raise ValueError(f"stance_leg {stance_leg} is not a leg any sensor watches")
        if self._order_lost and stance_leg is None:
            raise ValueError(
                f"the stance leg is not known ({self._order_lost}); arm with stance_leg = the clutch index "
                "of the leg on the ground now"
            )
        lost = [ch.detector for ch in self.channels if not ch.detector.synced and stance_leg not in ch.detector.legs]
        if lost:
            raise ValueError(
                f"the stance leg is not known ({lost[0].sync_detail}); arm with stance_leg = the clutch index "
                "of the leg on the ground now"
            )
        if stance_leg is not None:
            self._all_off()  # nothing stays locked on the old count
        for ch in self.channels:
            if stance_leg is not None and stance_leg in ch.detector.legs:
                ch.detector.resync(stance_leg)
            clear = getattr(ch.sensor, "clear_motion", None)
            if clear is not None:
                try:
                    clear()
                except SensorError as err:
                    self.fault(Fault.SPI_ERROR, str(err))
                    raise RuntimeError(f"cannot arm: {err}") from None
            ch.health.reset()
        self.active_faults.clear()
        self.armed = True
        owner = [i for i, ch in enumerate(self.channels) if stance_leg is not None and stance_leg in ch.detector.legs]
        if owner:
            self._stance_channel, self._trailing_channel = owner[0], None
            self._order_lost = ""
        self._last_touchdown_ns = self.clock_ns()
        self._event("arm", stance_leg=stance_leg)
        return self.status()

    def disarm(self, reason: str = "command") -> dict[str, Any]:
        """All clutches off; decisions no longer reach them."""
        self.armed = False
        self._all_off()
        self._event("disarm", reason=reason)
        return self.status()

    def set_param(self, name: str, value: Any) -> dict[str, Any]:
        """Set a detector parameter on every channel (ValueError names a bad one)."""
        params = self.channels[0].detector.params.with_value(name, value)
        for ch in self.channels:
            ch.detector.set_params(params)
        self._event("param", param=name, value=getattr(params, name))
        return {"name": name, "value": getattr(params, name)}

    def set_stance_leg(self, channel: int, index: int) -> None:
        """Tell a channel which of its legs is on the ground (index into its `legs`)."""
        self.channels[channel].detector.reset(index)

    def synchronised(self) -> bool:
        """True when every sensor knows its stance leg."""
        return all(ch.detector.synced for ch in self.channels)

    def params(self) -> DetectorParams:
        """The detector parameters in force."""
        return self.channels[0].detector.params

    def status(self) -> dict[str, Any]:
        """A JSON-able snapshot."""
        return {
            "armed": self.armed,
            "faults": {f.value: d for f, d in self.active_faults.items()},
            "engaged": self.clutches.engaged(),
            "samples": self.samples,
            "clutch_commands": self.clutch_commands,
            "channels": [
                {
                    "phase": ch.detector.phase.value,
                    "stance_leg": ch.detector.stance_leg,
                    "velocity_m_s": ch.detector.velocity_m_s,
                    "compression_m": ch.detector.compression_m,
                    "synchronised": ch.detector.synced,
                    "awaiting_touchdown": ch.detector.awaiting_clean_touchdown,
                    "sync_detail": ch.detector.sync_detail,
                }
                for ch in self.channels
            ],
        }

    # --- fail-safe ------------------------------------------------------------------------------
    def fault(self, fault: Fault, detail: str, t_ns: int | None = None) -> None:
        """All clutches off, disarm, and report `fault` once while it stays active."""
        self._all_off()
        self.armed = False
        if fault not in self.active_faults:
            self.active_faults[fault] = detail
            self.outbox.append(
                EventRecord(
                    self.clock_ns() if t_ns is None else t_ns,
                    "fault",
                    {"fault": fault.value, "code": fault.code, "detail": detail},
                )
            )

    def safe_stop(self, reason: str) -> None:
        """Called on shutdown: clutches off, disarmed."""
        self.armed = False
        self._all_off()
        self._event("stop", reason=reason)

    def _all_off(self) -> None:
        self.clutches.all_off()
        self._mask = 0

    def _event(self, event: str, **fields: Any) -> None:
        self.outbox.append(EventRecord(self.clock_ns(), event, fields))

    # --- the sample -----------------------------------------------------------------------------
    def step(self) -> None:
        """Read every channel once and act on it, then read back one register of each sensor (in turn)."""
        for i, ch in enumerate(self.channels):
            self._step_channel(i, ch)
        self._steps += 1
        if self.readback_every_samples and self._steps % self.readback_every_samples == 0 and not self.active_faults:
            # (with a fault latched the clutches are off and disarmed already: its diagnosis stands alone)
            for i, ch in enumerate(self.channels):
                self._read_back(i, ch, full=False)
        now = self.clock_ns()
        if self._mask and self.clutches.longest_hold_s(now) > self.max_hold_s:
            self.fault(Fault.CLUTCH_TIMEOUT, f"clutch held longer than max_hold_s={self.max_hold_s}", now)
        if self.id_check_interval_s > 0 and now >= self._next_id_check_ns:
            self._next_id_check_ns = now + int(self.id_check_interval_s * 1e9)
            for i, ch in enumerate(self.channels):
                self._read_back(i, ch, full=True, t_ns=now)

    def _read_back(self, i: int, ch: Channel, *, full: bool, t_ns: int | None = None) -> None:
        """Read back the sensor's identity and configuration (all of it, or the next register in turn); a
        mismatch faults (`id_mismatch`, `sensor_reset`). A sensor without read-back has its ID checked (full)."""
        check = getattr(ch.sensor, "check_all" if full else "check_next", None)
        if check is None and not full:
            return
        try:
            check() if check is not None else ch.sensor.verify_id()
        except SensorReset as err:
            self.fault(Fault.SENSOR_RESET, f"sensor {i}: {err}", t_ns)
        except SensorNotFound as err:
            self.fault(Fault.ID_MISMATCH, str(err), t_ns)
        except SensorError as err:
            self.fault(Fault.SPI_ERROR, str(err), t_ns)

    def _check_step(self, i: int, det: LegDetector, t_ns: int, decision: Decision) -> Decision:
        """With several sensors, a touchdown is a step only on a leg that is neither on the ground nor the
        one just before it (the trailing leg, whose foot may come down again after its clutch lets go),
        and at least `min_step_s` after the last step (or the arm). Otherwise the detector is told to
        dismiss it and nothing is switched (event `touchdown_dismissed`). A step on any leg but the one after the
        stance leg (channels in touchdown order) is measured proof that the stance leg is wrong: `leg_sync_lost`,
        and `arm` then needs the stance leg named."""
        too_soon = self._last_touchdown_ns is not None and t_ns - self._last_touchdown_ns < det.params.min_step_s * 1e9
        if i in (self._stance_channel, self._trailing_channel) or too_soon:
            det.dismiss_touchdown()
            why = (
                "too soon after the last step"
                if too_soon
                else ("the stance leg's" if i == self._stance_channel else "the trailing leg's")
            )
            self.outbox.append(
                EventRecord(t_ns, "touchdown_dismissed", {"channel": i, "leg": det.stance_leg, "why": why})
            )
            return Decision(release=decision.release)
        expected = None if self._stance_channel is None else (self._stance_channel + 1) % len(self.channels)
        if expected is not None and i != expected:
            # A step measured on a leg that is not the next one after the stance leg (channels are in touchdown
            # order): the stance leg named at arm, or the one followed since, is not the leg on the ground.
            det.dismiss_touchdown()
            self._order_lost = (
                f"sensor {i} measured a step, but the leg after the stance leg is sensor {expected}'s: "
                "the stance leg named at arm is wrong"
            )
            self._stance_channel = self._trailing_channel = None
            self.fault(Fault.LEG_SYNC_LOST, self._order_lost, t_ns)
            return Decision(release=decision.release)
        self._trailing_channel, self._stance_channel = self._stance_channel, i
        self._last_touchdown_ns = t_ns
        return decision

    def _step_channel(self, i: int, ch: Channel) -> None:
        try:
            s = ch.sensor.read_motion()
        except SensorError as err:
            self.fault(Fault.SPI_ERROR, str(err))
            return
        self.samples += 1
        bad = ch.health.check(s.t_ns, s.squal, s.saturated or s.overflow, s.stuck)
        if bad is None and s.resolution_reset:
            bad = (
                Fault.SENSOR_RESET,
                "the sensor reports 400 cpi: it reset itself (brown-out?); restart the firmware to configure it again",
            )
        if bad is not None:
            self.fault(bad[0], bad[1], s.t_ns)
        det = ch.detector
        trusted = bad is None and s.squal >= ch.health.limits.squal_min and not (s.saturated or s.overflow)
        decision = det.update(s.t_ns, s.displacement_m, trusted=trusted)
        if "touchdown" in decision.events and len(self.channels) > 1:
            decision = self._check_step(i, det, s.t_ns, decision)
        if decision.release is not None:
            self.clutches.release(decision.release)
            self._mask &= ~(1 << decision.release)
            if self.armed:
                self.clutch_commands += 1
        if "touchdown" in decision.events and len(self.channels) > 1:
            # The next leg is down: no other leg may stay clutched (one sensor per leg).
            for other in self.channels:
                if other is not ch and other.detector.phase is Phase.CLUTCHED:
                    leg = other.detector.stance_leg
                    other.detector.released_elsewhere()
                    self.clutches.release(leg)
                    self._mask &= ~(1 << leg)
        if "sync_lost" in decision.events:
            self.fault(Fault.LEG_SYNC_LOST, f"sensor {i}: {det.sync_detail}", s.t_ns)
        if decision.engage is not None and self.armed and self.verify_before_engage:
            # Identity and configuration read back right before every engage: a sensor swapped, unplugged,
            # answering garbage or reset by a brown-out is found before it can clutch (five register reads,
            # ~0.3 ms at 2 MHz).
            self._read_back(i, ch, full=True, t_ns=s.t_ns)
        if decision.engage is not None and self.armed:
            self.clutches.engage(decision.engage, s.t_ns)
            self._mask |= 1 << decision.engage
            self.clutch_commands += 1
        t_done = self.clock_ns()
        for name in decision.events:
            fields = {"channel": i, "leg": det.stance_leg, "armed": self.armed, "compression_m": det.compression_m}
            if decision.release is not None:
                fields["released_leg"] = decision.release
            self.outbox.append(EventRecord(s.t_ns, name, fields))
        self.seq += 1
        self.outbox.append(
            SampleRecord(
                s.t_ns,
                self.seq,
                i,
                det.position_m,
                det.velocity_m_s,
                det.compression_m,
                s.squal,
                s.shutter,
                s.max_pixel,
                det.phase.code,
                det.stance_leg,
                self._mask,
                self.armed,
                t_done - s.t_ns,
            )
        )
        self.last_latency_ns = t_done - s.t_ns
        self.last_had_command = decision.engage is not None or decision.release is not None
