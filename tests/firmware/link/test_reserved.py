"""The reserved UDP path (disarm, status) against the attacks of issue 32, item 2, on the loopback only: a PC
clock an hour ahead or ten minutes behind, a datagram numbered in the future, captured datagrams replayed after a
restart from a spoofed source, and bounded floods spoofing the operator's own address or spread over 900
addresses. Requests are built here by hand from the protocol's description (`protocol` module docstring), not
with the code under test. No test measures time: the flood's cost in disarm latency and loop rate is measured
by `python -m rimless.firmware.service.bench --flood` (docs/robot.md)."""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import json
import secrets
import socket
import threading
import time

import pytest

from rimless.firmware.errors import RobotUnreachable
from rimless.firmware.link.commands import ReservedListener
from rimless.firmware.link.remote import send_disarm_datagram, send_reserved_datagram
from rimless.firmware.service.bench import FLOOD_MAX_DATAGRAMS, Flood
from rimless.firmware.service.config import CommandsConfig
from tests.support.firmware_app import REPLY_GUARD_S, TOKEN, all_off, config, free_port, scenario


def request(kind: str, nonce: str, boot: str | None = None, t: int | None = None, token: str = TOKEN) -> bytes:
    """A version-3 request, from the protocol's description, padded to 400 bytes."""
    body = f"rimless3 {kind} {nonce} {boot or '-'} {'-' if t is None else t}".encode()
    data = body + b" " + hmac.new(token.encode(), body, hashlib.sha256).hexdigest().encode()
    return data + b" " + b"x" * (399 - len(data))


def v2_datagram(kind: str, n: int, token: str = TOKEN) -> bytes:
    """A protocol-version-2 datagram, as the PC of release 0.x sent it."""
    mac = hmac.new(token.encode(), f"{kind}\n{n}".encode(), hashlib.sha256).hexdigest()
    return json.dumps({kind: n, "mac": mac, "pad": "x" * 250}).encode()


def signed(reply: dict, token: str = TOKEN) -> bool:
    """The answer's MAC (HMAC-SHA256 under the token of "reply\\n" + its canonical JSON without "mac") holds."""
    body = json.dumps({k: v for k, v in reply.items() if k != "mac"}, sort_keys=True, separators=(",", ":"))
    return hmac.compare_digest(reply["mac"], hmac.new(token.encode(), b"reply\n" + body.encode(), "sha256").hexdigest())


def exchange(port: int, data: bytes, *, source: str = "127.0.0.1") -> dict | None:
    """Send `data` from `source`; its answer (asserted no larger than the request), or None when the robot dropped it.

    No fixed wait decides "not answered": after `data` the same socket sends a marker, a fresh first-contact
    status request with a nonce of its own, which the robot always answers (with a challenge, no status, nothing
    acted on). The robot handles datagrams one at a time in arrival order and loopback keeps the order of one
    socket's datagrams, so an answer to `data` comes before the marker's: the marker's answer is the event that says
    `data` was handled. `REPLY_GUARD_S` is only a hang guard."""
    marker = secrets.token_hex(16)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((source, 0))
        s.settimeout(REPLY_GUARD_S)
        s.sendto(data, ("127.0.0.1", port))
        s.sendto(request("status", marker), ("127.0.0.1", port))
        answers = []
        while not answers or answers[-1][1].get("for") != marker:
            raw = s.recv(65536)
            answers.append((raw, json.loads(raw)))
    *before, _marker_answer = answers
    assert len(before) <= 1, before  # one answer at most to one datagram
    if not before:
        return None
    reply, decoded = before[0]
    assert len(reply) <= len(data)
    return decoded


def test_exchange_takes_an_answer_however_late_it_comes() -> None:
    """The helper above against a stand-in robot that answers the first datagram only once the next has arrived (as
    late as an answer can come while the robot keeps order), then the marker: the late answer is returned, not taken
    for silence; a datagram left unanswered is None. The helper's former fixed 0.5 s wait returned None for the
    late one (the stand-in then saw no marker before its guard)."""
    server = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    server.bind(("127.0.0.1", 0))
    server.settimeout(REPLY_GUARD_S)

    def stand_in() -> None:
        for answer_first in (True, False):
            data, client = server.recvfrom(65536)
            marker, _ = server.recvfrom(65536)
            nonce = marker.split(b" ")[2].decode()
            if answer_first:
                server.sendto(b'{"for": "late"}', client)
            server.sendto(json.dumps({"for": nonce}).encode(), client)

    thread = threading.Thread(target=stand_in, daemon=True)
    thread.start()
    try:
        port = server.getsockname()[1]
        late = exchange(port, request("status", "a" * 32))
        dropped = exchange(port, request("status", "b" * 32))
    finally:
        thread.join(REPLY_GUARD_S)
        server.close()
    assert late == {"for": "late"} and dropped is None


def _disarms(port: int, count: int) -> list[bool]:
    out = []
    for _ in range(count):
        try:
            out.append(send_disarm_datagram("127.0.0.1", token=TOKEN, port=port, timeout_s=3.0)["disarmed"] is True)
        except RobotUnreachable:
            out.append(False)
    return out


@pytest.mark.parametrize("skew_s", [3600.0, -600.0])
def test_a_pc_clock_ahead_or_behind_neither_silences_nor_is_silenced(tmp_path, monkeypatch, skew_s) -> None:
    """Issue 32: with the PC's clock an hour ahead, one disarm silenced the next five after the clock was
    corrected; ten minutes behind, no disarm was answered. Fails on main (the datagram's number was the PC's
    clock)."""
    real_ns, real_s = time.time_ns, time.time

    async def script(app, hw):
        app.controller.arm()
        monkeypatch.setattr(time, "time_ns", lambda: real_ns() + int(skew_s * 1e9))
        monkeypatch.setattr(time, "time", lambda: real_s() + skew_s)
        skewed = await asyncio.to_thread(_disarms, app.command_port, 1)
        monkeypatch.setattr(time, "time_ns", real_ns)
        monkeypatch.setattr(time, "time", real_s)
        app.controller.arm()
        later = await asyncio.to_thread(_disarms, app.command_port, 5)
        return skewed, later, app.controller.armed

    app, summary, (skewed, later, armed), hw = scenario(config(tmp_path), script)
    assert skewed == [True] and later == [True] * 5
    assert armed is False and all_off(hw)


def test_a_datagram_numbered_in_the_future_silences_no_later_disarm(tmp_path) -> None:
    """A valid version-2 datagram numbered 2^63-1 (main accepted it and ignored every later one until a
    restart), and a version-3 request answering a challenge second far in the future: the operator's next
    five disarms are all answered. Fails on main."""

    async def script(app, hw):
        app.controller.arm()

        def run():
            old = exchange(app.command_port, v2_datagram("disarm", 2**63 - 1))
            boot = getattr(app.server, "boot", "0" * 32)  # (main had no boot nonce)
            future = exchange(app.command_port, request("status", secrets.token_hex(16), boot, 10**12 - 1))
            return old, future, _disarms(app.command_port, 5)

        return await asyncio.to_thread(run)

    app, summary, (old, future, later), hw = scenario(config(tmp_path), script)
    assert later == [True] * 5
    # the version-2 disarm was acted on, and its sender told why it gets no status
    assert old is not None and old["ok"] is False and "version 2" in old["error"] and "version 3" in old["error"]
    # the request from the future is authenticated but not fresh: a challenge, no status
    assert future is not None and signed(future) and "status" not in future and future["challenge"]["t"] < 10**12 - 1
    assert all_off(hw)


class Relay:
    """A UDP relay between the PC and the robot that keeps every datagram the PC sends: an eavesdropper."""

    def __init__(self, robot_port: int) -> None:
        self.robot = ("127.0.0.1", robot_port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.port = self.sock.getsockname()[1]
        self.captured: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        pc = None
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            if addr == self.robot:
                if pc is not None:
                    self.sock.sendto(data, pc)
            else:
                pc = addr
                self.captured.append(data)
                self.sock.sendto(data, self.robot)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.sock.close()


def test_captured_datagrams_replayed_after_a_restart_from_a_spoofed_source_get_no_status(tmp_path) -> None:
    """The operator disarms and asks the status through an eavesdropper; the robot restarts; every captured
    datagram is replayed twice from another address (127.0.0.2). Fails on main: the counter started again at
    the restart and the replayed status was answered, status included, to the spoofed source."""
    port = free_port()
    cfg = config(tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=port, token=TOKEN))

    async def before(app, hw):
        app.controller.arm()

        def run():
            relay = Relay(app.command_port)
            try:
                d = send_disarm_datagram("127.0.0.1", token=TOKEN, port=relay.port, timeout_s=3.0)
                s = send_reserved_datagram("127.0.0.1", "status", token=TOKEN, port=relay.port, timeout_s=3.0)
            finally:
                relay.close()
            same_start = [exchange(app.command_port, data, source="127.0.0.2") for data in relay.captured]
            return d, s, relay.captured, same_start

        return await asyncio.to_thread(run)

    _, _, (d, s, captured, same_start), _ = scenario(cfg, before)
    assert d["disarmed"] is True and s["status"]["armed"] is False
    assert len(captured) >= 4  # a disarm and a status, each a first contact and an answer to the challenge
    assert same_start == [None] * len(captured)  # before the restart: every one a replay, none answered

    async def after(app, hw):
        app.controller.arm()

        def run():
            first = [exchange(app.command_port, data, source="127.0.0.2") for data in captured]
            again = [exchange(app.command_port, data, source="127.0.0.2") for data in captured]
            return first, again

        return await asyncio.to_thread(run), app.controller.armed

    _, _, ((first, again), armed), hw = scenario(cfg, after)
    answered = [a for a in first if a is not None]
    assert all("status" not in a for a in answered)  # no status to a spoofed source, ever
    assert all(signed(a) for a in answered)
    assert again == [None] * len(captured)  # and each captured datagram is answered at most once
    assert armed is False and all_off(hw)  # a captured disarm still disarms: releasing is always safe


def _first_rejection(listener: ReservedListener) -> threading.Event:
    """An event set when `listener` (the robot's reserved path) first rejects a datagram: its `on_rejected` hook,
    wrapped (the hook is called from the listener's thread as it handles each datagram)."""
    rejected = threading.Event()
    logged = listener.on_rejected

    def on_rejected(addr: str, why: str) -> None:
        rejected.set()
        logged(addr, why)

    listener.on_rejected = on_rejected
    return rejected


def _flood_during_disarms(
    port: int, sources: list[str], count: int, reached: threading.Event
) -> tuple[list[bool], bool, int]:
    """Start a bounded flood (the bench's, another process, listening for answers) from `sources`; once the robot
    has rejected one of its datagrams (`reached`, from `_first_rejection`: the flood has reached it), ten disarms
    from 127.0.0.1; returns their results, whether the flood still ran when they were done, and how many of the
    flood's datagrams were answered. Waiting for the flood's "flooding" line alone raced: on a loaded machine the
    flood process was not scheduled before the ten disarms were done (CI, 2026-11-28: nothing of it rejected).
    A count the flood could finish raced the other way: 400 000 datagrams were all sent before the disarms were
    done while the suite compiled beside it (a CI run of session 21); the tests now flood up to the bench's own
    safety bound (`FLOOD_MAX_DATAGRAMS`), which `stop()` ends as soon as the disarms are done."""
    with Flood(sources, port, count=count, listen=True) as flood:
        assert reached.wait(REPLY_GUARD_S), "the flood never reached the robot"  # the guard only bounds a hang
        results = _disarms(port, 10)
        counted = flood.stop()
    return results, counted.stopped, counted.answered


def test_a_flood_spoofing_the_operators_address_leaves_every_disarm_answered(tmp_path) -> None:
    """A flood (junk, bad MACs and version-2 garbage, until the disarms are done) from 127.0.0.1, the
    operator's own address: ten disarms from there during it are all answered, and nothing of the flood is.
    Fails on main: the per-source budget the flood drained was the operator's (2-4 of 10 answered)."""

    async def script(app, hw):
        app.controller.arm()
        results, during, answered = await asyncio.to_thread(
            _flood_during_disarms,
            app.command_port,
            ["127.0.0.1"],
            FLOOD_MAX_DATAGRAMS,
            _first_rejection(app.server._udp),
        )
        return results, during, answered, getattr(app.server._udp, "rejected", 1)  # (main did not count them)

    app, summary, (results, during, answered, rejected), hw = scenario(config(tmp_path), script)
    assert results == [True] * 10
    assert during, "the flood ended before the ten disarms"
    assert answered == 0 and rejected > 0
    assert all_off(hw)


def test_a_flood_from_900_addresses_leaves_every_disarm_answered(tmp_path) -> None:
    """The same flood spread over 900 addresses (127.0.1.1 ...). Passes on main too: main answered them,
    slowly (up to 437 ms each, the loop down from 296 to 186 Hz); the time and the loop rate are measured by the
    bench (docs/robot.md), not here."""
    sources = [f"127.0.{1 + k // 250}.{1 + k % 250}" for k in range(900)]

    async def script(app, hw):
        app.controller.arm()
        results, during, answered = await asyncio.to_thread(
            _flood_during_disarms, app.command_port, sources, FLOOD_MAX_DATAGRAMS, _first_rejection(app.server._udp)
        )
        return results, during, answered, getattr(app.server._udp, "rejected", 1)  # (main did not count them)

    app, summary, (results, during, answered, rejected), hw = scenario(config(tmp_path), script)
    assert results == [True] * 10 and during and answered == 0 and rejected > 0


class ManualClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _listener(clock: ManualClock) -> tuple[ReservedListener, list[str]]:
    disarmed: list[str] = []
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener = ReservedListener(
        sock, TOKEN, lambda: disarmed.append("off"), lambda: {"armed": False}, lambda *a: None, clock=clock
    )
    sock.close()  # handle() is fed directly: no thread
    return listener, disarmed


def test_a_challenge_is_fresh_for_its_window_only_and_a_disarm_is_never_withheld() -> None:
    """On a clock of its own: a challenge answered within 30 s of the robot's clock gets the status, one 31 s
    old a new challenge; a disarm with a stale, foreign or missing challenge still disarms; a wrong token gets
    nothing and does nothing."""
    clock = ManualClock()
    listener, disarmed = _listener(clock)
    first = json.loads(listener.handle(request("status", "a" * 32), ("127.0.0.1", 1)) or b"null")
    challenge = first["challenge"]
    assert signed(first) and "status" not in first and challenge["boot"] == listener.boot
    clock.t += 30.9
    fresh = json.loads(listener.handle(request("status", "b" * 32, challenge["boot"], challenge["t"]), 1) or b"null")
    assert signed(fresh) and fresh["status"] == {"armed": False}
    clock.t += 0.2  # 31.1 s after the challenge
    stale = json.loads(listener.handle(request("status", "c" * 32, challenge["boot"], challenge["t"]), 1) or b"null")
    assert "status" not in stale and stale["challenge"]["t"] == 31
    other_boot = request("disarm", "d" * 32, "e" * 32, stale["challenge"]["t"])
    assert json.loads(listener.handle(other_boot, 1) or b"null")["disarmed"] is True and disarmed == ["off"]
    assert listener.handle(other_boot, 1) is None and disarmed == ["off", "off"]  # replay: acted on, unanswered
    assert listener.handle(request("disarm", "f" * 32, token="x" + TOKEN), 1) is None and len(disarmed) == 2
