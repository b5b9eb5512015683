"""Shared by the firmware tests: a virtual clock driving the register-level fake, the driver, the controller
and gpiozero MockFactory pins (`Rig`), so detector and fail-safe tests run sample by sample, without sleeping."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from gpiozero.pins.mock import MockFactory

from rimless.firmware.control.controller import Controller, EventRecord, SampleRecord
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.fake_adns3080 import FakeAdns3080

PINS = (17, 27, 22, 23, 24, 16, 20, 21)


class VirtualClock:
    """Seconds, advanced by hand (`t`, `sleep`) or by a loop waiting for its next deadline: it is also a
    `rimless.firmware.clock.Clock` (`now_ns`, `sleep_until`), so the sampler thread can run on it."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def ns(self) -> int:
        return round(self.t * 1e9)

    def sleep(self, s: float) -> None:
        self.t += s

    def now_ns(self) -> int:
        return self.ns()

    def sleep_until(self, deadline_ns: int) -> None:
        self.t = max(self.t, deadline_ns * 1e-9)


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

    def pin(self, leg: int):
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
