"""A virtual-clock rig for the leg-identity tests: the robot's own `Controller` on one register-level fake
ADNS-3080 counting eight legs, stepped at a fixed rate through a scripted `FakeWalk`, every engage recorded
with its (virtual) time so that it can be judged against the walk's truth."""

from __future__ import annotations

from dataclasses import dataclass, field

from gpiozero.pins.mock import MockFactory

from rimless.firmware.control.controller import Channel, Controller, EventRecord
from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.control.faults import HealthLimits, HealthMonitor
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080
from rimless.firmware.drivers.fake_walk import FakeWalk, airborne_locks

PINS = [17, 27, 22, 23, 24, 16, 20, 21]
LEGS = list(range(8))


class VirtualClock:
    def __init__(self) -> None:
        self.t_s = 0.0

    def seconds(self) -> float:
        return self.t_s

    def ns(self) -> int:
        return int(round(self.t_s * 1e9))

    def sleep(self, s: float) -> None:
        self.t_s += s


@dataclass
class WalkResult:
    engages: list[tuple[float, int]] = field(default_factory=list)
    events: list[tuple[float, str, dict]] = field(default_factory=list)
    airborne: list[tuple[float, int, int]] = field(default_factory=list)

    def names(self) -> list[str]:
        return [name for _t, name, _f in self.events]

    def faults(self) -> list[str]:
        return [f["fault"] for _t, name, f in self.events if name == "fault"]


def walk_controller(
    walk: FakeWalk,
    params: DetectorParams,
    *,
    duration_s: float = 3.0,
    rate_hz: float = 300.0,
    start_index: int = 0,
    seed: int = 0,
    fault_at: tuple[float, object] | None = None,
    verify_before_engage: bool = True,
    id_check_interval_s: float = 0.0,
    readback_every_samples: int = 1,
    cpi: int = 1600,
    records: list | None = None,
) -> WalkResult:
    """Arm at t = 0 naming the leg the walk starts on (`LEGS[start_index]`, as the operator does: the robot's
    defaults lock nothing before) and step the controller at `rate_hz` for `duration_s` of virtual time; `fault_at` =
    (t_s, action(fake)) injects a fault into the fake. The sensor is configured at `cpi` with the automatic
    frame rate, as the service does (`mark_configured` included). Every controller record goes to `records`."""
    clock = VirtualClock()
    fake = FakeAdns3080(
        walk, counts_per_m=DEFAULT_COUNTS_PER_M, noise_counts=0.3, seed=seed, clock=clock.seconds, needs_reset=False
    )
    drv = Adns3080(
        fake,
        counts_per_m=DEFAULT_COUNTS_PER_M * cpi / 1600,
        sleep=clock.sleep,  # type: ignore[arg-type]
        clock_ns=clock.ns,
    )
    drv.set_resolution(cpi)
    drv.set_frame_rate(None)
    drv.mark_configured()
    clock.t_s = 0.0  # the configuration's waits are over before the walk's time starts
    bank = ClutchBank(PINS, pin_factory=MockFactory())
    ctl = Controller(
        [Channel(drv, LegDetector(params, LEGS, start_index=start_index), HealthMonitor(HealthLimits()))],
        bank,
        clock_ns=clock.ns,
        id_check_interval_s=id_check_interval_s,
        verify_before_engage=verify_before_engage,
        readback_every_samples=readback_every_samples,
    )
    res = WalkResult()
    try:
        ctl.arm(stance_leg=LEGS[start_index])
        for k in range(int(duration_s * rate_hz)):
            clock.t_s = k / rate_hz
            if fault_at is not None and clock.t_s >= fault_at[0]:
                fault_at[1](fake)  # type: ignore[operator]
                fault_at = None
            before = set(bank.engaged())
            ctl.step()
            for leg in sorted(set(bank.engaged()) - before):
                res.engages.append((clock.t_s, leg))
            while ctl.outbox:
                rec = ctl.outbox.popleft()
                if records is not None:
                    records.append(rec)
                if isinstance(rec, EventRecord):
                    res.events.append((clock.t_s, rec.name, rec.fields))
    finally:
        bank.close()
    res.airborne = airborne_locks(walk, res.engages, LEGS, start_index)
    return res
