"""A command client that never reads its replies, on the loopback: it is dropped quietly (no asyncio traceback,
no error logged) within the server's reply timeout, and an operator is served meanwhile. Bounded: at most
`CHUNKS` sends of 4096 garbage lines (8 MB of refusals: more than the buffers on the way hold, measured
2.2 MB here), 40 s at most for the whole test (about 4 s on a quiet machine)."""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time

from rimless.firmware.service.config import CommandsConfig
from tests.support.firmware_app import TOKEN, Client, config, scenario

CHUNKS = 40  # 164 k lines
CHUNK = b"x\n" * 4096  # each line a garbled message: a 50-byte refusal for 2 bytes sent
REPLY_TIMEOUT_S = 1.0


def flood_without_reading(port: int, done: threading.Event, out: dict) -> None:
    """Send the garbage, never read, and hold the connection open until `done` (or the server resets it)."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # the refusals pile up in the server
    s.connect(("127.0.0.1", port))
    s.settimeout(1.0)
    chunks = 0
    try:
        while chunks < CHUNKS and not done.is_set():
            try:
                s.sendall(CHUNK)
                chunks += 1
            except TimeoutError:  # the server is not reading now: try again
                continue
            except OSError as err:  # reset by the server: dropped
                out["send_error"] = type(err).__name__
                break
        out["chunks"] = chunks
        done.wait(40)
    finally:
        s.close()


def test_a_client_that_never_reads_is_dropped_quietly_while_the_operator_is_served(tmp_path, caplog) -> None:
    caplog.set_level(logging.WARNING)
    errors: list[dict] = []
    out: dict = {}

    async def script(app, hw):
        asyncio.get_running_loop().set_exception_handler(lambda _loop, ctx: errors.append(ctx))
        server = app.server
        server.reply_timeout_s = REPLY_TIMEOUT_S
        done = threading.Event()
        flooder = threading.Thread(target=flood_without_reading, args=(app.command_port, done, out))
        flooder.start()
        try:
            deadline = time.monotonic() + 35
            rejected_before = server.rejected
            while server.rejected < rejected_before + 1000:  # the flood is being answered
                assert time.monotonic() < deadline, "the flood was never read"
                await asyncio.sleep(0.05)
            op = await Client.connect(app.command_port)
            served = await op.cmd("status", 1)  # the operator, meanwhile
            while server.unread_dropped == 0:  # dropped once its replies wait REPLY_TIMEOUT_S
                assert time.monotonic() < deadline, "the non-reader was never dropped"
                await asyncio.sleep(0.05)
            after = await op.cmd("ping", 2)
            op.close()
        finally:
            done.set()
            await asyncio.to_thread(flooder.join, 10)
        return served, after, server.connections

    # no authentication deadline to drop it first: only its unread replies can
    cfg = config(tmp_path, commands=CommandsConfig(bind="127.0.0.1", port=0, token=TOKEN, auth_timeout_s=60.0))
    _app, _summary, (served, after, conns), _hw = scenario(cfg, script, timeout_s=40.0)
    assert served["ok"] and after["ok"]
    assert conns <= 1  # the non-reader is gone
    assert out["chunks"] == CHUNKS
    assert errors == []  # nothing reached the loop's exception handler
    bad = [r for r in caplog.records if r.levelno >= logging.ERROR or r.exc_info or "Traceback" in r.getMessage()]
    assert bad == [], [r.getMessage() for r in bad]
