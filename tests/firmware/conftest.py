"""The `make_rig` fixture: a `Rig` (tests.support.firmware_rig) built and closed per test."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from gpiozero.pins.mock import MockFactory

from rimless.firmware.control.controller import Channel, Controller
from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.control.faults import HealthLimits, HealthMonitor
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080
from tests.support.firmware_rig import PINS, Rig, VirtualClock


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
        sensor = Adns3080(
            fake, counts_per_m=DEFAULT_COUNTS_PER_M, reset=fake.set_reset, sleep=clock.sleep, clock_ns=clock.ns
        )
        sensor.power_up()
        sensor.set_resolution(1600)
        factory = MockFactory(revision="c03111")
        factories.append(factory)
        bank = ClutchBank(PINS, pin_factory=factory)
        banks.append(bank)
        clock.t = 0.0  # the gait's time axis starts after power-up
        det = LegDetector(params or DetectorParams(), legs, start_index=start_index)
        ctl = Controller(
            [Channel(sensor, det, HealthMonitor(limits or HealthLimits()))],
            bank,
            max_hold_s=max_hold_s,
            id_check_interval_s=id_check_interval_s,
            clock_ns=clock.ns,
        )
        if arm:
            ctl.arm()
        return Rig(clock, fake, sensor, ctl, factory, rate_hz)

    yield make
    for bank in banks:
        bank.close()
    for f in factories:
        f.close()
