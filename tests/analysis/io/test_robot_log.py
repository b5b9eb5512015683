"""The robot's trial log read for the clutch timing (`rimless.analysis.io.robot_log`): against logs written here
by hand (the times are the expectation), a log written by the fake robot over its command channel, and the
report's measured-beside-simulated clutched time (`trials report --robot-log`)."""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.io.robot_log import FORMAT, read_clutch_log
from rimless.errors import InputFileError
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory
from tests.support.firmware_app import gait


def write_log(
    path: Path,
    locks: list[tuple[float, int, float | None]],
    *,
    torn: bool = False,
    disarmed_lock_at: float | None = None,
) -> Path:
    """A trial log with a lock of leg L at t and its release (the next leg's touchdown carrying released_leg)
    at t + clutched (None: never released); samples between the events as the firmware writes them."""
    lines = [{"format": FORMAT, "trial": "hand", "started_epoch_s": 1.8e9}]
    seq = 0
    for t, leg, held in locks:
        lines.append(
            {
                "timestamp": 1.8e9 + t,
                "t_mono_s": t,
                "event": {"channel": 0, "leg": leg, "armed": True, "name": "lock", "code": 2},
            }
        )
        seq += 1
        lines.append(
            {
                "timestamp": 1.8e9 + t + 0.01,
                "t_mono_s": t + 0.01,
                "seq": seq,
                "ch": 0,
                "leg": {
                    "position_m": 0.0,
                    "velocity_m_s": 0.0,
                    "compression_m": 0.008,
                    "phase": 2,
                    "stance": leg,
                    "clutch_mask": 1 << leg,
                },
            }
        )
        if held is not None:
            lines.append(
                {
                    "timestamp": 1.8e9 + t + held,
                    "t_mono_s": t + held,
                    "event": {
                        "channel": 0,
                        "leg": leg + 1,
                        "armed": True,
                        "released_leg": leg,
                        "name": "touchdown",
                        "code": 1,
                    },
                }
            )
    if disarmed_lock_at is not None:
        lines.append({"t_mono_s": disarmed_lock_at, "event": {"leg": 7, "armed": False, "name": "lock"}})
    text = "".join(json.dumps(o) + "\n" for o in lines)
    if torn:
        text += '{"t_mono_s": 99.0, "event": {"na'
    path.write_text(text)
    return path


def test_clutched_times_from_a_hand_written_log(tmp_path):
    locks = [(10.0, 1, 0.3471), (10.4, 2, 0.3502), (10.8, 3, 0.3390), (11.2, 4, None)]
    log = read_clutch_log(write_log(tmp_path / "a.jsonl", locks, torn=True, disarmed_lock_at=11.5))
    assert log.leg.tolist() == [1, 2, 3, 4]  # the disarmed decision moved no clutch
    np.testing.assert_allclose(log.complete(), [0.3471, 0.3502, 0.3390], atol=1e-9)
    assert np.isnan(log.clutched_s[-1])  # still locked when the log ends
    assert any("torn last line" in w for w in log.warnings)


@pytest.mark.parametrize(
    "text, where",
    [
        ('{"format": "something-else/2"}\n', ":1:"),
        (f'{{"format": "{FORMAT}"}}\nnot json\n', ":2:"),
        (
            f'{{"format": "{FORMAT}"}}\n{{"t_mono_s": "x", "event": {{"name": "lock", "leg": 1}}}}\n',
            ":2: field t_mono_s",
        ),
    ],
)
def test_a_bad_log_is_one_error_naming_file_and_line(tmp_path, text, where):
    p = tmp_path / "bad.jsonl"
    p.write_text(text)
    with pytest.raises(InputFileError) as exc:
        read_clutch_log(p)
    assert str(p) + where in str(exc.value) and "\n" not in str(exc.value)


class WheelOnTheRamp:
    """The fake's trajectory (on its virtual clock): at rest until `release()`, then the walk of
    `tests.support.firmware_app.gait`, its first touchdown 0.1 s after the first sample that saw the release."""

    def __init__(self) -> None:
        self.released = threading.Event()
        self.walk: GaitTrajectory | None = None

    def release(self) -> None:
        self.released.set()

    def __call__(self, t: float) -> float:
        if self.walk is None:
            if not self.released.is_set():
                return 0.0
            self.walk = gait(now_s=t)
        return self.walk(t)


@pytest.mark.slow
def test_a_log_written_by_the_fake_robot(tmp_path):
    """The fake walks steps of 0.4 s: each armed lock is released by the next touchdown, so every clutched time is
    one and the same fraction of 0.4 s and locks follow each other by 0.4 s.

    The operator's flow as docs/robot.md gives it: the app runs disarmed; with the wheel at rest on the ramp, the
    operator arms over the signed command link naming the leg on the ground (`rimless robot arm --stance-leg K`,
    the token's HMAC over the connection's nonce: nothing on the LAN without the token can arm), keeps a heartbeat
    running while armed (`rimless robot heartbeat`, the same `Heartbeat`), starts a trial, lets the wheel go, and
    stops the trial and disarms. The wheel is let go once the arm is answered, so the arm lands at rest as it does
    on the ramp (before, the test armed in-process at the app's start, `scenario(arm=True)`, the local `run --arm`,
    which no link-loss timer watches). The fake, its walk and the log's times are on a virtual clock: a loaded
    machine makes the run slower, never different. The test ends on the event, four clutched times in the log (or
    a fault), not after a time."""
    from rimless.firmware.link.heartbeat import Heartbeat
    from rimless.firmware.service.config import CommandsConfig
    from tests.support.firmware_app import TOKEN, Client, config, scenario, wait_for

    def four_locks() -> bool:
        files = list((tmp_path / "trials").glob("*.jsonl"))
        return bool(files) and read_clutch_log(files[0]).complete().size >= 4

    wheel = WheelOnTheRamp()
    # the robot's link-loss timeout is 2 s; 10 s here, as the watchdogs' 1 s in `config`: a loaded test machine
    # paused threads for 0.3-0.6 s (the heartbeat beats every 0.2 s)
    cfg = config(tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN, link_timeout_s=10.0))

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        armed = await c.cmd("arm", 1, stance_leg=cfg.configured_stance_leg())  # at rest: the leg on the ground
        beat = Heartbeat("127.0.0.1", token=TOKEN, port=app.command_port, period_s=0.2, echo=lambda _line: None)
        beating = threading.Thread(target=beat.run, daemon=True)
        beating.start()
        try:
            started = await c.cmd("trial_start", 2, name="clutch")
            wheel.release()
            # a hang guard, not a bound: the log is read as it is flushed (every 0.05 s)
            await wait_for(lambda: bool(app.controller.active_faults) or four_locks(), timeout_s=120.0, every_s=0.05)
            stopped = await c.cmd("trial_stop", 3)
            disarmed = await c.cmd("disarm", 4)
        finally:
            beat.stop()
            await asyncio.to_thread(beating.join, 5.0)
            c.close()
        return armed, started, stopped, disarmed, app.armed_remotely

    _, summary, (armed, started, r, disarmed, remotely), _ = scenario(cfg, script, trajectory=wheel, timeout_s=150.0)
    assert armed["ok"] and started["ok"] and r["ok"] and disarmed["ok"], (armed, started, r, disarmed)
    assert not summary.faults, summary.faults
    assert remotely is False  # armed over the link, disarmed by the operator
    log = read_clutch_log(r["result"]["path"])
    held = log.complete()
    events = [json.loads(ln).get("event") for ln in Path(r["result"]["path"]).read_text().splitlines() if ln.strip()]
    assert held.size >= 3, events
    assert np.all((held > 0.05) & (held < 0.4))
    # The fake samples at 300 Hz on its virtual clock: a lock and a release each land on a sample (3.3 ms apart);
    # 20 ms still tells a constant hold from one that drifts by a step's fraction.
    assert np.ptp(held) < 0.02, held
    np.testing.assert_allclose(np.diff(log.lock_s[: held.size]), 0.4, atol=0.02)
    # armed at rest and the trial started before the wheel was let go: the log holds every touchdown after the arm,
    # and the first lock is in the step of the fourth (the robot's defaults: `confirm_steps` 2, docs/robot.md)
    names = [e["name"] for e in events if e]
    assert names.index("lock") > 0 and names[: names.index("lock")].count("touchdown") == 4, names[:40]


@pytest.mark.slow
def test_report_shows_measured_beside_simulated(tmp_path):
    from rimless.analysis.cli import app
    from rimless.analysis.examples.bundled import data_files

    trial = next(p for p in data_files() if p.name == "SYNTHETIC_er_slope2.0deg_run1.csv")
    log = write_log(tmp_path / "robot.jsonl", [(1.0 + 0.4 * k, k % 8, 0.30 + 0.001 * k) for k in range(5)])
    runner = CliRunner()
    res = runner.invoke(app, ["report", str(trial), "--robot-log", str(log), "--out", str(tmp_path / "rep"), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout[res.stdout.index("{") :])
    c = out["clutch_time_per_step"][trial.name]
    measured = [r["measured_ms"] for r in c["rows"] if r["measured_ms"] is not None]
    np.testing.assert_allclose(measured, [300.0, 301.0, 302.0, 303.0, 304.0], atol=1e-6)
    sim = [r["simulated_ms"] for r in c["rows"] if r["simulated_ms"] is not None]
    comp_periods = out["trials"][0]
    assert sim and all(0.0 < s < 1000.0 for s in sim) and comp_periods["status"] == "ok"
    assert c["difference_ms"] == pytest.approx(c["measured_mean_ms"] - c["simulated_mean_ms"])
    assert 'id="clutch-time"' in (tmp_path / "rep" / "report.html").read_text()
    # several trials need TRIAL=FILE; an unknown trial or a missing log is refused naming the option
    bad = runner.invoke(app, ["report", str(trial), str(trial), "--robot-log", str(log), "--out", str(tmp_path / "r2")])
    assert bad.exit_code == 2 and "--robot-log" in bad.output
    bad = runner.invoke(
        app, ["report", str(trial), "--robot-log", "nope.csv=" + str(log), "--out", str(tmp_path / "r3")]
    )
    assert bad.exit_code == 2 and "is not one of the trials" in bad.output
