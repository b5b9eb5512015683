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


def test_a_stop_signal_after_the_loop_keeps_the_runs_summary(tmp_path, monkeypatch) -> None:
    """Fails before: a signal landing after the firmware's loop had ended (here while the pin histories are
    read) was reported as "before the firmware ran", its summary lost. Now the summary stands and the signal
    sets the exit code (130 for Ctrl-C)."""
    from rimless.firmware.errors import Interrupted
    from rimless.firmware.service import runner

    def signal_now(*args, **kwargs):
        raise Interrupted(signal.SIGINT)

    monkeypatch.setattr(runner, "pin_histories", signal_now)
    cfg = RobotConfig(commands=CommandsConfig(enabled=False), log=LogConfig(dir=str(tmp_path)))
    running = []
    outcome = run_robot(cfg, fake=True, duration_s=0.3, arm=True, on_running=running.append, stance_leg=0)
    assert len(running) == 1  # called once, in the loop
    assert not outcome.before_start and outcome.signal == "SIGINT" and outcome.exit_code == 130
    assert outcome.summary is not None and outcome.summary.stop_reason == "duration" and outcome.summary.samples > 0
