"""The robot's hardware assembled from its configuration: the one place that picks the backend, the real Pi
(spidev + gpiozero's default pin factory) or the fake (register-level ADNS-3080 fakes and gpiozero's
MockFactory), and wires each sensor to its leg detector and health monitor (`Channel`).

It sits in the service layer because it reads `RobotConfig` and builds control objects; the drivers it
uses (`adns3080`, `spi`, `clutch`, `gpio`, `fake_adns3080`) know nothing of either."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from rimless.firmware.clock import Clock, seconds, sleeper
from rimless.firmware.control.controller import Channel
from rimless.firmware.control.detector import LegDetector
from rimless.firmware.control.faults import HealthMonitor
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.drivers.fake_adns3080 import FakeAdns3080, GaitTrajectory
from rimless.firmware.drivers.gpio import (
    GpioChipSelectBus,
    HeartbeatOutput,
    PinLog,
    mock_pin_factory,
    open_clutches,
    output,
    release_pins,
)
from rimless.firmware.service.config import RobotConfig, SensorConfig


@dataclass
class Hardware:
    """Everything the app drives, plus how to close it (clutches last)."""

    channels: list[Channel]
    clutches: ClutchBank
    sensors: list[Adns3080]
    pin_factory: Any = None
    fakes: list[FakeAdns3080] = field(default_factory=list)
    closers: list[Callable[[], None]] = field(default_factory=list)
    heartbeat: HeartbeatOutput | None = None
    clock: Clock | None = None  # the control loop's clock (None: the monotonic clock; the fakes' virtual clock)

    def outputs_off(self) -> None:
        """Heartbeat stopped (low) and every clutch off; tries both whatever the first raises."""
        try:
            if self.heartbeat is not None:
                self.heartbeat.stop()
        finally:
            self.clutches.all_off()

    def close(self) -> None:
        """Heartbeat low, clutches off and released, then the buses and reset pins."""
        try:
            if self.heartbeat is not None:
                with contextlib.suppress(Exception):
                    self.heartbeat.close()
            self.clutches.close()
        finally:
            for close in reversed(self.closers):
                try:
                    close()
                except Exception:  # noqa: BLE001 - close everything we can
                    pass


def _configure(sensor: Adns3080, cfg: SensorConfig) -> None:
    sensor.power_up(pulse_reset=False)  # the RESET lines were pulsed by `_reset_all`
    sensor.set_resolution(cfg.resolution_cpi)
    sensor.set_frame_rate(cfg.frame_rate_hz)
    sensor.mark_configured()  # read back from now on: a brown-out is seen at 400 cpi too
    sensor.clear_motion()


def _reset_all(sensors: list[Adns3080], cfg: RobotConfig) -> None:
    """Wake every sensor (NPD), then pulse each RESET line once (sensors may share one), before any
    sensor is configured."""
    for sensor in sensors:
        sensor.wake()
    done: set[int] = set()
    for sensor, s in zip(sensors, cfg.sensors, strict=True):
        if s.reset_pin not in done:
            sensor.reset_pulse(wake=False)
            done.add(s.reset_pin)


def _channels(cfg: RobotConfig, sensors: list[Adns3080]) -> list[Channel]:
    return [
        Channel(
            sensor, LegDetector(cfg.detector, s.legs, start_index=cfg.clutch.start_leg_index), HealthMonitor(s.health())
        )
        for sensor, s in zip(sensors, cfg.sensors, strict=True)
    ]


def default_fake_trajectory(now_s: float | None = None) -> GaitTrajectory:
    """The synthetic gait of `--fake`: a touchdown every 0.4 s from 0.3 s after `now_s` (default: the monotonic
    clock now), 8 mm compression peaking 60 ms later."""
    start = time.monotonic() if now_s is None else now_s
    return GaitTrajectory(start_s=start + 0.3, step_period_s=0.4, compression_m=0.008, compression_s=0.06)


def build_fake(
    cfg: RobotConfig,
    *,
    trajectory: Callable[[float], float] | None = None,
    trajectories: Sequence[Callable[[float], float]] | None = None,
    pin_factory: Any = None,
    noise_counts: float = 0.3,
    seed: int = 0,
    pin_log: PinLog | None = None,
    clock: Clock | None = None,
) -> Hardware:
    """Fake sensors replaying `trajectory` (or one of `trajectories` per sensor) on `clock` (None: the monotonic
    clock; a `VirtualClock` samples every deadline whatever the load, see `rimless.firmware.clock`), which is
    also the clock of the drivers, the clutches and the app's control loop (`Hardware.clock`); clutches, RESET,
    NPD and GPIO chip selects on a MockFactory (recording every pin change in `pin_log`)."""
    factory = pin_factory if pin_factory is not None else mock_pin_factory(pin_log)
    now_s = time.monotonic if clock is None else seconds(clock)
    traj = trajectory if trajectory is not None else default_fake_trajectory(now_s())
    clock_ns = time.monotonic_ns if clock is None else clock.now_ns
    clutches = ClutchBank(cfg.clutch.pins, active_high=cfg.clutch.active_high, pin_factory=factory, clock_ns=clock_ns)
    fakes: list[FakeAdns3080] = []
    sensors: list[Adns3080] = []
    closers: list[Callable[[], None]] = []
    lines: dict[int, Any] = {}
    on_line: dict[int, list[FakeAdns3080]] = {}  # the fakes whose RESET is wired to each GPIO
    try:
        for i, s in enumerate(cfg.sensors):
            # counts_per_m is calibrated at the configured resolution; the fake takes it at 1600 cpi.
            fake = FakeAdns3080(
                trajectories[i] if trajectories else traj,
                counts_per_m=s.counts_per_m * 1600 / s.resolution_cpi,
                axis=s.axis,
                sign=s.sign,
                noise_counts=noise_counts,
                seed=seed + i,
                speed_hz=s.spi_speed_hz,
                clock=now_s,
            )
            closers.append(fake.close)
            fakes.append(fake)
            reset = _shared_line(lines, s.reset_pin, factory, closers)
            npd = None if s.npd_pin is None else _shared_line(lines, s.npd_pin, factory, closers)
            bus: Any = fake
            if s.cs_pin is not None:
                cs = output(s.cs_pin, active_high=False, pin_factory=factory)
                closers.append(cs.close)
                bus = GpioChipSelectBus(fake, cs)

            def drive_reset(on: bool, dev: Any = reset, pin: int = s.reset_pin) -> None:
                dev.on() if on else dev.off()
                for f in on_line[pin]:
                    f.set_reset(on)

            def drive_npd(on: bool, dev: Any = npd, fake: FakeAdns3080 = fake) -> None:
                dev.on() if on else dev.off()
                fake.set_npd(on)

            on_line.setdefault(s.reset_pin, []).append(fake)
            sensor = Adns3080(
                bus,
                counts_per_m=s.counts_per_m,
                axis=s.axis,
                sign=s.sign,
                reset=drive_reset,
                npd=None if npd is None else drive_npd,
                sleep=time.sleep if clock is None else sleeper(clock),
                clock_ns=clock_ns,
            )
            sensors.append(sensor)
        _reset_all(sensors, cfg)
        for sensor, s in zip(sensors, cfg.sensors, strict=True):
            _configure(sensor, s)
    except BaseException:
        Hardware([], clutches, [], closers=closers).close()
        raise
    hw = Hardware(_channels(cfg, sensors), clutches, sensors, factory, fakes, closers, clock=clock)
    if cfg.clutch.heartbeat_pin:
        try:
            hw.heartbeat = HeartbeatOutput(cfg.clutch.heartbeat_pin, pin_factory=factory)
        except BaseException:
            hw.close()
            raise
    return hw


def _drive(dev: Any) -> Callable[[bool], None]:
    """A pin driver for the sensor: `drive(True)` sets the output device `dev` high, `drive(False)` low."""

    def drive(on: bool) -> None:
        if on:
            dev.on()
        else:
            dev.off()

    return drive


def _shared_line(lines: dict[int, Any], pin: int, factory: Any, closers: list[Callable[[], None]]) -> Any:
    """One output device per GPIO (RESET lines may be shared); active high, starting low."""
    if pin not in lines:
        lines[pin] = output(pin, active_high=True, pin_factory=factory)
        closers.append(lines[pin].close)
    return lines[pin]


def build_real(cfg: RobotConfig) -> Hardware:
    """Open the SPI buses and GPIO on the Pi, pulse RESET, power up and check every sensor.

    Raises `GpioUnavailable` (one line) when this machine has no usable GPIO, `SensorError` when a
    sensor cannot be opened or identified.
    """
    from rimless.firmware.drivers.spi import SpidevBus

    closers: list[Callable[[], None]] = []
    sensors: list[Adns3080] = []
    clutches = open_clutches(cfg.clutch.pins, active_high=cfg.clutch.active_high)  # off first, before anything
    try:
        lines: dict[int, Any] = {}
        buses: dict[tuple[int, int], Any] = {}
        for s in cfg.sensors:
            key = (s.spi_bus, s.spi_device)
            if key not in buses:
                buses[key] = SpidevBus(s.spi_bus, s.spi_device, speed_hz=s.spi_speed_hz, no_cs=s.cs_pin is not None)
                closers.append(buses[key].close)
            bus: Any = buses[key]
            if s.cs_pin is not None:
                cs = output(s.cs_pin, active_high=False)
                closers.append(cs.close)
                bus = GpioChipSelectBus(bus, cs)
            reset_dev = _shared_line(lines, s.reset_pin, None, closers)
            npd_dev = None if s.npd_pin is None else _shared_line(lines, s.npd_pin, None, closers)
            sensor = Adns3080(
                bus,
                counts_per_m=s.counts_per_m,
                axis=s.axis,
                sign=s.sign,
                reset=_drive(reset_dev),
                npd=None if npd_dev is None else _drive(npd_dev),
            )
            sensors.append(sensor)
        _reset_all(sensors, cfg)
        for sensor, s in zip(sensors, cfg.sensors, strict=True):
            _configure(sensor, s)
    except BaseException:
        Hardware([], clutches, [], closers=closers).close()
        raise
    hw = Hardware(_channels(cfg, sensors), clutches, sensors, None, [], closers)
    if cfg.clutch.heartbeat_pin:
        try:
            hw.heartbeat = HeartbeatOutput(cfg.clutch.heartbeat_pin)
        except BaseException:
            hw.close()
            raise
    return hw


@dataclass(frozen=True)
class ReleaseReport:
    """What `release_clutches` did: the pins driven to their off level, and that level."""

    pins: tuple[int, ...]
    off_level: str  # "low" or "high"
    fake_levels: dict[str, str] | None = None  # each mock pin's level history, with `fake`

    def to_json(self) -> dict[str, Any]:
        """The JSON of `rimless robot release --json`."""
        out: dict[str, Any] = {"released_pins": list(self.pins), "level": self.off_level}
        if self.fake_levels is not None:
            out["fake_levels"] = self.fake_levels
        return out


def release_clutches(cfg: RobotConfig, *, fake: bool = False) -> ReleaseReport:
    """Drive every clutch pin of `cfg` to its off level, then give the lines back (on mock pins with `fake`).

    Raises `GpioUnavailable` (one line) when this machine has no usable GPIO.
    """
    factory = mock_pin_factory() if fake else None
    levels = release_pins(cfg.clutch.pins, active_high=cfg.clutch.active_high, pin_factory=factory)
    return ReleaseReport(tuple(cfg.clutch.pins), "low" if cfg.clutch.active_high else "high", levels if fake else None)
