"""The asyncio app over real loopback sockets: commands, telemetry, trial log, watchdogs."""

from __future__ import annotations

import asyncio
import itertools
import json
import socket
import threading
import time

from rimless.firmware.service.config import CommandsConfig, SamplingConfig, TelemetryConfig
from rimless.firmware.service.triallog import read_trial_log
from tests.support.firmware_app import TOKEN, Client, all_off, config, scenario, wait_for


def test_bad_messages_are_refused_and_change_nothing(tmp_path) -> None:
    async def script(app, hw):
        c = await Client.connect(app.command_port)
        before = await c.cmd("status", 1)
        assert before["ok"] and before["result"]["armed"] is False
        replies = [
            await c.raw(b"{not json\n"),
            await c.raw(b"[1, 2]\n"),
            await c.raw(b"\xff\xfe\n"),
            await c.raw(b"x" * 5000 + b"\n"),  # oversized
            await c.cmd("arm", 2, token="wrong"),
            await c.raw(json.dumps({"seq": 3, "cmd": "arm"}).encode() + b"\n"),  # no token
            await c.cmd("arm", 1),  # replayed seq: out of order
            await c.cmd("arm", 4, extra=1),  # unknown argument
            await c.raw(json.dumps({"seq": 5, "cmd": "arm", "args": {}, "mac": "0" * 64, "x": 1}).encode() + b"\n"),
            await c.cmd("fly", 6),
            await c.cmd("set", 7, name="touch_velocity_m_s", value=-3),
            await c.cmd("set", 8, name="no_such_param", value=1),
            await c.cmd("set", 9, name="touch_velocity_m_s"),
            await c.cmd("trial_stop", 10),  # out of order: no trial running
            await c.cmd("trial_start", 11, name="../escape"),
            await c.raw(json.dumps({"token": TOKEN, "seq": 13, "cmd": "arm", "args": {}}).encode() + b"\n"),
        ]
        after = await c.cmd("status", 12)
        c.close()
        return before["result"], replies, after["result"]

    app, summary, (before, replies, after), hw = scenario(config(tmp_path), script)
    assert len(replies) == 16
    for r in replies:
        assert r["ok"] is False and r["error"], r
    assert "garbled" in replies[0]["error"] and "longer than 4096" in replies[3]["error"]
    assert "unauthenticated" in replies[4]["error"] and "unauthenticated" in replies[5]["error"]
    assert "out of order" in replies[6]["error"] and replies[6]["seq"] == 1
    assert "no trial is running" in replies[13]["error"]
    assert after["armed"] is False and after["params"] == before["params"] and after["trial"] is None
    assert after["engaged"] == [] and all_off(hw)
    assert not (tmp_path / "trials").exists() or not list((tmp_path / "trials").glob("*.jsonl"))  # no trial log
    assert summary.error is None


def test_arm_set_trial_disarm_over_tcp(tmp_path) -> None:
    async def script(app, hw):
        c = await Client.connect(app.command_port)
        r_arm = await c.cmd("arm", 1, stance_leg=0)  # the leg the fake walk starts on
        r_set = await c.cmd("set", 2, name="touch_velocity_m_s", value=0.06)
        r_start = await c.cmd("trial_start", 3, name="slope1")
        r_again = await c.cmd("trial_start", 4, name="slope2")
        # until the trial has 250 samples and a lock: a condition, not a delay (a loaded machine samples late)
        s0, locked = app.controller.samples, []
        await wait_for(
            lambda: (
                (locked.append(1) if hw.clutches.engaged() else None, locked)[1] and app.controller.samples - s0 > 250
            )
        )
        r_status = await c.cmd("status", 5)
        r_stop = await c.cmd("trial_stop", 6)
        r_disarm = await c.cmd("disarm", 7)
        c.close()
        return r_arm, r_set, r_start, r_again, r_status, r_stop, r_disarm

    app, summary, rs, hw = scenario(config(tmp_path), script)
    r_arm, r_set, r_start, r_again, r_status, r_stop, r_disarm = rs
    assert r_arm["ok"] and r_arm["result"]["armed"] is True
    assert r_set["result"] == {"name": "touch_velocity_m_s", "value": 0.06}
    assert r_start["ok"] and "slope1" in r_start["result"]["path"]
    assert not r_again["ok"] and "already running" in r_again["error"]
    assert r_status["result"]["params"]["touch_velocity_m_s"] == 0.06
    assert r_disarm["ok"] and r_disarm["result"]["armed"] is False
    assert all_off(hw)
    # The trial log: every sample in order, events included, header first.
    log = read_trial_log(r_stop["result"]["path"])
    assert log.header["trial"] == "slope1" and not log.torn_tail
    seqs = [s["seq"] for s in log.samples]
    assert len(seqs) > 200 and seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    names = [e["event"]["name"] for e in log.events]
    assert names[0] == "trial_start" and names[-1] == "trial_stop"
    assert "lock" in names and "touchdown" in names
    assert r_stop["result"]["lines"] == 1 + len(log.samples) + len(log.events)


def test_telemetry_reaches_a_udp_receiver_in_plotjuggler_shape(tmp_path) -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    port = rx.getsockname()[1]
    cfg = config(tmp_path, telemetry=TelemetryConfig(host="127.0.0.1", port=port, max_datagram_bytes=1000))

    datagrams = []

    async def script(app, hw):
        rx.setblocking(False)
        deadline = time.monotonic() + 50  # a hang guard
        # read while the app runs, so the socket buffer never overflows, until a lock was sent (and 1 s at least)
        for k in itertools.count():
            await asyncio.sleep(0.01)
            while True:
                try:
                    datagrams.append(rx.recv(65536))
                except BlockingIOError:
                    break
            if k >= 100 and any(b'"name":"lock"' in d for d in datagrams) or time.monotonic() > deadline:
                break

    app, summary, _, hw = scenario(cfg, script, arm=True)

    def sample_count() -> int:
        return sum(1 for d in datagrams for o in json.loads(d) if "leg" in o)

    # The run has stopped and says how many samples it took; the app flushes its telemetry before it returns, but
    # loopback may hand a datagram to the receiver after sendto returned (this VM lags): read until every sample is
    # in (a hang guard on each read, not a bound), then whatever else is queued.
    rx.settimeout(30.0)
    while sample_count() < summary.samples:
        try:
            datagrams.append(rx.recv(65536))
        except TimeoutError:
            break
    rx.setblocking(False)
    while True:
        try:
            datagrams.append(rx.recv(65536))
        except BlockingIOError:
            break
    rx.close()
    assert datagrams and all(len(d) <= 1000 for d in datagrams)
    objs = [o for d in datagrams for o in json.loads(d)]
    samples = [o for o in objs if "leg" in o]
    events = [o for o in objs if "event" in o]
    assert len(samples) == summary.samples  # nothing lost on loopback, decimate = 1
    now = time.time()
    for o in samples:
        assert isinstance(o["timestamp"], float) and abs(o["timestamp"] - now) < 60
        assert isinstance(o["leg"]["velocity_m_s"], float) and isinstance(o["sensor"]["squal"], int)
    assert all(isinstance(e["event"]["code"], int) for e in events)
    assert any(e["event"]["name"] == "lock" for e in events)


def test_dead_telemetry_receiver_costs_the_loop_nothing(tmp_path) -> None:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    dead_port = probe.getsockname()[1]
    probe.close()  # nobody listens there: every send gets ICMP port-unreachable
    cfg = config(
        tmp_path,
        telemetry=TelemetryConfig(host="127.0.0.1", port=dead_port, period_s=0.005),
        sampling=SamplingConfig(rate_hz=500.0),
    )

    async def script(app, hw):
        await asyncio.sleep(1.0)
        await wait_for(lambda: app.controller.clutch_commands >= 2)  # a lock and its release

    app, summary, _, hw = scenario(cfg, script, arm=True)
    assert app.telemetry is not None
    assert app.telemetry.dropped_datagrams > 0  # the errors happened...
    assert summary.error is None and summary.faults == []  # ...and were absorbed
    assert summary.clutch_commands >= 2  # the control loop kept working meanwhile
    assert all_off(hw)


def test_link_loss_disarms(tmp_path) -> None:
    """The link-loss timer runs on a virtual clock (`app.link_clock`) moved by the test: 12 pings 0.9 s apart
    (each inside the 1 s link timeout, 10.8 s in all; the watchdog thread's link check runs a whole round after
    each) keep the remote arm; then 1.1 s with no command disarms, every clutch off. Nothing depends on how fast
    the machine delivers a ping."""
    from tests.support.firmware_app import TurnClock

    cfg = config(tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN, link_timeout_s=1.0))
    clock = TurnClock()  # never released: it moves only by `advance`

    async def script(app, hw):
        app.link_clock = clock
        c = await Client.connect(app.command_port)
        assert (await c.cmd("arm", 1))["ok"]
        for seq in range(2, 14):  # heartbeats keep it armed
            clock.advance(0.9)
            assert (await c.cmd("ping", seq))["ok"]
            rounds = app.watchdog.rounds  # a whole round of the link check (the watchdog thread's) after the ping
            await wait_for(lambda rounds=rounds: app.watchdog.rounds >= rounds + 2)
        armed_while_pinging = app.controller.armed
        clock.advance(1.1)  # then silence, longer than the link timeout: disarmed (by the watchdog thread)
        await wait_for(lambda: not app.controller.armed)
        c.close()
        return armed_while_pinging

    app, summary, armed_while_pinging, hw = scenario(cfg, script)
    assert armed_while_pinging is True
    assert "link_lost" in summary.faults
    assert all_off(hw)


class StallingSensor:
    """Wraps a sensor; once a clutch is engaged, blocks one read until `until()` holds (at most `stall_s`, a hang
    guard), or raises `exc` there. `stuck` is True while that read blocks."""

    def __init__(self, inner, clutches, stall_s: float, exc: Exception | None = None, until=None) -> None:
        self.inner, self.clutches, self.stall_s, self.exc = inner, clutches, stall_s, exc
        self.until = until or (lambda: False)
        self.fired = False
        self.stuck = False

    def read_motion(self):
        if not self.fired and self.clutches.engaged():
            self.fired = True
            if self.exc is not None:
                raise self.exc
            self.stuck = True
            end = time.monotonic() + self.stall_s
            while not self.until() and time.monotonic() < end:
                time.sleep(0.005)
            self.stuck = False
        return self.inner.read_motion()

    def verify_id(self):
        return self.inner.verify_id()


def test_stalled_sampler_trips_the_watchdog(tmp_path) -> None:
    """On events: the sampler stays stuck in a read until the test has seen the watchdog's fault and read the
    pins (all off while it was still stuck), however late a loaded machine runs the watchdog thread."""
    wrappers = []
    seen = threading.Event()

    def hook(hw):
        for ch in hw.channels:
            ch.sensor = StallingSensor(ch.sensor, hw.clutches, stall_s=120.0, until=seen.is_set)
            wrappers.append(ch.sensor)

    async def script(app, hw):
        try:
            await wait_for(lambda: "sensor_stalled" in app.summary.faults)
            return [hw.pin_factory.pin(p).state for p in hw.clutches.pins], wrappers[0].stuck
        finally:
            seen.set()

    # both watchdogs at 2 s: the stall lasts until the trip (an event), so a longer deadline proves the same, and a
    # machine at load 10-20 no longer trips them before the engage (at 0.3 s / 0.25 s it did, after 0.26-0.30 s)
    sampling = SamplingConfig(stall_timeout_s=2.0, loop_stall_s=2.0)
    app, summary, (states_during_stall, still_stuck), hw = scenario(
        config(tmp_path, sampling=sampling), script, arm=True, hw_hook=hook
    )
    assert wrappers[0].fired and still_stuck
    assert states_during_stall == [False] * 8  # off while the sampler was still stuck
    assert all_off(hw)


def test_exception_in_the_control_path_stops_the_app_safely(tmp_path) -> None:
    def hook(hw):
        for ch in hw.channels:
            ch.sensor = StallingSensor(ch.sensor, hw.clutches, 0, exc=RuntimeError("driver bug"))

    async def script(app, hw):
        await wait_for(lambda: bool(app.summary.stop_reason))  # the app stops by itself

    app, summary, _, hw = scenario(config(tmp_path), script, arm=True, hw_hook=hook)
    assert summary.error is not None and "driver bug" in summary.error
    assert "exception" in summary.faults
    assert summary.stop_reason == "error"
    engaged_once = [p for p in hw.clutches.pins if any(s.state for s in hw.pin_factory.pin(p).states)]
    assert engaged_once  # it really was on when the error struck...
    assert all_off(hw)  # ...and is off now
