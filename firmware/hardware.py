"""The one place that picks the hardware backend: the real Pi (spidev + gpiozero's default pin
factory) or the fake (register-level ADNS-3080 fakes and gpiozero's MockFactory)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rimless.firmware.adns3080 import Adns3080
from rimless.firmware.clutch import ClutchBank
from rimless.firmware.config import RobotConfig, SensorConfig
from rimless.firmware.controller import Channel
from rimless.firmware.detector import LegDetector
from rimless.firmware.fake_adns3080 import FakeAdns3080, GaitTrajectory
from rimless.firmware.faults import HealthMonitor

PI4_REVISION = "c03111"  # MockFactory reports a Pi 4B with this revision


@dataclass
class Hardware:
    """Everything the app drives, plus how to close it (clutches last)."""

    channels: list[Channel]
    clutches: ClutchBank
    sensors: list[Adns3080]
    pin_factory: Any = None
    fakes: list[FakeAdns3080] = field(default_factory=list)
    closers: list[Callable[[], None]] = field(default_factory=list)

    def close(self) -> None:
        """Clutches off and released, then the buses and reset pins."""
        try:
            self.clutches.close()
        finally:
            for close in reversed(self.closers):
                try:
                    close()
                except Exception:  # noqa: BLE001 - close everything we can
                    pass


def _configure(sensor: Adns3080, cfg: SensorConfig) -> None:
    sensor.power_up()
    sensor.set_resolution(cfg.resolution_cpi)
    sensor.set_frame_rate(cfg.frame_rate_hz)
    sensor.clear_motion()


def _channels(cfg: RobotConfig, sensors: list[Adns3080]) -> list[Channel]:
    return [
        Channel(sensor, LegDetector(cfg.detector, s.legs, start_index=cfg.clutch.start_leg_index), HealthMonitor(s.health()))
        for sensor, s in zip(sensors, cfg.sensors, strict=True)
    ]


def default_fake_trajectory() -> GaitTrajectory:
    """The synthetic gait of `--fake`: a touchdown every 0.4 s, 8 mm compression peaking 60 ms later."""
    return GaitTrajectory(start_s=time.monotonic() + 0.3, step_period_s=0.4, compression_m=0.008, compression_s=0.06)


def build_fake(
    cfg: RobotConfig,
    *,
    trajectory: Callable[[float], float] | None = None,
    pin_factory: Any = None,
    noise_counts: float = 0.3,
    seed: int = 0,
) -> Hardware:
    """Fake sensors replaying `trajectory` on the monotonic clock, clutches on a MockFactory."""
    from gpiozero.pins.mock import MockFactory

    factory = pin_factory if pin_factory is not None else MockFactory(revision=PI4_REVISION)
    traj = trajectory if trajectory is not None else default_fake_trajectory()
    fakes, sensors = [], []
    for i, s in enumerate(cfg.sensors):
        # counts_per_m is calibrated at the configured resolution; the fake takes it at 1600 cpi.
        fake = FakeAdns3080(traj, counts_per_m=s.counts_per_m * 1600 / s.resolution_cpi, axis=s.axis,
                            sign=s.sign, noise_counts=noise_counts, seed=seed + i)
        sensor = Adns3080(fake, counts_per_m=s.counts_per_m, axis=s.axis, sign=s.sign)
        _configure(sensor, s)
        fakes.append(fake)
        sensors.append(sensor)
    clutches = ClutchBank(cfg.clutch.pins, active_high=cfg.clutch.active_high, pin_factory=factory)
    return Hardware(_channels(cfg, sensors), clutches, sensors, factory, fakes, [f.close for f in fakes])


def build_real(cfg: RobotConfig) -> Hardware:
    """Open the SPI buses and GPIO on the Pi, power up and check every sensor (raises on failure)."""
    from gpiozero import DigitalOutputDevice

    from rimless.firmware.spi import SpidevBus

    closers: list[Callable[[], None]] = []
    sensors: list[Adns3080] = []
    clutches = ClutchBank(cfg.clutch.pins, active_high=cfg.clutch.active_high)  # off first, before anything
    try:
        for s in cfg.sensors:
            bus = SpidevBus(s.spi_bus, s.spi_device, speed_hz=s.spi_speed_hz)
            closers.append(bus.close)
            reset_cb = None
            if s.reset_pin is not None:
                reset_dev = DigitalOutputDevice(s.reset_pin, active_high=True, initial_value=False)
                closers.append(reset_dev.close)
                reset_cb = lambda on, d=reset_dev: d.on() if on else d.off()
            sensor = Adns3080(bus, counts_per_m=s.counts_per_m, axis=s.axis, sign=s.sign, reset=reset_cb)
            _configure(sensor, s)
            sensors.append(sensor)
    except BaseException:
        Hardware([], clutches, [], closers=closers).close()
        raise
    return Hardware(_channels(cfg, sensors), clutches, sensors, None, [], closers)
