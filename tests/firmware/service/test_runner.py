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


@pytest.mark.parametrize("where", ["making the loop", "setting it up"])
def test_a_stop_signal_while_the_loop_is_made_leaves_no_loop_unclosed(tmp_path, monkeypatch, where) -> None:
    """Fails before (while it is made): a Ctrl-C landing while `asyncio.run` made its event loop left that loop
    unclosed; its ``__del__`` closed it later wherever the garbage collector ran (a traceback on the command's
    stderr, seen once). A real SIGINT is raised in the process at that moment (`signal.raise_signal` runs the
    Python handler before it returns); the run ends as stopped before the firmware ran, the loop closed."""
    import asyncio

    made = []
    real_new_loop = asyncio.new_event_loop

    def new_loop_then_signal():
        loop = real_new_loop()
        made.append(loop)
        if where == "making the loop":
            signal.raise_signal(signal.SIGINT)
        return loop

    real_runner = asyncio.Runner

    class RunnerSignalledOnEntry(real_runner):  # the signal once the loop exists, before the run starts
        def __enter__(self):
            runner = super().__enter__()
            if where == "setting it up":
                signal.raise_signal(signal.SIGINT)
            return runner

    monkeypatch.setattr(asyncio, "new_event_loop", new_loop_then_signal)
    monkeypatch.setattr(asyncio.events, "new_event_loop", new_loop_then_signal)  # what asyncio.run calls
    monkeypatch.setattr(asyncio, "Runner", RunnerSignalledOnEntry)
    monkeypatch.setattr(asyncio.runners, "Runner", RunnerSignalledOnEntry)
    cfg = RobotConfig(commands=CommandsConfig(enabled=False), log=LogConfig(dir=str(tmp_path)))
    outcome = run_robot(cfg, fake=True, duration_s=5.0, arm=True, stance_leg=0)
    assert outcome.before_start and outcome.signal == "SIGINT" and outcome.exit_code == 130
    assert len(made) == 1 and made[0].is_closed()
