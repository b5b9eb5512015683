"""The hardware self-test of `rimless robot check`: sensor IDs, SQUAL, frame rate and resolution, and a
click of each clutch, with every clutch released on any fault or stop signal.

Times in seconds. The result is a `SelfTestReport`; the command only prints it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.firmware.drivers.gpio import pin_histories
from rimless.firmware.errors import CommandError, Interrupted, SensorError
from rimless.firmware.service.config import RobotConfig, load_config
from rimless.firmware.service.hardware import Hardware, build_fake, build_real
from rimless.firmware.service.safety import stop_on_signals

CLICK_ON_S = 0.2  # each clutch is engaged this long
CLICK_GAP_S = 0.1  # pause after each release
SQUAL_READS = 5  # the best of this many SQUAL reads is reported


@dataclass
class SensorCheck:
    """One sensor: identified (Product_ID and its inverse matched), its revision, best SQUAL, frame rate, cpi."""

    index: int
    revision_id: int
    squal: int
    frame_rate_hz: float
    resolution_cpi: int

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "product_id_ok": True,
            "revision_id": self.revision_id,
            "squal": self.squal,
            "frame_rate_hz": self.frame_rate_hz,
            "resolution_cpi": self.resolution_cpi,
        }


@dataclass
class ClutchClick:
    """One clutch engaged for `CLICK_ON_S`, then released."""

    leg: int
    pin: int

    def to_json(self) -> dict[str, Any]:
        return {"leg": self.leg, "pin": self.pin, "clicked": True}


@dataclass
class SelfTestReport:
    """What `self_test` found. `interrupted` names the stop signal that ended it early (then `exit_code` is
    128 + its number); `fake_pins` holds the mock pins' level histories after such a stop with `fake`."""

    sensors: list[SensorCheck] = field(default_factory=list)
    clutches: list[ClutchClick] = field(default_factory=list)
    interrupted: str | None = None
    exit_code: int = 0
    fake_pins: str = ""

    def to_json(self) -> dict[str, Any]:
        """The JSON of `rimless robot check --json`."""
        return {"sensors": [s.to_json() for s in self.sensors], "clutches": [c.to_json() for c in self.clutches]}


def self_test(
    config: RobotConfig | Path | None = None,
    *,
    fake: bool = False,
    click: bool = True,
    on_click: Callable[[int, int], None] | None = None,
    click_s: float = CLICK_ON_S,
) -> SelfTestReport:
    """Open the hardware of `config` (a `RobotConfig`, or the robot.toml to load; None: the defaults), the
    fakes with `fake`; identify and read every sensor, and with `click` engage each clutch for `click_s`
    seconds (`on_click(leg, pin)` is called once it is engaged).

    Any stop signal (SIGINT, SIGTERM, SIGHUP, SIGQUIT) releases every clutch at once and ends the test:
    the report then says which signal. Raises `CommandError` ("sensor check failed: ...") when a sensor
    cannot be opened or read; the hardware is closed (clutches off) on every path.
    """
    state: dict[str, Hardware] = {}
    report = SelfTestReport()

    def release_now() -> None:
        hw = state.get("hw")
        if hw is not None:
            hw.clutches.all_off()

    try:
        with stop_on_signals(release_now):
            cfg = config if isinstance(config, RobotConfig) else load_config(config)
            try:
                hw = build_fake(cfg) if fake else build_real(cfg)
            except SensorError as err:
                raise CommandError(f"sensor check failed: {err}") from None
            state["hw"] = hw
            try:
                _check(hw, report, click, on_click, click_s)
            except SensorError as err:
                raise CommandError(f"sensor check failed: {err}") from None
            finally:
                hw.close()
    except Interrupted as sig:
        opened = state.get("hw")
        if opened is not None:
            opened.close()  # idempotent: the finally above already ran
            if fake and opened.pin_factory is not None:
                report.fake_pins = pin_histories(opened.pin_factory, opened.clutches.pins)
        report.interrupted, report.exit_code = sig.name, sig.exit_code
    return report


def _check(
    hw: Hardware,
    report: SelfTestReport,
    click: bool,
    on_click: Callable[[int, int], None] | None,
    click_s: float = CLICK_ON_S,
) -> None:
    for i, sensor in enumerate(hw.sensors):
        rev = sensor.verify_id()
        squal = [sensor.squal() for _ in range(SQUAL_READS)]
        report.sensors.append(
            SensorCheck(i, rev, max(squal), round(sensor.frame_rate_hz(), 1), int(sensor.resolution()))
        )
    if not click:
        return
    for leg, pin in enumerate(hw.clutches.pins):
        hw.clutches.engage(leg)
        try:
            if on_click is not None:
                on_click(leg, pin)  # engaged now: a signal from here on finds this clutch on
            time.sleep(click_s)
        finally:
            hw.clutches.release(leg)
        time.sleep(CLICK_GAP_S)
        report.clutches.append(ClutchClick(leg, pin))
