"""Shared rigs: a virtual clock driving the register-level fake, the driver, the controller and
gpiozero MockFactory pins, so detector and fail-safe tests run sample by sample, without sleeping."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import pytest
from gpiozero.pins.mock import MockFactory

from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.control.controller import Channel, Controller, EventRecord, SampleRecord
from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080
from rimless.firmware.control.faults import HealthLimits, HealthMonitor

PINS = (17, 27, 22, 23, 24, 16, 20, 21)


class VirtualClock:
    """Seconds, advanced by hand."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def ns(self) -> int:
        return round(self.t * 1e9)

    def sleep(self, s: float) -> None:
        self.t += s


@dataclass
class Rig:
    """Fake sensor + driver + controller + mock clutch pins on a virtual clock."""

    clock: VirtualClock
    fake: FakeAdns3080
    sensor: Adns3080
    controller: Controller
    factory: MockFactory
    rate_hz: float
    pins: tuple[int, ...] = PINS
    lock_times: list[float] = field(default_factory=list)

    def pin(self, leg: int):  # noqa: ANN201 - MockPin
        return self.factory.pin(self.pins[leg])

    def levels(self, leg: int) -> list[bool]:
        return [s.state for s in self.pin(leg).states]

    def run(self, duration_s: float, on_sample: Callable[[Rig], None] | None = None) -> None:
        """Step the controller at rate_hz for duration_s of virtual time."""
        n = round(duration_s * self.rate_hz)
        start = self.clock.t
        for k in range(1, n + 1):
            self.clock.t = start + k / self.rate_hz
            self.controller.step()
            if on_sample is not None:
                on_sample(self)

    def events(self, name: str) -> list[EventRecord]:
        return [r for r in self.controller.outbox if isinstance(r, EventRecord) and r.name == name]

    def samples(self) -> list[SampleRecord]:
        return [r for r in self.controller.outbox if isinstance(r, SampleRecord)]


@pytest.fixture
def make_rig() -> Callable[..., Rig]:
    factories: list[MockFactory] = []
    banks: list[ClutchBank] = []

    def make(
        trajectory: Callable[[float], float],
        *,
        rate_hz: float = 300.0,
        params: DetectorParams | None = None,
        legs: tuple[int, ...] = tuple(range(8)),
        noise_counts: float = 0.3,
        seed: int = 0,
        max_hold_s: float = 1.0,
        limits: HealthLimits | None = None,
        id_check_interval_s: float = 0.0,
        arm: bool = True,
        start_index: int = -1,
    ) -> Rig:
        # start_index -1: the last leg stands at arm time, so the first touchdown is legs[0].
        clock = VirtualClock()
        fake = FakeAdns3080(trajectory, clock=clock, noise_counts=noise_counts, seed=seed)
        sensor = Adns3080(fake, counts_per_m=DEFAULT_COUNTS_PER_M, reset=fake.set_reset, sleep=clock.sleep,
                          clock_ns=clock.ns)
        sensor.power_up()
        sensor.set_resolution(1600)
        factory = MockFactory(revision="c03111")
        factories.append(factory)
        bank = ClutchBank(PINS, pin_factory=factory)
        banks.append(bank)
        clock.t = 0.0  # the gait's time axis starts after power-up
        det = LegDetector(params or DetectorParams(), legs, start_index=start_index)
        ctl = Controller([Channel(sensor, det, HealthMonitor(limits or HealthLimits()))], bank,
                         max_hold_s=max_hold_s, id_check_interval_s=id_check_interval_s, clock_ns=clock.ns)
        if arm:
            ctl.arm()
        return Rig(clock, fake, sensor, ctl, factory, rate_hz)

    yield make
    for bank in banks:
        bank.close()
    for f in factories:
        f.close()
