"""The shutdown path runs to the end whatever fails in it, logging never blocks control, and one
sensor per leg (GPIO chip selects) clutches the leg it measures."""

from __future__ import annotations

import asyncio
import dataclasses
import io
import logging
import socket
import threading
import time

import pytest

from rimless.firmware.service.config import ConfigError, RobotConfig, SensorConfig, TelemetryConfig, config_from_dict
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory
from rimless.firmware.service.logsetup import NonBlockingLog
from rimless.firmware.link.telemetry import TelemetrySender
from tests.firmware.test_app import Client, all_off, config, scenario


def released(hw) -> bool:
    """Every clutch pin driven low, then given back (gpiozero closes a pin as an input)."""
    pins = [hw.pin_factory.pin(p) for p in hw.clutches.pins]
    return all(p.state is False and p.function == "input" for p in pins) and hw.clutches._devices == []


def test_an_exception_in_telemetry_still_closes_the_hardware(tmp_path, monkeypatch) -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    cfg = config(tmp_path, telemetry=TelemetryConfig(host="127.0.0.1", port=rx.getsockname()[1]))

    def broken(self, records):  # noqa: ANN001
        raise RuntimeError("encoder bug")

    monkeypatch.setattr(TelemetrySender, "send", broken)

    async def script(app, hw):
        await asyncio.sleep(0.8)
        return bool(hw.clutches.engaged()) or any(
            any(s.state for s in hw.pin_factory.pin(p).states) for p in hw.clutches.pins)

    app, summary, was_on, hw = scenario(config(tmp_path, telemetry=cfg.telemetry), script, arm=True)
    rx.close()
    assert was_on
    assert released(hw)
    assert summary.error is not None and "telemetry" in summary.error and "encoder bug" in summary.error


def test_an_open_command_connection_at_shutdown_logs_nothing(tmp_path, caplog, capfd) -> None:
    caplog.set_level(logging.DEBUG)

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        assert (await c.cmd("status", 1))["ok"]
        idle = await asyncio.open_connection("127.0.0.1", app.command_port)  # never says a word
        return c, idle

    app, summary, _conns, hw = scenario(config(tmp_path), script)
    err = capfd.readouterr().err
    assert "CancelledError" not in err and "Traceback" not in err
    assert not [r for r in caplog.records if r.exc_info or "CancelledError" in r.getMessage()]
    assert summary.error is None and released(hw)


class BlockedStream(io.TextIOBase):
    """stderr that nobody reads: every write blocks until `release` is set."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.writes = 0

    def write(self, s: str) -> int:
        self.release.wait(30)
        self.writes += 1
        return len(s)


def test_a_blocked_stderr_does_not_freeze_control(tmp_path) -> None:
    stream = BlockedStream()
    logger = logging.getLogger("rimless.robot")

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        t0 = time.perf_counter()
        for k in range(2000):  # far more than the queue holds
            logger.warning("flood %d", k)
        flood_s = time.perf_counter() - t0
        replies = []
        for seq in range(1, 6):
            t0 = time.perf_counter()
            r = await c.cmd("status", seq)
            replies.append((r["ok"], time.perf_counter() - t0))
            await asyncio.sleep(0.05)
        c.close()
        return flood_s, replies, app.controller.samples

    log = NonBlockingLog(stream, queue_len=100).start()
    try:
        app, summary, (flood_s, replies, samples), hw = scenario(config(tmp_path), script, arm=True)
    finally:
        stream.release.set()
        log.stop()
    assert flood_s < 0.5  # 2000 log calls returned at once
    assert all(ok and dt < 0.5 for ok, dt in replies), replies
    assert log.dropped >= 1800 and summary.samples > 50 and all_off(hw)


def leg_view(traj: GaitTrajectory, leg: int, legs: int = 8):
    """What the sensor of `leg` sees: only the stances of that leg (every `legs`-th step)."""

    def f(t: float) -> float:
        if t < traj.start_s:
            return 0.0
        k = int((t - traj.start_s) // traj.step_period_s)
        return traj(t) if k % legs == leg else 0.0

    return f


CS_PINS = (2, 3, 4, 5, 6, 12, 13, 19)


def per_leg_config(tmp_path) -> RobotConfig:
    base = config(tmp_path)
    sensors = tuple(SensorConfig(spi_device=0, cs_pin=cs, legs=(k,)) for k, cs in enumerate(CS_PINS))
    return dataclasses.replace(base, sensors=sensors)


def test_one_sensor_per_leg_with_gpio_chip_selects_clutches_the_measured_leg(tmp_path) -> None:
    from rimless.firmware.drivers.hardware import build_fake

    cfg = per_leg_config(tmp_path)
    traj = GaitTrajectory(start_s=time.monotonic() + 0.15, step_period_s=0.3, compression_m=0.008, compression_s=0.06)
    hw = build_fake(cfg, trajectories=[leg_view(traj, k) for k in range(8)])
    from rimless.firmware.service.app import RobotApp

    async def main():
        app = RobotApp(cfg, hw)
        # Stop between leg 3's lock and leg 4's touchdown.
        return await app.run(duration_s=traj.touchdown_s(4) - 0.1 - time.monotonic(), arm=True, handle_signals=False)

    summary = asyncio.run(main())
    assert summary.faults == [] and summary.error is None
    hist = {k: "".join("1" if s.state else "0" for s in hw.pin_factory.pin(p).states)
            for k, p in enumerate(cfg.clutch.pins)}
    for k in range(4):  # legs 0..3 stanced once each, released at the next leg's touchdown (leg 3: at stop)
        assert hist[k] == "010", hist
    assert all(hist[k] == "0" for k in range(4, 8)), hist
    for cs in CS_PINS:  # every chip select idles high and was pulled low for transfers
        states = [s.state for s in hw.pin_factory.pin(cs).states]
        assert states[-1] is True and False in states[1:]


def test_clutch_pins_off_spi_lines_and_off_boot_pull_ups_without_a_reason() -> None:
    with pytest.raises(ConfigError, match="GPIO9 is an SPI line"):
        config_from_dict({"clutch": {"pins": [9, 27]}, "sensor": {"legs": [0, 1]}})
    with pytest.raises(ConfigError, match="GPIO4 is pulled up at power-on"):
        config_from_dict({"clutch": {"pins": [4, 27]}, "sensor": {"legs": [0, 1]}})
    ok = config_from_dict({"clutch": {"pins": [4, 27], "boot_pull_up_reason": "1k pull-down on the module input"},
                           "sensor": {"legs": [0, 1]}})
    assert ok.clutch.pins == (4, 27)
    with pytest.raises(ConfigError, match="GPIO7 is an SPI line"):
        config_from_dict({"clutch": {"pins": [7, 27], "boot_pull_up_reason": "x"}, "sensor": {"legs": [0, 1]}})
    with pytest.raises(ConfigError, match="HAT ID EEPROM"):
        config_from_dict({"clutch": {"pins": [0, 27]}, "sensor": {"legs": [0, 1]}})
    with pytest.raises(ConfigError, match="GPIO19 is an SPI line"):  # SPI1 in use: its lines too
        config_from_dict({"clutch": {"pins": [19, 27]}, "sensor": {"spi_bus": 1, "legs": [0, 1]}})
    with pytest.raises(ConfigError, match="reset_pin GPIO17 is also a clutch pin"):
        config_from_dict({"sensor": {"reset_pin": 17}})
    with pytest.raises(ConfigError, match="cs_pin GPIO5 is also"):
        config_from_dict({"sensor": [{"legs": [0], "cs_pin": 5}, {"legs": [1], "cs_pin": 5}]})


def test_sensors_sharing_a_reset_line_each_get_npd_and_one_pulse(tmp_path) -> None:
    from rimless.firmware.drivers.hardware import build_fake

    base = config(tmp_path)
    sensors = (SensorConfig(spi_device=0, legs=(0, 1, 2, 3), npd_pin=5),
               SensorConfig(spi_device=1, legs=(4, 5, 6, 7), npd_pin=6))
    hw = build_fake(dataclasses.replace(base, sensors=sensors))
    try:
        assert [f.resets for f in hw.fakes] == [1, 1] and all(f.powered for f in hw.fakes)
        reset = [s.state for s in hw.pin_factory.pin(25).states]
        assert reset == [False, True, False]  # one pulse on the shared line
        assert all(hw.pin_factory.pin(p).state is True for p in (5, 6))
        assert [s.verify_id() for s in hw.sensors] == [1, 1]
    finally:
        hw.close()
