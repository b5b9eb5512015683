"""`robot run` as a library call: the exit code follows the shell's convention, the fake run ends with
every clutch released."""

from __future__ import annotations

import signal

import pytest

from rimless.firmware.service.app import RunSummary
from rimless.firmware.service.config import CommandsConfig, LogConfig, RobotConfig, TelemetryConfig
from rimless.firmware.service.runner import RunOutcome, run_robot, with_telemetry


@pytest.mark.parametrize(
    ("outcome", "code"),
    [
        (RunOutcome(True, RunSummary(stop_reason="duration")), 0),
        (RunOutcome(True, RunSummary(stop_reason="SIGTERM"), "SIGTERM"), 0),  # a service stop
        (RunOutcome(True, RunSummary(stop_reason="SIGINT"), "SIGINT"), 128 + signal.SIGINT),
        (RunOutcome(True, RunSummary(stop_reason="SIGHUP"), "SIGHUP"), 128 + signal.SIGHUP),
        (RunOutcome(True, RunSummary(stop_reason="error", error="boom"), "SIGINT"), 1),  # the fault wins
        (RunOutcome(True, None, "SIGTERM", before_start=True), 0),
        (RunOutcome(True, None, "SIGQUIT", before_start=True), 128 + signal.SIGQUIT),
    ],
)
def test_exit_code_is_the_shell_convention(outcome, code) -> None:
    assert outcome.exit_code == code


def test_with_telemetry_appends_destinations() -> None:
    cfg = RobotConfig(telemetry=TelemetryConfig(destinations=("a:1",)))
    assert with_telemetry(cfg, ["b:2"]).telemetry.destinations == ("a:1", "b:2")
    assert with_telemetry(cfg, []) is cfg


def test_fake_run_for_a_moment_ends_with_every_clutch_off(tmp_path) -> None:
    cfg = RobotConfig(commands=CommandsConfig(enabled=False), log=LogConfig(dir=str(tmp_path)))
    started = []
    outcome = run_robot(cfg, fake=True, duration_s=0.5, arm=True, on_start=started.append, stance_leg=0)
    assert len(started) == 1 and outcome.exit_code == 0 and outcome.summary is not None
    assert outcome.summary.stop_reason == "duration" and outcome.summary.samples > 0
    levels = dict(item.split("=") for item in outcome.fake_pins.split())
    assert set(levels) == {f"GPIO{p}" for p in cfg.clutch.pins}
    assert all(h.endswith("0") for h in levels.values()), levels
