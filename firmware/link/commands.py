"""The robot side of the command channel: an asyncio TCP server, authenticated per connection, that
holds under abuse, and the reserved UDP path for `disarm` and `status` on a thread of its own.

The wire format and the validation of each message are in `protocol`.

Abuse limits: at most `max_connections` connections; a connection that has not sent a valid
command within `auth_timeout_s` is closed, so is one idle for `idle_timeout_s`; an authenticated
connection is never dropped to make room, and a stranger's connection makes room only by dropping
another stranger's, never one from an address that authenticated before (`CommandServer`).
Rejections are logged at most `LOG_LINES_PER_S` times per second.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import secrets
import socket
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Any

from rimless.firmware.link.protocol import (
    COMMANDS,
    DEFAULT_PORT,
    HELLO,
    PROTOCOL_VERSION,
    RESERVED_WINDOW_S,
    Command,
    Rejected,
    Sha256Mac,
    WeakToken,
    check_reserved_request,
    check_token,
    check_v2_reserved,
    command_mac,
    new_boot_nonce,
    parse_command,
    parse_reserved_request,
    reply_mac,
)

__all__ = [  # the protocol's names are re-exported: the server and its tests speak them
    "COMMANDS",
    "DEFAULT_PORT",
    "HELLO",
    "LOG_LINES_PER_S",
    "PROTOCOL_VERSION",
    "Command",
    "CommandServer",
    "RateLimitedLog",
    "Rejected",
    "ReservedListener",
    "WeakToken",
    "check_token",
    "command_mac",
    "parse_command",
    "parse_reserved_request",
]

log = logging.getLogger("rimless.robot.commands")

LOG_LINES_PER_S = 5.0


class ReservedListener:
    """The reserved path for `disarm` and `status` (see `protocol`): a thread of its own on a UDP socket, so
    neither TCP connections nor a busy event loop can delay it. The callbacks run in this thread (they must be
    thread-safe); `on_status` returns a small JSON-able dict.

    Nothing a sender does changes how the next sender is served, except through the token: no counter to push
    into the future, no per-source budget to drain with a spoofed address. Every datagram is checked on its raw
    bytes (a layout check and one HMAC, no JSON); one that fails gets no answer. An authenticated disarm
    disarms, whatever its challenge. An authenticated request is answered once (its MAC, kept
    `RESERVED_WINDOW_S`, is the replay key), with the status only when it answers this start's challenge.
    Rejection logs go through the caller's rate-limited log.

    :param clock: the robot's seconds (monotonic); the challenges' seconds count from the listener's start.
    :param boot: this start's nonce (default: a fresh one).
    """

    MAX_REPLAY_KEYS = 16384  # authenticated requests remembered; only token holders can add one

    def __init__(
        self,
        sock: socket.socket,
        token: str,
        on_disarm: Callable[[], None],
        on_status: Callable[[], dict[str, Any]],
        on_rejected: Callable[[str, str], None],
        *,
        boot: str | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.sock = sock
        self.token = token
        self._mac = Sha256Mac(token.encode("utf-8"))
        self.on_disarm = on_disarm
        self.on_status = on_status
        self.on_rejected = on_rejected
        self.boot = boot or new_boot_nonce()
        self.clock = clock
        self._t0 = clock()
        self.disarms = 0
        self.statuses = 0
        self.replays = 0  # authenticated requests seen before: acted on if disarms, not answered
        self.rejected = 0  # datagrams that failed their MAC or layout: not answered
        self.challenges = 0  # authenticated but not fresh: answered with a challenge, no status
        self.version_errors = 0  # authenticated version-2 datagrams: answered with an error naming the versions
        self.received = 0
        self._seen: dict[str, float] = {}  # replay key (MAC) -> the second it expires
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rimless-reserved", daemon=True)

    @classmethod
    def bind(
        cls,
        host: str,
        port: int,
        token: str,
        on_disarm: Callable[[], None],
        on_status: Callable[[], dict[str, Any]],
        on_rejected: Callable[[str, str], None],
        *,
        boot: str | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> ReservedListener:
        """Bind the UDP socket (raises OSError) and start the thread."""
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind((host, port))
            sock.settimeout(0.2)
            with contextlib.suppress(OSError):  # room for a burst while the thread waits for the GIL
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        except OSError:
            sock.close()
            raise
        listener = cls(sock, token, on_disarm, on_status, on_rejected, boot=boot, clock=clock)
        listener._thread.start()
        return listener

    def now_s(self) -> int:
        """The challenge's second: whole seconds of the robot's clock since this listener started."""
        return int(self.clock() - self._t0)

    def _status(self) -> dict[str, Any]:
        try:
            return self.on_status()
        except Exception as err:  # noqa: BLE001 - a racing read must not kill the reserved path
            return {"error": f"{type(err).__name__}: {err}"}

    def _first_time(self, key: str, now: int) -> bool:
        """True the first time `key` is seen within `RESERVED_WINDOW_S`; remembers it."""
        if self._seen.get(key, -1) >= now:
            return False
        self._seen[key] = now + RESERVED_WINDOW_S
        if len(self._seen) > self.MAX_REPLAY_KEYS:
            for k in [k for k, until in self._seen.items() if until < now] or [next(iter(self._seen))]:
                del self._seen[k]
        return True

    def handle(self, data: bytes, addr: Any) -> bytes | None:
        """Act on one datagram; return the answer to send (None: no answer). Public for the tests and the
        bench, which feed it directly."""
        self.received += 1
        if data.startswith(b"{"):
            return self._handle_v2(data, addr)
        req = check_reserved_request(data, self._mac)
        if isinstance(req, str):
            self.rejected += 1
            self.on_rejected(str(addr), req)
            return None  # no answer to what is not authenticated
        if req.kind == "disarm":
            self.on_disarm()  # before anything else: a disarm is never withheld
            self.disarms += 1
        now = self.now_s()
        if not self._first_time(req.mac, now):
            self.replays += 1
            self.on_rejected(str(addr), f"reserved {req.kind}: seen before (a replay); acted on, not answered")
            return None  # a replay with a spoofed source must not reflect
        fresh = req.boot == self.boot and req.t_s is not None and now - RESERVED_WINDOW_S <= req.t_s <= now
        reply: dict[str, Any] = {
            "v": PROTOCOL_VERSION,
            "ok": True,
            "for": req.client_nonce,
            "challenge": {"boot": self.boot, "t": now},
        }
        if req.kind == "disarm":
            reply["disarmed"] = True
        if fresh:
            self.statuses += req.kind == "status"
            return self._bounded(reply, self._status(), len(data))
        self.challenges += 1
        return self._bounded(reply, None, len(data))

    def _handle_v2(self, data: bytes, addr: Any) -> bytes | None:
        """A protocol-version-2 datagram: a disarm whose MAC holds is acted on; each authenticated one is
        answered once with an error naming the versions (never the status)."""
        out = check_v2_reserved(data, self._mac)
        if isinstance(out, str):
            self.rejected += 1
            self.on_rejected(str(addr), out)
            return None
        kind, n = out
        if kind == "disarm":
            self.on_disarm()
            self.disarms += 1
        self.version_errors += 1
        if not self._first_time(f"v2:{kind}:{n}", self.now_s()):
            self.replays += 1
            return None
        msg = {
            "ok": False,
            "n": n,
            "version": PROTOCOL_VERSION,
            "error": f"protocol version 2 datagram: this robot speaks version {PROTOCOL_VERSION}"
            + (" (the disarm was acted on)" if kind == "disarm" else "")
            + "; upgrade rimless on the PC",
        }
        answer = json.dumps(msg, separators=(",", ":")).encode()
        return answer if len(answer) <= len(data) else None

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(1024)
            except TimeoutError:
                continue
            except OSError:
                return  # closed
            try:
                out = self.handle(data, addr)
            except Exception as err:  # noqa: BLE001 - any datagram gets a log line, never a traceback
                self.on_rejected(str(addr), f"unreadable reserved datagram ({type(err).__name__})")
                continue
            if out is not None:
                with contextlib.suppress(OSError, TypeError, ValueError):
                    self.sock.sendto(out, addr)

    def _bounded(self, reply: dict[str, Any], status: dict[str, Any] | None, limit: int) -> bytes | None:
        """The signed answer, never larger than the request (`limit` bytes): the status shrinks to its counts,
        then goes, if need be (None when even the bare answer does not fit)."""
        candidates = [reply] if status is None else [dict(reply, status=status)]
        if status is not None:
            short = {
                k: (len(v) if isinstance(v, list) else v)
                for k, v in status.items()
                if k in ("armed", "faults", "engaged")
            }
            candidates += [dict(reply, status=short), reply]
        for cand in candidates:
            cand = dict(cand, mac=reply_mac(self.token, cand))
            out = json.dumps(cand, separators=(",", ":"), default=str).encode()
            if len(out) <= limit:
                return out
        return None

    def close(self) -> None:
        """Stop the thread and close the socket."""
        self._stop.set()
        self._thread.join(1.0)
        self.sock.close()


class RateLimitedLog:
    """Logs at most `per_s` lines per second; the rest are counted and summarised in the next line."""

    def __init__(
        self, logger: logging.Logger, per_s: float = LOG_LINES_PER_S, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.logger = logger
        self.per_s = per_s
        self.clock = clock
        self._allowance = per_s
        self._last = clock()
        self.suppressed = 0
        self.logged = 0
        self._lock = threading.Lock()  # the event loop and the disarm thread both log

    def warning(self, msg: str, *args: Any) -> None:
        """Log `msg % args` as a warning if the budget allows."""
        with self._lock:
            self._warning(msg, *args)

    def _warning(self, msg: str, *args: Any) -> None:
        now = self.clock()
        self._allowance = min(self.per_s, self._allowance + (now - self._last) * self.per_s)
        self._last = now
        if self._allowance < 1.0:
            self.suppressed += 1
            return
        self._allowance -= 1.0
        if self.suppressed:
            msg = f"{msg} ({self.suppressed} similar lines suppressed)"
            self.suppressed = 0
        self.logged += 1
        self.logger.warning(msg, *args)


Handler = Callable[[Command], Awaitable[dict[str, Any]]]


class _Conn:
    __slots__ = ("task", "writer", "opened_s", "authenticated", "peer", "source")

    def __init__(self, task: asyncio.Task[None], writer: asyncio.StreamWriter, peer: str, source: str) -> None:
        self.task = task
        self.writer = writer
        self.opened_s = time.monotonic()
        self.authenticated = False
        self.peer = peer
        self.source = source


class CommandServer:
    """asyncio TCP server; `handler` executes a validated command or raises ValueError/RuntimeError.

    Connections are of three kinds: authenticated (sent a valid command: never dropped to make room),
    pending from an operator's address (an address that authenticated before, `KNOWN_OPERATORS` remembered:
    TCP's handshake proves the address, so no stranger can pose as one), and pending from a stranger. A
    stranger's connection can only make room by dropping another stranger's (the oldest of the source holding
    the most), never an operator's; `RESERVED_FOR_OPERATORS` of the `max_connections` slots strangers never
    hold; per source address at most `MAX_UNAUTHENTICATED_PER_SOURCE` pending connections. So the operator's
    session, and each new connection of the operator's PC, stays whatever strangers do from any number of
    addresses.

    :param max_connections: connections held at once.
    :param auth_timeout_s: a connection must send a valid command within this time.
    :param idle_timeout_s: an authenticated connection silent this long is closed.
    :param boot: this start's nonce, announced in the hello and used by the reserved UDP path.
    """

    MAX_UNAUTHENTICATED_PER_SOURCE = 4
    RESERVED_FOR_OPERATORS = 2
    KNOWN_OPERATORS = 64
    REPLY_TIMEOUT_S = 5.0  # a peer whose replies cannot be sent for this long (it never reads) is dropped

    def __init__(
        self,
        handler: Handler,
        token: str,
        *,
        host: str = "0.0.0.0",
        port: int = DEFAULT_PORT,
        max_message_bytes: int = 4096,
        max_connections: int = 16,
        auth_timeout_s: float = 5.0,
        idle_timeout_s: float = 60.0,
        on_valid: Callable[[], None] | None = None,
        on_disarm: Callable[[], None] | None = None,
        on_status: Callable[[], dict[str, Any]] | None = None,
        boot: str | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not token:
            raise ValueError("the command server needs a non-empty token")
        self.handler = handler
        self.token = token
        self.host = host
        self.port = port
        self.max_message_bytes = max_message_bytes
        self.max_connections = max_connections
        self.auth_timeout_s = auth_timeout_s
        self.idle_timeout_s = idle_timeout_s
        self.on_valid = on_valid
        self.on_disarm = on_disarm
        self.on_status = on_status
        self.reply_timeout_s = self.REPLY_TIMEOUT_S
        self.boot = boot or new_boot_nonce()
        self.clock = clock
        self._udp: ReservedListener | None = None
        self._operators: dict[str, None] = {}  # addresses that authenticated, most recent last
        self.connects = 0  # connections accepted by the kernel and seen by the server
        self.rejected = 0
        self.accepted = 0
        self.evicted = 0
        self.timed_out = 0
        self.unread_dropped = 0  # of them: peers that did not read their replies for reply_timeout_s
        self.refused_per_source = 0
        self.log = RateLimitedLog(log)
        self._server: asyncio.Server | None = None
        self._conns: dict[asyncio.Task[None], _Conn] = {}

    @property
    def connections(self) -> int:
        """Connections open now."""
        return len(self._conns)

    async def start(self) -> int:
        """Listen; returns the bound port (useful with port 0).

        The backlog is small on purpose: asyncio accepts up to `backlog` connections per loop turn, so a
        flood cannot exhaust the file descriptors (EMFILE pauses accepting for a second) nor queue
        hundreds of connections ahead of an operator's `disarm`.
        """
        self._server = await asyncio.start_server(
            self._client, self.host, self.port, limit=self.max_message_bytes * 2, backlog=64
        )
        port = int(self._server.sockets[0].getsockname()[1])
        if self.on_disarm is not None:
            try:
                self._udp = ReservedListener.bind(
                    self.host,
                    port,
                    self.token,
                    self.on_disarm,
                    self.on_status or (lambda: {}),
                    self._rejected,
                    boot=self.boot,
                    clock=self.clock,
                )
            except OSError as err:
                log.warning("reserved UDP path unavailable on port %d: %s", port, err)
        return port

    @property
    def udp_disarms(self) -> int:
        """Disarms received over the reserved UDP path."""
        return 0 if self._udp is None else self._udp.disarms

    async def close(self) -> None:
        """Stop listening and drop the connections (quietly: no CancelledError escapes or is logged)."""
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        if self._server is None:
            return
        self._server.close()
        tasks = list(self._conns)
        for t in tasks:
            t.cancel()
        if tasks:
            await asyncio.gather(*tasks, return_exceptions=True)
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self._server.wait_closed(), 1.0)
        self._server = None

    def _unauthenticated_from(self, source: str) -> int:
        return sum(1 for c in self._conns.values() if c.source == source and not c.authenticated)

    def is_operator(self, source: str) -> bool:
        """Whether `source` (an address) authenticated on this server before."""
        return source in self._operators

    def _mark_operator(self, source: str) -> None:
        self._operators.pop(source, None)
        self._operators[source] = None
        while len(self._operators) > self.KNOWN_OPERATORS:
            self._operators.pop(next(iter(self._operators)))

    def _make_room(self, source: str) -> bool:
        """Room for a new connection from `source`, or False (refused; no one else's is dropped): see the class
        docstring. Authenticated connections are never dropped; a stranger drops only strangers."""
        if self._unauthenticated_from(source) >= self.MAX_UNAUTHENTICATED_PER_SOURCE:
            return False
        operator = self.is_operator(source)
        stranger_cap = self.max_connections - self.RESERVED_FOR_OPERATORS

        def pending(strangers: bool) -> list[_Conn]:
            return [c for c in self._conns.values() if not c.authenticated and self.is_operator(c.source) != strangers]

        while True:
            strangers = pending(True)
            if len(self._conns) < self.max_connections and (operator or len(strangers) < stranger_cap):
                return True
            victims = strangers or (pending(False) if operator else [])
            if operator and not strangers:
                victims = [c for c in victims if c.source == source]  # an operator's PC makes room only in its own
            if not victims:
                return False
            counts: dict[str, int] = {}
            for c in victims:
                counts[c.source] = counts.get(c.source, 0) + 1
            victim = min(victims, key=lambda c: (-counts[c.source], c.opened_s))
            self._conns.pop(victim.task, None)
            victim.task.cancel()
            with contextlib.suppress(Exception):
                victim.writer.transport.abort()
            self.evicted += 1
            self.log.warning(
                "command connection from %s dropped to make room (cap %d)", victim.peer, self.max_connections
            )

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        peername = writer.get_extra_info("peername")
        peer = str(peername)
        source = str(peername[0]) if isinstance(peername, tuple) and peername else peer
        self.connects += 1
        if not self._make_room(source):
            self.refused_per_source += 1
            self.log.warning(
                "command connection from %s refused: no room (%d connections; at most %d unauthenticated from %s)",
                peer,
                len(self._conns),
                self.MAX_UNAUTHENTICATED_PER_SOURCE,
                source,
            )
            with contextlib.suppress(Exception):
                writer.transport.abort()
            return
        conn = _Conn(task, writer, peer, source)
        self._conns[task] = conn
        nonce = secrets.token_hex(16)
        last_seq: int | None = None
        buf = b""
        discarding = False
        try:
            await self._reply(writer, {"hello": HELLO, "version": PROTOCOL_VERSION, "nonce": nonce, "boot": self.boot})
            while True:
                timeout = (
                    self.idle_timeout_s
                    if conn.authenticated
                    else max(0.0, conn.opened_s + self.auth_timeout_s - time.monotonic())
                )
                try:
                    chunk = await asyncio.wait_for(reader.read(4096), timeout)
                except TimeoutError:
                    self.timed_out += 1
                    return
                if not chunk:
                    return
                buf += chunk
                while True:
                    nl = buf.find(b"\n")
                    if nl < 0:
                        if len(buf) > self.max_message_bytes:
                            if not discarding:
                                self._rejected(peer, f"message longer than {self.max_message_bytes} bytes")
                                await self._reply(
                                    writer,
                                    {
                                        "ok": False,
                                        "seq": None,
                                        "error": f"message longer than {self.max_message_bytes} bytes",
                                    },
                                )
                            discarding = True
                            buf = b""
                        break
                    line, buf = buf[:nl], buf[nl + 1 :]
                    if discarding:  # the tail of an oversized message
                        discarding = False
                        continue
                    if len(line) > self.max_message_bytes:
                        self._rejected(peer, f"message longer than {self.max_message_bytes} bytes")
                        await self._reply(
                            writer,
                            {"ok": False, "seq": None, "error": f"message longer than {self.max_message_bytes} bytes"},
                        )
                        continue
                    if not line.strip():
                        continue
                    reply, last_seq = await self._handle(line, nonce, last_seq, conn)
                    await self._reply(writer, reply)
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.CancelledError):
            return  # a dropped peer, or shutdown: nothing to report
        except TimeoutError:  # a peer that does not read its replies (drain timed out): drop it quietly
            self.timed_out += 1
            self.unread_dropped += 1
            with contextlib.suppress(Exception):
                writer.transport.abort()
            return
        finally:
            self._conns.pop(task, None)
            with contextlib.suppress(Exception):
                writer.close()

    def _rejected(self, peer: str, reason: str) -> None:
        self.rejected += 1
        self.log.warning("command from %s refused: %s", peer, reason)

    async def _handle(
        self, line: bytes, nonce: str, last_seq: int | None, conn: _Conn
    ) -> tuple[dict[str, Any], int | None]:
        try:
            cmd = parse_command(line, self.token, nonce, last_seq)
        except Rejected as err:
            self._rejected(conn.peer, str(err))
            return {"ok": False, "seq": err.seq, "error": str(err)}, last_seq
        except Exception as err:  # noqa: BLE001 - any input must get a one-line refusal, never a traceback
            self._rejected(conn.peer, f"unreadable message ({type(err).__name__})")
            return {"ok": False, "seq": None, "error": "garbled message"}, last_seq
        conn.authenticated = True
        self._mark_operator(conn.source)
        if self.on_valid is not None:
            self.on_valid()
        try:
            result = await self.handler(cmd)
        except (ValueError, RuntimeError, TimeoutError) as err:
            self._rejected(conn.peer, f"{cmd.cmd}: {err}")
            return {"ok": False, "seq": cmd.seq, "error": f"{cmd.cmd}: {err}"}, cmd.seq
        except Exception as err:  # noqa: BLE001 - a bug must still get a reply, and must not kill the server
            self._rejected(conn.peer, f"{cmd.cmd}: internal error {type(err).__name__}: {err}")
            return {
                "ok": False,
                "seq": cmd.seq,
                "error": f"{cmd.cmd}: internal error {type(err).__name__}: {err}",
            }, cmd.seq
        self.accepted += 1
        return {"ok": True, "seq": cmd.seq, "result": result}, cmd.seq

    async def _reply(self, writer: asyncio.StreamWriter, obj: dict[str, Any]) -> None:
        writer.write(json.dumps(obj, separators=(",", ":"), default=str).encode() + b"\n")
        await asyncio.wait_for(writer.drain(), self.reply_timeout_s)
