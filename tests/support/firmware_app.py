"""Shared by the firmware tests: a `RobotApp` on fake hardware over loopback sockets (`scenario`; the control
loop and the fakes on a `VirtualClock`, so a loaded machine never makes the fake walk miss a sample), a client
of the signed command protocol written from its description (`Client`), and small probes."""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import json
import secrets
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path

from rimless.firmware.clock import VirtualClock, seconds
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory
from rimless.firmware.service.app import RobotApp
from rimless.firmware.service.config import CommandsConfig, LogConfig, RobotConfig, SamplingConfig
from rimless.firmware.service.hardware import build_fake

TOKEN = secrets.token_urlsafe(18)  # generated: a token published in the tests is refused


#: how long the test client waits for a reply that should come (a hang guard, not a bound)
REPLY_GUARD_S = 30.0

#: the watchdogs' own tests: the control-thread watchdog at 0.3 s, the event loop's at the robot's 0.25 s
WATCHDOG_TEST_SAMPLING = SamplingConfig(stall_timeout_s=0.3)


def config(tmp_path: Path, **kw) -> RobotConfig:
    base = dict(
        commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN),
        log=LogConfig(dir=str(tmp_path / "trials"), flush_interval_s=0.05),
        # Both watchdogs at 1 s instead of the robot's 0.1 s (control thread) and 0.25 s (event loop): a test
        # machine at load 6-7 on 2 cores (two test workers beside other jobs) paused the sampler for 0.3-0.6 s
        # and the event loop for as long, which faulted tests of other things. Tests of the watchdogs pass
        # their own SamplingConfig (`WATCHDOG_TEST_SAMPLING`).
        sampling=SamplingConfig(stall_timeout_s=1.0, loop_stall_s=1.0),
    )
    base.update(kw)
    return RobotConfig(**base)


def gait(step_period_s: float = 0.4, steps: int | None = None, now_s: float | None = None) -> GaitTrajectory:
    """A walk from 0.1 s after `now_s` (default: the monotonic clock now)."""
    start = time.monotonic() if now_s is None else now_s
    return GaitTrajectory(start_s=start + 0.1, step_period_s=step_period_s, steps=steps)


def scenario(cfg: RobotConfig, script, *, trajectory=None, arm=False, timeout_s=60.0, hw_hook=None):
    """Run the app with fake hardware on a virtual clock (paced to the wall clock; `trajectory` on that clock,
    by default a walk from 0.1 s after the first sample); `script(app, hw)` runs once it is ready, then the app
    stops. `timeout_s` is a hang guard (the app's --duration-s), not a bound: scripts end on their own events."""
    clock = VirtualClock()
    hw = build_fake(cfg, trajectory=trajectory or gait(now_s=seconds(clock)()), clock=clock)
    if hw_hook is not None:
        hw_hook(hw)

    async def main():
        ready = asyncio.Event()
        app = RobotApp(cfg, hw, on_ready=lambda a: ready.set())
        # armed as an operator arms the robot: naming the leg the fake walk starts on (the configured one)
        leg = cfg.configured_stance_leg() if arm else None
        run = asyncio.create_task(app.run(duration_s=timeout_s, arm=arm, handle_signals=False, stance_leg=leg))
        await ready.wait()
        try:
            result = await script(app, hw)
        finally:
            app.request_stop("test done")
            summary = await run
        return app, summary, result

    return (*asyncio.run(main()), hw)


class Client:
    """A loopback client of the signed protocol (written from the protocol's description)."""

    def __init__(self, reader, writer, hello) -> None:
        self.reader, self.writer, self.hello = reader, writer, hello
        self.nonce = hello["nonce"]

    @classmethod
    async def connect(cls, port: int) -> Client:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        hello = json.loads(await asyncio.wait_for(reader.readline(), REPLY_GUARD_S))
        return cls(reader, writer, hello)

    def sign(self, seq: int, cmd: str, args: dict, token: str = TOKEN) -> bytes:
        body = json.dumps([seq, cmd, args], sort_keys=True, separators=(",", ":"), ensure_ascii=True)
        mac = hmac.new(token.encode(), f"{self.nonce}\n{body}".encode(), hashlib.sha256).hexdigest()
        return json.dumps({"seq": seq, "cmd": cmd, "args": args, "mac": mac}).encode() + b"\n"

    async def raw(self, data: bytes) -> dict:
        self.writer.write(data)
        await self.writer.drain()
        return json.loads(await asyncio.wait_for(self.reader.readline(), REPLY_GUARD_S))

    async def cmd(self, cmd: str, seq: int, token: str = TOKEN, **args) -> dict:
        return await self.raw(self.sign(seq, cmd, args, token))

    def close(self) -> None:
        self.writer.close()


async def wait_for(condition, timeout_s: float = 50.0, every_s: float = 0.01) -> None:
    """Poll `condition()` in the event loop until it holds; AssertionError after `timeout_s` (generous: a
    loaded test machine is slow, and a condition costs no time when it holds early). Under `scenario`'s
    default 60 s run."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met in {timeout_s:g} s")
        await asyncio.sleep(every_s)


def all_off(hw) -> bool:
    return all(hw.pin_factory.pin(p).state is False for p in hw.clutches.pins) if hw.clutches.pins else True


def free_port() -> int:
    """A TCP port free on the loopback now (a robot nobody runs)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_udp_bound(port: int, timeout_s: float = 10.0) -> bool:
    """Wait until some socket is bound to UDP `port` on this host (Linux: /proc/net/udp); False on timeout.

    A sender that starts before the receiver has bound loses its first datagrams (port unreachable), which a
    loaded machine turns into a flaky count.
    """
    needle = f":{port:04X} "
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            with open("/proc/net/udp", encoding="ascii") as fh:
                if any(needle in line.split()[1] + " " for line in fh.readlines()[1:] if len(line.split()) > 1):
                    return True
        except OSError:
            time.sleep(0.5)  # no /proc: fall back on a fixed head start
            return False
        time.sleep(0.01)
    return False


def signed_datagram(data: bytes) -> bytes:
    """A telemetry datagram as a robot of protocol version 3 sends it: with its tag (`robot listen` without the
    token takes the first sender whose datagrams carry one for the robot)."""
    from rimless.firmware.link.telemetry import sign_datagram, telemetry_key

    return sign_datagram(data, telemetry_key("any-token-of-this-robot", "e" * 32), "e" * 32)


class TurnClock:
    """A virtual clock (s) for `listen(clock=...)` and `RobotApp.link_clock`, moved by events, never by the
    machine's speed: it stands still until released (`release()`, or `release_when()` holding at a reading: say,
    once listen reached the stage of its last datagram), then moves `step_s` at each reading (listen reads it
    once or twice a turn of its loop, and a turn without a datagram waits 0.1 s on its socket: a silence is
    counted in listen's idle turns). `advance(s)` moves it by hand."""

    def __init__(self, step_s: float = 0.1, release_when: Callable[[], bool] | None = None) -> None:
        self.t = 0.0
        self.step_s = step_s
        self.release_when = release_when
        self.released = threading.Event()

    def release(self) -> None:
        self.released.set()

    def advance(self, s: float) -> None:
        self.t += s

    def __call__(self) -> float:
        if not self.released.is_set() and self.release_when is not None and self.release_when():
            self.released.set()
        if self.released.is_set():
            self.t += self.step_s
        return self.t


def stage_reached(path: Path, name: str) -> Callable[[], bool]:
    """Whether the stage `name` is in the stage file `path` (`rimless.progress.stage` with
    RIMLESS_TEST_STAGE_FILE set to a plain file: for code run in the test's own process)."""

    def reached() -> bool:
        try:
            return name in path.read_text().splitlines()
        except FileNotFoundError:
            return False

    return reached
