"""The app's shutdown path runs to the end whatever fails in it, and logging never blocks control."""

from __future__ import annotations

import asyncio
import io
import logging
import socket
import threading
import time

from rimless.firmware.link.telemetry import TelemetrySender
from rimless.firmware.service.config import TelemetryConfig
from rimless.firmware.service.logsetup import NonBlockingLog
from tests.support.firmware_app import Client, all_off, config, scenario, wait_for


def released(hw) -> bool:
    """Every clutch pin driven low, then given back (gpiozero closes a pin as an input)."""
    pins = [hw.pin_factory.pin(p) for p in hw.clutches.pins]
    return all(p.state is False and p.function == "input" for p in pins) and hw.clutches._devices == []


def test_an_exception_in_telemetry_still_closes_the_hardware(tmp_path, monkeypatch) -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    cfg = config(tmp_path, telemetry=TelemetryConfig(host="127.0.0.1", port=rx.getsockname()[1]))

    def broken(self, records):
        raise RuntimeError("encoder bug")

    monkeypatch.setattr(TelemetrySender, "send", broken)

    async def script(app, hw):
        def was_on() -> bool:
            return bool(hw.clutches.engaged()) or any(
                any(s.state for s in hw.pin_factory.pin(p).states) for p in hw.clutches.pins
            )

        # a counted leg locks from the third touchdown (0.1, 0.5, 0.9 s) on; a loaded machine may take longer
        await asyncio.sleep(1.4)
        await wait_for(lambda: was_on() or bool(app.summary.stop_reason))
        return was_on()

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
    """stderr that nobody reads: a write blocks until `release` is set (after `HANG_GUARD_S` without it, every
    write goes through: a log call that waits on stderr then fails the test instead of hanging it). Records the
    threads that wrote and how many writes returned."""

    HANG_GUARD_S = 60.0

    def __init__(self) -> None:
        self.release = threading.Event()
        self.writes = 0
        self.writers: set[int] = set()

    def write(self, s: str) -> int:
        self.writers.add(threading.get_ident())
        if not self.release.wait(self.HANG_GUARD_S):
            self.release.set()
        self.writes += 1
        return len(s)


def test_a_blocked_stderr_does_not_freeze_control(tmp_path) -> None:
    """On events, not times: the 2000 log calls return, and five commands are answered, while the log's first
    write to stderr is still blocked (no write has returned); no log call writes on the event loop's thread.
    Fails when logging writes to stderr on the caller's thread: the first call waits on the blocked stream."""
    stream = BlockedStream()
    logger = logging.getLogger("rimless.robot")

    async def script(app, hw):
        c = await Client.connect(app.command_port)
        t0 = time.perf_counter()
        for k in range(2000):  # far more than the queue holds
            logger.warning("flood %d", k)
        flood_s = time.perf_counter() - t0
        writes_after_flood = stream.writes
        replies = []
        for seq in range(1, 6):
            r = await c.cmd("status", seq)
            replies.append(r["ok"])
            await asyncio.sleep(0.05)
        writes_after_replies = stream.writes
        # the control loop samples meanwhile: waited for (its 50 samples are an event, not the replies' 0.25 s)
        await wait_for(lambda: app.sampler.stats.samples > 50)
        c.close()
        loop_wrote = threading.get_ident() in stream.writers
        return flood_s, writes_after_flood, replies, writes_after_replies, loop_wrote

    log = NonBlockingLog(stream, queue_len=100).start()
    try:
        app, summary, result, hw = scenario(config(tmp_path), script, arm=True)
    finally:
        stream.release.set()
        log.stop()
    flood_s, writes_after_flood, replies, writes_after_replies, loop_wrote = result
    print(f"2000 log calls took {flood_s * 1e3:.1f} ms with stderr blocked")  # a figure, not a bound
    assert writes_after_flood == 0  # the flood returned while stderr's first write was still blocked
    assert replies == [True] * 5 and writes_after_replies == 0  # answered while stderr was still blocked
    assert not loop_wrote  # no log call wrote on the event loop's thread
    assert log.dropped >= 1800 and summary.samples > 50 and all_off(hw)
