"""Remote operation: a TCP command channel authenticated per connection, that holds under abuse.

Wire format: one JSON object per line (UTF-8, `\\n`-terminated, at most `max_message_bytes`).
On connect the robot sends a hello line with a fresh random nonce:

    {"hello": "rimless-robot", "version": 2, "nonce": "<32 hex digits>"}

Every command then carries an HMAC-SHA256 keyed with the shared token (the token itself never
crosses the wire) over the connection's nonce and the command:

    {"seq": 1, "cmd": "arm", "args": {}, "mac": "<64 hex digits>"}
    mac = HMAC-SHA256(token, nonce + "\\n" + json.dumps([seq, cmd, args], sort_keys=True,
                                                         separators=(",", ":"), ensure_ascii=True))

`seq` must increase on the connection. A line captured on one connection fails its MAC on any
other (new nonce), and a replay on the same connection fails the `seq` check. Every line gets
exactly one reply: `{"ok": true, "seq": 1, "result": {...}}` or `{"ok": false, "seq": 1 | null,
"error": "..."}`. A refused message changes nothing.

Abuse limits: at most `max_connections` connections; a connection that has not sent a valid
command within `auth_timeout_s` is closed, so is one idle for `idle_timeout_s`; when the cap is
reached, the oldest connection that never authenticated is dropped to make room, so a new
operator connection (for `disarm` or `status`) always gets in. Rejections are logged at most
`LOG_LINES_PER_S` times per second.

Reserved path for `disarm` and `status`: the same port number on UDP takes one datagram,
`{"disarm": n, "mac": HMAC-SHA256(token, "disarm\\n" + str(n))}` (any integer n; "status" likewise),
served by a thread of its own, and answers `{"ok": true, "n": n, "disarmed": true, "status": {...}}`.
It holds no state per sender, so no number of TCP connections can block it; a replayed disarm can
only disarm, which is always safe, and a replayed status only reads.

Commands: status, ping, arm {stance_leg?}, disarm, set {name, value}, trial_start {name?}, trial_stop.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac
import json
import logging
import secrets
import socket
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from rimless.errors import ParameterError
from rimless.firmware.errors import CommandError, RobotUnreachable

log = logging.getLogger("rimless.robot.commands")

DEFAULT_PORT = 9871
PROTOCOL_VERSION = 2
HELLO = "rimless-robot"
COMMANDS: dict[str, frozenset[str]] = {
    "status": frozenset(),
    "ping": frozenset(),
    "arm": frozenset({"stance_leg"}),
    "disarm": frozenset(),
    "set": frozenset({"name", "value"}),
    "trial_start": frozenset({"name"}),
    "trial_stop": frozenset(),
}
REQUIRED_ARGS: dict[str, frozenset[str]] = {"set": frozenset({"name", "value"})}
_TOP_KEYS = frozenset({"seq", "cmd", "args", "mac"})
MAX_DEPTH = 4  # {"args": {"value": ...}} needs 2; anything deeper is refused
LOG_LINES_PER_S = 5.0
MIN_TOKEN_CHARS = 16
# Values that appeared in examples and tests: never accepted as a real token.
KNOWN_EXAMPLE_TOKENS = frozenset({"change-me", "changeme", "s3cret", "secret", "token", "tok", "bench", "password"})


class WeakToken(ParameterError):
    """The command token is too short or a published example value."""


def check_token(token: str) -> str:
    """Return `token` if it is acceptable for the command channel, else raise `WeakToken` saying why."""
    if token.lower() in KNOWN_EXAMPLE_TOKENS:
        raise WeakToken("the command token is an example value; generate one with `python3 -c "
                        "\"import secrets; print(secrets.token_urlsafe(24))\"`")
    if len(token) < MIN_TOKEN_CHARS:
        raise WeakToken(f"the command token is too short ({len(token)} characters, at least {MIN_TOKEN_CHARS})")
    if len(set(token)) < 6:
        raise WeakToken("the command token repeats too few characters to be secret")
    return token


RESERVED_KINDS = ("disarm", "status")


def reserved_mac(token: str, kind: str, n: int) -> str:
    """HMAC-SHA256 (hex) of a reserved-path datagram: `kind` ("disarm" or "status") and number `n`."""
    return hmac.new(token.encode("utf-8"), f"{kind}\n{n}".encode("ascii"), hashlib.sha256).hexdigest()


def disarm_mac(token: str, n: int) -> str:
    """HMAC-SHA256 (hex) of a reserved-path disarm datagram with number `n`."""
    return reserved_mac(token, "disarm", n)


def parse_reserved_datagram(data: bytes, token: str) -> tuple[str, int]:
    """Validate a reserved-path datagram; return (kind, number) or raise `Rejected`."""
    if len(data) > 512 or _max_depth(data) > 1:
        raise Rejected("reserved datagram: too long or nested")
    try:
        obj = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise Rejected("reserved datagram: not UTF-8 JSON") from None
    kinds = [k for k in RESERVED_KINDS if isinstance(obj, dict) and k in obj]
    if not isinstance(obj, dict) or len(kinds) != 1 or set(obj) != {kinds[0], "mac"}:
        raise Rejected("reserved datagram: expected exactly mac and one of disarm, status")
    kind = kinds[0]
    n, mac = obj[kind], obj["mac"]
    if isinstance(n, bool) or not isinstance(n, int) or not isinstance(mac, str) or not 0 <= n < 2**63:
        raise Rejected(f"reserved datagram: {kind} must be a non-negative integer and mac a string")
    if not hmac.compare_digest(mac.encode("ascii", "replace"), reserved_mac(token, kind, n).encode("ascii")):
        raise Rejected("reserved datagram: bad mac")
    return kind, n


def parse_disarm_datagram(data: bytes, token: str) -> int:
    """Validate a reserved-path disarm datagram; return its number or raise `Rejected`."""
    kind, n = parse_reserved_datagram(data, token)
    if kind != "disarm":
        raise Rejected("reserved datagram: not a disarm")
    return n


class ReservedListener:
    """The reserved path for `disarm` and `status`: a thread of its own on a UDP socket, so neither
    TCP connections nor a busy event loop can delay it. The callbacks run in this thread (they must
    be thread-safe); `on_status` returns a small JSON-able dict."""

    def __init__(self, sock: socket.socket, token: str, on_disarm: Callable[[], None],
                 on_status: Callable[[], dict[str, Any]], on_rejected: Callable[[str, str], None]) -> None:
        self.sock = sock
        self.token = token
        self.on_disarm = on_disarm
        self.on_status = on_status
        self.on_rejected = on_rejected
        self.disarms = 0
        self.statuses = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rimless-reserved", daemon=True)

    @classmethod
    def bind(cls, host: str, port: int, token: str, on_disarm: Callable[[], None],
             on_status: Callable[[], dict[str, Any]], on_rejected: Callable[[str, str], None]) -> ReservedListener:
        """Bind the UDP socket (raises OSError) and start the thread."""
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind((host, port))
            sock.settimeout(0.2)
        except OSError:
            sock.close()
            raise
        listener = cls(sock, token, on_disarm, on_status, on_rejected)
        listener._thread.start()
        return listener

    def _status(self) -> dict[str, Any]:
        try:
            return self.on_status()
        except Exception as err:  # noqa: BLE001 - a racing read must not kill the reserved path
            return {"error": f"{type(err).__name__}: {err}"}

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(4096)
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return  # closed
            try:
                kind, n = parse_reserved_datagram(data, self.token)
            except Rejected as err:
                self.on_rejected(str(addr), str(err))
                continue
            except Exception as err:  # noqa: BLE001 - any datagram gets a log line, never a traceback
                self.on_rejected(str(addr), f"unreadable reserved datagram ({type(err).__name__})")
                continue
            reply: dict[str, Any] = {"ok": True, "n": n}
            try:
                if kind == "disarm":
                    self.on_disarm()
                    self.disarms += 1
                    reply["disarmed"] = True
                else:
                    self.statuses += 1
            finally:
                reply["status"] = self._status()
                with contextlib.suppress(OSError, TypeError, ValueError):
                    self.sock.sendto(json.dumps(reply, default=str).encode(), addr)

    def close(self) -> None:
        """Stop the thread and close the socket."""
        self._stop.set()
        self._thread.join(1.0)
        self.sock.close()


def command_mac(token: str, nonce: str, seq: int, cmd: str, args: dict[str, Any]) -> str:
    """HMAC-SHA256 (hex) of one command under `token`, bound to the connection's `nonce`."""
    body = json.dumps([seq, cmd, args], sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hmac.new(token.encode("utf-8"), f"{nonce}\n{body}".encode("ascii"), hashlib.sha256).hexdigest()


@dataclass(frozen=True, slots=True)
class Command:
    """A validated command."""

    seq: int
    cmd: str
    args: dict[str, Any]


class Rejected(ValueError):
    """A message that is refused; `seq` is echoed when it could be read."""

    def __init__(self, msg: str, seq: int | None = None) -> None:
        super().__init__(msg)
        self.seq = seq


def _check_tree(obj: Any, depth: int = 0) -> None:
    """Refuse deep nesting and strings that are not valid Unicode (lone surrogates)."""
    if depth > MAX_DEPTH:
        raise Rejected(f"message nested deeper than {MAX_DEPTH} levels")
    if isinstance(obj, str):
        try:
            obj.encode("utf-8")
        except UnicodeEncodeError:
            raise Rejected("garbled message: a string is not valid Unicode (lone surrogate)") from None
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _check_tree(k, depth + 1)
            _check_tree(v, depth + 1)
    elif isinstance(obj, list):
        for v in obj:
            _check_tree(v, depth + 1)


def _max_depth(line: bytes) -> int:
    """Bracket nesting depth of a JSON text (outside strings), without recursion."""
    depth = best = 0
    in_str = esc = False
    for b in line:
        if in_str:
            if esc:
                esc = False
            elif b == 0x5C:  # backslash
                esc = True
            elif b == 0x22:
                in_str = False
        elif b == 0x22:
            in_str = True
        elif b in (0x5B, 0x7B):
            depth += 1
            best = max(best, depth)
        elif b in (0x5D, 0x7D):
            depth -= 1
    return best


def parse_command(line: bytes, token: str, nonce: str, last_seq: int | None) -> Command:
    """Validate one line; raise `Rejected` with the reason. Checks run before anything is acted on."""
    if _max_depth(line) > MAX_DEPTH + 1:
        raise Rejected(f"message nested deeper than {MAX_DEPTH} levels")
    try:
        obj = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise Rejected("garbled message: not UTF-8 JSON") from None
    if not isinstance(obj, dict):
        raise Rejected("a message must be a JSON object")
    _check_tree(obj)
    seq = obj.get("seq")
    seq_ok = isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq < 2**63
    echo = seq if seq_ok else None
    if "token" in obj:
        raise Rejected("unauthenticated: clear-text tokens are not accepted; sign with the connection nonce "
                       "(protocol version 2)", echo)
    extra = sorted(set(obj) - _TOP_KEYS)
    if extra:
        raise Rejected(f"unknown field {extra[0]!r}", echo)
    if not seq_ok:
        raise Rejected("seq must be a non-negative integer", None)
    cmd = obj.get("cmd")
    args = obj.get("args", {})
    mac = obj.get("mac")
    if not isinstance(cmd, str) or not isinstance(args, dict) or not isinstance(mac, str):
        raise Rejected("unauthenticated: a message needs cmd (string), args (object) and mac (string)", echo)
    expected = command_mac(token, nonce, seq, cmd, args)
    if not hmac.compare_digest(mac.encode("ascii", "replace"), expected.encode("ascii")):
        raise Rejected("unauthenticated: bad mac (wrong token, or a message replayed from another connection)",
                       echo)
    if last_seq is not None and seq <= last_seq:
        raise Rejected(f"out of order: seq {seq} after {last_seq} (replayed?)", echo)
    if cmd not in COMMANDS:
        raise Rejected(f"unknown command {cmd!r}; known: {', '.join(sorted(COMMANDS))}", echo)
    bad = sorted(set(args) - COMMANDS[cmd])
    if bad:
        raise Rejected(f"{cmd}: unknown argument {bad[0]!r}", echo)
    missing = sorted(REQUIRED_ARGS.get(cmd, frozenset()) - set(args))
    if missing:
        raise Rejected(f"{cmd}: missing argument {missing[0]!r}", echo)
    return Command(seq, cmd, args)


class RateLimitedLog:
    """Logs at most `per_s` lines per second; the rest are counted and summarised in the next line."""

    def __init__(self, logger: logging.Logger, per_s: float = LOG_LINES_PER_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
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
    __slots__ = ("task", "writer", "opened_s", "authenticated", "peer")

    def __init__(self, task: asyncio.Task[None], writer: asyncio.StreamWriter, peer: str) -> None:
        self.task = task
        self.writer = writer
        self.opened_s = time.monotonic()
        self.authenticated = False
        self.peer = peer


class CommandServer:
    """asyncio TCP server; `handler` executes a validated command or raises ValueError/RuntimeError.

    :param max_connections: connections held at once (new ones evict the oldest unauthenticated).
    :param auth_timeout_s: a connection must send a valid command within this time.
    :param idle_timeout_s: an authenticated connection silent this long is closed.
    """

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
        self._udp: ReservedListener | None = None
        self.rejected = 0
        self.accepted = 0
        self.evicted = 0
        self.timed_out = 0
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
        self._server = await asyncio.start_server(self._client, self.host, self.port,
                                                  limit=self.max_message_bytes * 2, backlog=64)
        port = int(self._server.sockets[0].getsockname()[1])
        if self.on_disarm is not None:
            try:
                self._udp = ReservedListener.bind(self.host, port, self.token, self.on_disarm,
                                                  self.on_status or (lambda: {}), self._rejected)
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

    def _make_room(self) -> None:
        """At the cap: drop the oldest connection that never authenticated (else the oldest one)."""
        while len(self._conns) >= self.max_connections:
            conns = sorted(self._conns.values(), key=lambda c: (c.authenticated, c.opened_s))
            victim = conns[0]
            self._conns.pop(victim.task, None)
            victim.task.cancel()
            with contextlib.suppress(Exception):
                victim.writer.transport.abort()
            self.evicted += 1
            self.log.warning("command connection from %s dropped to make room (cap %d)", victim.peer,
                             self.max_connections)

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        peer = str(writer.get_extra_info("peername"))
        self._make_room()
        conn = _Conn(task, writer, peer)
        self._conns[task] = conn
        nonce = secrets.token_hex(16)
        last_seq: int | None = None
        buf = b""
        discarding = False
        try:
            await self._reply(writer, {"hello": HELLO, "version": PROTOCOL_VERSION, "nonce": nonce})
            while True:
                timeout = self.idle_timeout_s if conn.authenticated else \
                    max(0.0, conn.opened_s + self.auth_timeout_s - time.monotonic())
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
                                await self._reply(writer, {"ok": False, "seq": None,
                                                           "error": f"message longer than {self.max_message_bytes} bytes"})
                            discarding = True
                            buf = b""
                        break
                    line, buf = buf[:nl], buf[nl + 1 :]
                    if discarding:  # the tail of an oversized message
                        discarding = False
                        continue
                    if len(line) > self.max_message_bytes:
                        self._rejected(peer, f"message longer than {self.max_message_bytes} bytes")
                        await self._reply(writer, {"ok": False, "seq": None,
                                                   "error": f"message longer than {self.max_message_bytes} bytes"})
                        continue
                    if not line.strip():
                        continue
                    reply, last_seq = await self._handle(line, nonce, last_seq, conn)
                    await self._reply(writer, reply)
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.CancelledError):
            return  # a dropped peer, or shutdown: nothing to report
        finally:
            self._conns.pop(task, None)
            with contextlib.suppress(Exception):
                writer.close()

    def _rejected(self, peer: str, reason: str) -> None:
        self.rejected += 1
        self.log.warning("command from %s refused: %s", peer, reason)

    async def _handle(self, line: bytes, nonce: str, last_seq: int | None,
                      conn: _Conn) -> tuple[dict[str, Any], int | None]:
        try:
            cmd = parse_command(line, self.token, nonce, last_seq)
        except Rejected as err:
            self._rejected(conn.peer, str(err))
            return {"ok": False, "seq": err.seq, "error": str(err)}, last_seq
        except Exception as err:  # noqa: BLE001 - any input must get a one-line refusal, never a traceback
            self._rejected(conn.peer, f"unreadable message ({type(err).__name__})")
            return {"ok": False, "seq": None, "error": "garbled message"}, last_seq
        conn.authenticated = True
        if self.on_valid is not None:
            self.on_valid()
        try:
            result = await self.handler(cmd)
        except (ValueError, RuntimeError, TimeoutError) as err:
            self._rejected(conn.peer, f"{cmd.cmd}: {err}")
            return {"ok": False, "seq": cmd.seq, "error": f"{cmd.cmd}: {err}"}, cmd.seq
        except Exception as err:  # noqa: BLE001 - a bug must still get a reply, and must not kill the server
            self._rejected(conn.peer, f"{cmd.cmd}: internal error {type(err).__name__}: {err}")
            return {"ok": False, "seq": cmd.seq, "error": f"{cmd.cmd}: internal error {type(err).__name__}: {err}"}, cmd.seq
        self.accepted += 1
        return {"ok": True, "seq": cmd.seq, "result": result}, cmd.seq

    @staticmethod
    async def _reply(writer: asyncio.StreamWriter, obj: dict[str, Any]) -> None:
        writer.write(json.dumps(obj, separators=(",", ":"), default=str).encode() + b"\n")
        await asyncio.wait_for(writer.drain(), 5.0)


class RobotLink:
    """PC side: one authenticated connection to the robot; `call` sends a signed command.

    Raises `RobotUnreachable` (bad host, refused, timeout, dropped) or `CommandError` (refused).
    """

    def __init__(self, host: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 3.0) -> None:
        self.host, self.port, self.timeout_s = host, port, timeout_s
        self._token = token
        self._seq = 0
        self._buf = b""
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout_s)
        except socket.gaierror as err:
            raise RobotUnreachable(f"robot host {host!r} cannot be resolved ({err.strerror})") from None
        except (TimeoutError, socket.timeout):
            raise RobotUnreachable(f"no answer from {host}:{port} within {timeout_s} s") from None
        except OSError as err:
            raise RobotUnreachable(f"cannot reach the robot at {host}:{port} ({err.strerror or err})") from None
        try:
            hello = self._read_obj()
        except BaseException:
            self.sock.close()
            raise
        nonce = hello.get("nonce")
        if hello.get("hello") != HELLO or not isinstance(nonce, str):
            self.sock.close()
            raise CommandError(f"{host}:{port} is not a rimless robot (protocol version {PROTOCOL_VERSION})")
        self.nonce = nonce

    def _read_obj(self) -> dict[str, Any]:
        try:
            while b"\n" not in self._buf:
                chunk = self.sock.recv(65536)
                if not chunk:
                    raise RobotUnreachable(f"the robot at {self.host}:{self.port} closed the connection")
                self._buf += chunk
        except (TimeoutError, socket.timeout):
            raise RobotUnreachable(f"no answer from {self.host}:{self.port} within {self.timeout_s} s") from None
        except OSError as err:
            if isinstance(err, RobotUnreachable):
                raise
            raise RobotUnreachable(f"connection to {self.host}:{self.port} lost ({err.strerror or err})") from None
        line, self._buf = self._buf.split(b"\n", 1)
        try:
            obj = json.loads(line)
        except ValueError:
            raise CommandError(f"garbled reply from {self.host}:{self.port}") from None
        if not isinstance(obj, dict):
            raise CommandError(f"garbled reply from {self.host}:{self.port}")
        return obj

    def call(self, cmd: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Send one command and return its `result`."""
        self._seq += 1
        args = args or {}
        msg = {"seq": self._seq, "cmd": cmd, "args": args,
               "mac": command_mac(self._token, self.nonce, self._seq, cmd, args)}
        try:
            self.sock.sendall(json.dumps(msg).encode() + b"\n")
        except OSError as err:
            raise RobotUnreachable(f"connection to {self.host}:{self.port} lost ({err.strerror or err})") from None
        reply = self._read_obj()
        if "ok" not in reply:
            raise CommandError(f"garbled reply from {self.host}:{self.port}")
        if not reply["ok"]:
            raise CommandError(f"robot refused {cmd}: {reply.get('error')}")
        result = reply.get("result")
        return result if isinstance(result, dict) else {"result": result}

    def close(self) -> None:
        """Close the connection."""
        with contextlib.suppress(OSError):
            self.sock.close()

    def __enter__(self) -> RobotLink:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def send_reserved_datagram(host: str, kind: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 1.0,
                           copies: int = 3) -> dict[str, Any]:
    """PC side: `disarm` or `status` over the reserved UDP path; returns the robot's answer.

    Sends up to `copies` datagrams (UDP may drop one), waiting `timeout_s / copies` for an answer
    after each. Raises `RobotUnreachable` when none comes.
    """
    n = secrets.randbits(62)
    data = json.dumps({kind: n, "mac": reserved_mac(token, kind, n)}).encode()
    try:
        info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
    except socket.gaierror as err:
        raise RobotUnreachable(f"robot host {host!r} cannot be resolved ({err.strerror})") from None
    with socket.socket(info[0], socket.SOCK_DGRAM) as sock:
        sock.settimeout(timeout_s / copies)
        for _ in range(copies):
            try:
                sock.sendto(data, info[4])
                reply, _ = sock.recvfrom(65536)
            except (TimeoutError, socket.timeout, ConnectionRefusedError):
                continue
            except OSError as err:
                raise RobotUnreachable(f"cannot reach the robot at {host}:{port} ({err.strerror or err})") from None
            try:
                obj = json.loads(reply)
            except ValueError:
                continue
            if isinstance(obj, dict) and obj.get("ok") and obj.get("n") == n:
                return obj
    raise RobotUnreachable(f"no answer to the UDP {kind} from {host}:{port} within {timeout_s} s")


def send_disarm_datagram(host: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 1.0,
                         copies: int = 3) -> dict[str, Any]:
    """PC side: disarm over the reserved UDP path (see `send_reserved_datagram`)."""
    return send_reserved_datagram(host, "disarm", token=token, port=port, timeout_s=timeout_s, copies=copies)


def send_command(
    host: str, cmd: str, args: dict[str, Any] | None = None, *, token: str, port: int = DEFAULT_PORT,
    timeout_s: float = 3.0,
) -> dict[str, Any]:
    """PC side: send one command on a fresh connection and return its `result`.

    Raises `RobotUnreachable` (bad host, refused, timeout) or `CommandError` (the robot refused).
    """
    with RobotLink(host, token=token, port=port, timeout_s=timeout_s) as link:
        return link.call(cmd, args)
