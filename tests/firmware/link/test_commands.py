"""The command channel under abuse, on the loopback only: idle-connection floods, replays, hostile
JSON, log floods, weak tokens, and the heartbeat that keeps a remotely armed robot armed."""

from __future__ import annotations

import asyncio
import json
import logging
import os
import resource
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from rimless.firmware.errors import RobotUnreachable
from rimless.firmware.link.commands import RateLimitedLog
from rimless.firmware.link.heartbeat import Heartbeat
from rimless.firmware.link.remote import RobotLink, send_command
from rimless.firmware.service.config import CommandsConfig
from tests.support.firmware_app import TOKEN, Client, all_off, config, scenario, wait_for

RIMLESS = [str(Path(sys.executable).with_name("rimless"))]


def test_replayed_arm_is_rejected_on_a_new_connection_and_on_the_same_one(tmp_path) -> None:
    async def script(app, hw):
        c1 = await Client.connect(app.command_port)
        captured = c1.sign(1, "arm", {})
        r1 = await c1.raw(captured)
        await c1.cmd("disarm", 2)
        replay_same = await c1.raw(captured)  # same connection: seq goes backwards
        c2 = await Client.connect(app.command_port)
        replay_new = await c2.raw(captured)  # new connection: another nonce, the mac fails
        clear = await c2.raw(json.dumps({"token": TOKEN, "seq": 5, "cmd": "arm", "args": {}}).encode() + b"\n")
        status = await c2.cmd("status", 6)
        c1.close()
        c2.close()
        return r1, replay_same, replay_new, clear, status, c1.nonce != c2.nonce

    app, summary, (r1, same, new, clear, status, fresh), hw = scenario(config(tmp_path), script)
    assert r1["ok"] and fresh
    assert not same["ok"] and "out of order" in same["error"]
    assert not new["ok"] and "bad mac" in new["error"]
    assert not clear["ok"] and "clear-text" in clear["error"]
    assert status["result"]["armed"] is False and all_off(hw)


def test_hostile_json_gets_one_line_refusals_without_tracebacks(tmp_path, caplog) -> None:
    lines = [
        b'{"seq": 1, "cmd": "arm", "args": {"x": "\\ud800"}, "mac": "00"}',  # lone surrogate
        b"[" * 2000 + b"]" * 2000,  # deep nesting
        b'{"seq": 2, "cmd": "set", "args": {"name": "' + b"[" * 1500 + b'"}, "mac": "\\udfff"}',
        b'{"a":' * 1000 + b"1" + b"}" * 1000,
        b'{"seq": 3, "cmd": "arm", "args": {}, "mac": "\\u00e9\\u00e9"}',  # non-ASCII mac
    ]
    caplog.set_level(logging.DEBUG)

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        replies = [await c.raw(line + b"\n") for line in lines]
        ok = await c.cmd("status", 10)
        c.close()
        return replies, ok

    app, summary, (replies, ok), hw = scenario(
        config(tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN, max_message_bytes=8192)), script
    )
    for r in replies:
        assert r["ok"] is False and "\n" not in r["error"], r
    assert "surrogate" in replies[0]["error"] and "nested" in replies[1]["error"] and "nested" in replies[3]["error"]
    assert ok["ok"] and summary.error is None
    assert not [rec for rec in caplog.records if rec.exc_info or "Traceback" in rec.getMessage()]


def test_rejection_logs_are_rate_limited() -> None:
    t = [0.0]
    logger = logging.getLogger("test.ratelimit")
    records: list[str] = []

    class H(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record.getMessage())

    logger.addHandler(H())
    logger.propagate = False
    rl = RateLimitedLog(logger, per_s=5.0, clock=lambda: t[0])
    for k in range(10_000):  # 10 000 bad lines in 10 s
        t[0] = k * 1e-3
        rl.warning("refused %d", k)
    assert 50 <= len(records) <= 56  # 5 per second plus the initial burst
    assert "similar lines suppressed" in records[-1]


def test_flood_of_garbage_logs_a_bounded_number_of_lines(tmp_path, caplog) -> None:
    caplog.set_level(logging.WARNING, logger="rimless.robot.commands")

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        c.writer.write(b"garbage\n" * 3000)
        await c.writer.drain()
        for _ in range(3000):
            await asyncio.wait_for(c.reader.readline(), 5)
        ok = await c.cmd("status", 1)
        c.close()
        return ok

    app, summary, ok, hw = scenario(config(tmp_path), script)
    assert ok["ok"]
    logged = [r for r in caplog.records if r.name == "rimless.robot.commands"]
    assert 1 <= len(logged) <= 40, len(logged)


def test_unauthenticated_connections_time_out_and_the_cap_evicts_them(tmp_path) -> None:
    # 1 s to authenticate: the operator's client does it at once even on a loaded machine
    cfg = config(
        tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN, max_connections=4, auth_timeout_s=1.0)
    )

    async def script(app, hw):
        idle = [await asyncio.open_connection("127.0.0.1", app.command_port) for _ in range(10)]
        await asyncio.sleep(0.05)
        at_cap = app.server.connections
        c = await Client.connect(app.command_port)  # gets in although the cap is reached
        ok = await c.cmd("status", 1)
        # the idle ones never authenticated: each is closed (EOF) within auth_timeout_s
        eof = [await asyncio.wait_for(r.read(), 10) for r, _ in idle]
        still = await c.cmd("ping", 2)  # the authenticated one stays
        for _, w in idle:
            w.close()
        c.close()
        return at_cap, ok, eof, still, app.server.evicted

    app, summary, (at_cap, ok, eof, still, evicted), hw = scenario(cfg, script)
    assert at_cap <= 4 and ok["ok"] and still["ok"] and evicted >= 6
    assert all(data.startswith(b'{"hello"') or data == b"" for data in eof)


def _open_idle(port: int, n: int, out: list[socket.socket], threads: int = 100) -> None:
    """`n` idle connections from another host than the operator's (127.0.0.2: the per-source limit refuses
    most of them, which is the point), opened by `threads` threads at once: a connect the full listen backlog
    dropped waits for the kernel's SYN retry (1 s), so one thread took 11 s for 1100."""

    def open_some(count: int) -> None:
        for _ in range(count):
            s = socket.socket()
            s.settimeout(5)
            s.bind(("127.0.0.2", 0))
            try:
                s.connect(("127.0.0.1", port))
            except OSError:
                s.close()
                continue
            out.append(s)

    openers = [threading.Thread(target=open_some, args=(n // threads + (k < n % threads),)) for k in range(threads)]
    for t in openers:
        t.start()
    for t in openers:
        t.join()


def test_1100_idle_connections_do_not_delay_disarm(tmp_path) -> None:
    """The robot runs as on a Pi (1024 open files at most) in its own process; 1100 idle loopback
    connections are opened, then an operator connects and disarms."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard < 2400:
        pytest.skip("needs 2400 open files in the test process")
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, 2400), hard))
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    cfg = tmp_path / "robot.toml"
    # idle connections get 60 s to authenticate: a disarm answered while they are still held did not wait for them
    cfg.write_text(
        f'[commands]\nbind = "127.0.0.1"\nport = {port}\nlink_timeout_s = 0.0\nauth_timeout_s = 60.0\n'
        f'[log]\ndir = "{tmp_path}"\n'
    )
    env = {**os.environ, "RIMLESS_TOKEN": TOKEN}

    def pi_limits() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (1024, 1024))

    proc = subprocess.Popen(
        [*RIMLESS, "robot", "run", "--fake", "--arm", "--stance-leg", "0", "--config", str(cfg)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        text=True,
        preexec_fn=pi_limits,
    )
    idle: list[socket.socket] = []
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                assert send_command("127.0.0.1", "status", token=TOKEN, port=port, timeout_s=1)["armed"]
                break
            except RobotUnreachable:
                assert time.monotonic() < deadline and proc.poll() is None
                time.sleep(0.05)
        opener = threading.Thread(target=_open_idle, args=(port, 1100, idle))
        opener.start()
        opener.join(60)
        assert len(idle) >= 1000  # connected (the robot may have closed most of them at once)
        result = send_command("127.0.0.1", "disarm", token=TOKEN, port=port, timeout_s=30)
        status = send_command("127.0.0.1", "status", token=TOKEN, port=port, timeout_s=30)
    finally:
        for s in idle:
            s.close()
        proc.terminate()
        _, err = proc.communicate(timeout=20)
    assert result["armed"] is False and status["engaged"] == []
    # answered while idle connections still held slots (none can have timed out: 60 s), at most the cap
    # (the time it takes is measured by the bench, docs/robot.md: no wall-clock assert here)
    assert 2 <= status["link"]["connections"] <= 16
    assert "Traceback" not in err


def test_heartbeat_keeps_a_remote_arm_and_its_loss_disarms(tmp_path) -> None:
    # a heartbeat every 0.1 s against a 1 s link timeout: ten times the period, for a loaded machine
    cfg = config(tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN, link_timeout_s=1.0))

    async def script(app, hw):
        def operator() -> tuple[bool, bool]:
            lines: list[str] = []
            with RobotLink("127.0.0.1", token=TOKEN, port=app.command_port) as link:
                link.call("arm")
            hb = Heartbeat("127.0.0.1", token=TOKEN, port=app.command_port, period_s=0.1, echo=lines.append)
            hb.run(duration_s=2.5)  # two and a half link timeouts, kept alive
            armed_with_heartbeat = app.controller.armed
            deadline = time.monotonic() + 10  # heartbeat stopped: disarmed after link_timeout_s
            while app.controller.armed and time.monotonic() < deadline:
                time.sleep(0.02)
            return armed_with_heartbeat, app.controller.armed

        return await asyncio.to_thread(operator)

    app, summary, (with_hb, after), hw = scenario(cfg, script)
    assert with_hb is True and after is False
    assert "link_lost" in summary.faults and all_off(hw)


def test_link_loss_fail_safe_is_on_by_default_for_a_remote_arm() -> None:
    assert CommandsConfig().link_timeout_s > 0


def _flood(port: int, stop: threading.Event, counter: list[int]) -> None:
    """Open connections as fast as possible and hold them (a live flood, not idle sockets)."""
    held: list[socket.socket] = []
    try:
        while not stop.is_set():
            try:
                s = socket.create_connection(("127.0.0.1", port), timeout=0.5)
            except OSError:
                continue
            held.append(s)
            counter[0] += 1
            if len(held) > 1500:
                held.pop(0).close()
    finally:
        for s in held:
            s.close()


def test_reserved_udp_path_disarms_during_a_live_connection_flood(tmp_path) -> None:
    from rimless.firmware.link.remote import send_disarm_datagram

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        assert (await c.cmd("arm", 1))["ok"]
        stop = threading.Event()
        counter = [0]
        flooder = threading.Thread(target=_flood, args=(app.command_port, stop, counter))
        flooder.start()
        try:
            while counter[0] < 300:
                await asyncio.sleep(0.01)
            reply = await asyncio.to_thread(
                send_disarm_datagram, "127.0.0.1", token=TOKEN, port=app.command_port, timeout_s=10.0
            )
            at_reply = counter[0]
            armed_after = app.controller.armed
            while counter[0] == at_reply:  # the flood still ran after the answer: it came during the flood
                await asyncio.sleep(0.01)
            bad = await asyncio.to_thread(_bad_datagram, app.command_port)
        finally:
            stop.set()
            await asyncio.to_thread(flooder.join, 30)
        c.close()
        return reply, armed_after, bad, at_reply

    app, summary, (reply, armed_after, bad, at_reply), hw = scenario(config(tmp_path), script)
    assert reply["ok"] and reply["disarmed"] and armed_after is False and all_off(hw)
    assert reply["status"]["engaged"] == [] and isinstance(reply["status"]["faults"], list)
    assert at_reply >= 300  # answered with 300 connections or more made, and the flood went on after it
    assert bad is None  # a datagram with a wrong mac gets no answer and changes nothing


def _bad_datagram(port: int):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(0.3)
    s.sendto(json.dumps({"disarm": 1, "mac": "0" * 64}).encode(), ("127.0.0.1", port))
    try:
        return s.recv(4096)
    except TimeoutError:
        return None
    finally:
        s.close()


def test_reserved_udp_status_answers_once_and_ignores_replays_and_strangers(tmp_path) -> None:
    """A status by challenge and response; the same request sent again, a request signed with another token, and
    a disarm replayed are not answered (the disarm still disarms: releasing is always safe)."""
    from rimless.firmware.link.protocol import reserved_request
    from rimless.firmware.link.remote import send_reserved_datagram

    async def script(app, hw):
        app.controller.arm()
        st = await asyncio.to_thread(send_reserved_datagram, "127.0.0.1", "status", token=TOKEN, port=app.command_port)

        def exchange():  # blocking socket calls, off the event loop (a blocked loop trips the watchdog)
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

            def ask(data, timeout_s=0.5):  # 0.5 s of silence for the ignored ones, 5 s for an expected answer
                s.settimeout(timeout_s)
                s.sendto(data, ("127.0.0.1", app.command_port))
                try:
                    reply = s.recv(65536)
                except TimeoutError:
                    return None
                assert len(reply) <= len(data)  # never more bytes than the request
                return json.loads(reply)

            first = ask(reserved_request(TOKEN, "status", "1" * 32), 5.0)
            ch = first["challenge"]
            fresh = ask(reserved_request(TOKEN, "status", "2" * 32, ch["boot"], ch["t"]), 5.0)
            replay = ask(reserved_request(TOKEN, "status", "2" * 32, ch["boot"], ch["t"]))
            stranger = ask(reserved_request("not-the-token-" + TOKEN, "status", "3" * 32, ch["boot"], ch["t"]))
            disarm = reserved_request(TOKEN, "disarm", "4" * 32, ch["boot"], ch["t"])
            first_disarm = ask(disarm, 5.0)
            app.controller.arm()
            replayed_disarm = ask(disarm)
            s.close()
            return first, fresh, replay, stranger, first_disarm, replayed_disarm

        answers = await asyncio.to_thread(exchange)
        return st, answers, app.server._udp.replays, app.controller.armed

    app, summary, (st, answers, replays, armed), hw = scenario(config(tmp_path), script)
    first, fresh, replay, stranger, first_disarm, replayed_disarm = answers
    assert st["ok"] and st["status"]["armed"] is True and "disarmed" not in st
    assert first is not None and "status" not in first  # a first contact gets a challenge only
    assert fresh is not None and fresh["status"]["armed"] is True
    assert replay is None and stranger is None
    assert first_disarm is not None and first_disarm["disarmed"] is True
    assert replayed_disarm is None and replays == 2 and armed is False and all_off(hw)


def test_a_connect_flood_from_one_host_cannot_evict_the_operator(tmp_path) -> None:
    """Bounded churn (up to 4000 connects from 127.0.0.2 in a separate process, loopback only, stopped once the
    operator is done) while the operator at 127.0.0.1 sends five signed commands: every one is answered while
    the flood still runs, and the flood's excess is refused per source.
    Fails on today's main only on the per-source refusal: at this bounded rate its five commands got through
    too (the eviction the issue measured needed 14-16 k connects/s, beyond a bounded test on 2 shared cores)."""
    from rimless.firmware.link.remote import send_command

    code = (
        "import socket\n"
        "held = []\n"
        "for k in range(4000):\n"
        "    s = socket.socket(); s.settimeout(1); s.bind(('127.0.0.2', 0))\n"
        "    try:\n"
        "        s.connect(('127.0.0.1', PORT)); held.append(s)\n"
        "    except OSError:\n"
        "        s.close()\n"
        "    if len(held) > 200:\n"
        "        held.pop(0).close()\n"
    )

    async def script(app, hw):
        def run():
            flood = subprocess.Popen([sys.executable, "-c", code.replace("PORT", str(app.command_port))])
            results = []
            try:
                deadline = time.monotonic() + 60  # a hang guard: the event is the flood's first refusal
                while app.server.refused_per_source == 0:  # nothing announces it: looked at
                    assert flood.poll() is None and time.monotonic() < deadline, "the flood was never refused"
                    time.sleep(0.01)
                for _ in range(5):
                    results.append(
                        send_command("127.0.0.1", "status", token=TOKEN, port=app.command_port, timeout_s=3)["armed"]
                        is False
                    )
                    time.sleep(0.05)
                flooding = flood.poll() is None  # the five were answered while the flood ran
            finally:
                flood.kill()  # its remaining connects (about 15 s of them) would only wait out refusals
                flood.wait(60)
            return results, flooding, app.server.refused_per_source

        return await asyncio.to_thread(run)

    app, summary, (results, flooding, refused), hw = scenario(config(tmp_path), script)
    assert results == [True] * 5
    assert flooding
    assert refused > 0


def _churn(port: int, addresses: int, per_address: int) -> list[socket.socket]:
    """Connections from `addresses` loopback addresses (127.0.2.x), `per_address` each, held open: strangers
    that never authenticate."""
    held = []
    for k in range(addresses):
        for _ in range(per_address):
            s = socket.socket()
            s.settimeout(5)
            s.bind((f"127.0.2.{k + 1}", 0))
            try:
                s.connect(("127.0.0.1", port))
            except OSError:
                s.close()
                continue
            held.append(s)
    return held


@pytest.mark.parametrize(("addresses", "per_address"), [(64, 4), (250, 1)])
def test_connect_churn_from_many_addresses_evicts_neither_the_operators_session_nor_its_next_connection(
    tmp_path, addresses, per_address
) -> None:
    """Issue 32: churn from 64 addresses dropped the operator's connection 4 times in 12. Here the operator at
    127.0.0.1 holds an authenticated session and opens its next connection (hello read, command not yet sent);
    then 256 connections from 64 other addresses (or 250 from 250) arrive and stay. In three rounds, the pending connection's
    command and the session's ping are both answered. Fails on main: the operator's pending connection was the
    oldest unauthenticated one, the first dropped to make room. The connections are counted in, not timed."""

    async def script(app, hw):
        srv = app.server
        session = await Client.connect(app.command_port)
        assert (await session.cmd("status", 1))["ok"]
        seq = 1
        answers = []
        for _ in range(3):
            pending = await Client.connect(app.command_port)
            before = srv.evicted + srv.refused_per_source + srv.timed_out + srv.connections
            held = await asyncio.to_thread(_churn, app.command_port, addresses, per_address)
            # every stranger's connection seen by the server (held, dropped or refused) before the operator speaks
            seen = before + len(held)
            await wait_for(lambda n=seen: srv.evicted + srv.refused_per_source + srv.timed_out + srv.connections >= n)
            seq += 1
            answers.append((await pending.cmd("status", 1))["ok"])
            answers.append((await session.cmd("ping", seq))["ok"])
            pending.close()
            for s in held:
                s.close()
        session.close()
        return answers, srv.evicted

    app, summary, (answers, evicted), hw = scenario(config(tmp_path), script)
    assert answers == [True] * 6
    assert evicted > 0  # the strangers made room among themselves
