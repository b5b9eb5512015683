"""Remote operation: a TCP command channel with a shared token and strict validation.

Wire format: one JSON object per line (UTF-8, `\\n`-terminated, at most `max_message_bytes`):

    {"token": "...", "seq": 1, "cmd": "arm", "args": {}}

`seq` is an integer that must increase on each connection (a replayed or reordered message is
refused). Every line gets exactly one reply line: `{"ok": true, "seq": 1, "result": {...}}` or
`{"ok": false, "seq": 1 | null, "error": "..."}`. A refused message changes nothing.

Commands: status, ping, arm, disarm, set {name, value}, trial_start {name?}, trial_stop.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import socket
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from rimless.firmware.errors import CommandError, RobotUnreachable

DEFAULT_PORT = 9871
COMMANDS: dict[str, frozenset[str]] = {
    "status": frozenset(),
    "ping": frozenset(),
    "arm": frozenset(),
    "disarm": frozenset(),
    "set": frozenset({"name", "value"}),
    "trial_start": frozenset({"name"}),
    "trial_stop": frozenset(),
}
REQUIRED_ARGS: dict[str, frozenset[str]] = {"set": frozenset({"name", "value"})}
_TOP_KEYS = frozenset({"token", "seq", "cmd", "args"})


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


def parse_command(line: bytes, token: str, last_seq: int | None) -> Command:
    """Validate one line; raise `Rejected` with the reason. Checks run before anything is acted on."""
    try:
        obj = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise Rejected("garbled message: not UTF-8 JSON") from None
    if not isinstance(obj, dict):
        raise Rejected("a message must be a JSON object")
    seq = obj.get("seq")
    seq_ok = isinstance(seq, int) and not isinstance(seq, bool) and 0 <= seq < 2**63
    echo = seq if seq_ok else None
    tok = obj.get("token")
    if not isinstance(tok, str) or not hmac.compare_digest(tok.encode(), token.encode()):
        raise Rejected("unauthenticated: missing or wrong token", echo)
    extra = sorted(set(obj) - _TOP_KEYS)
    if extra:
        raise Rejected(f"unknown field {extra[0]!r}", echo)
    if not seq_ok:
        raise Rejected("seq must be a non-negative integer", None)
    if last_seq is not None and seq <= last_seq:
        raise Rejected(f"out of order: seq {seq} after {last_seq}", echo)
    cmd = obj.get("cmd")
    if not isinstance(cmd, str) or cmd not in COMMANDS:
        raise Rejected(f"unknown command {cmd!r}; known: {', '.join(sorted(COMMANDS))}", echo)
    args = obj.get("args", {})
    if not isinstance(args, dict):
        raise Rejected("args must be an object", echo)
    bad = sorted(set(args) - COMMANDS[cmd])
    if bad:
        raise Rejected(f"{cmd}: unknown argument {bad[0]!r}", echo)
    missing = sorted(REQUIRED_ARGS.get(cmd, frozenset()) - set(args))
    if missing:
        raise Rejected(f"{cmd}: missing argument {missing[0]!r}", echo)
    return Command(seq, cmd, args)


Handler = Callable[[Command], Awaitable[dict[str, Any]]]


class CommandServer:
    """asyncio TCP server; `handler` executes a validated command or raises ValueError/RuntimeError."""

    def __init__(
        self,
        handler: Handler,
        token: str,
        *,
        host: str = "0.0.0.0",
        port: int = DEFAULT_PORT,
        max_message_bytes: int = 4096,
        on_valid: Callable[[], None] | None = None,
    ) -> None:
        if not token:
            raise ValueError("the command server needs a non-empty token")
        self.handler = handler
        self.token = token
        self.host = host
        self.port = port
        self.max_message_bytes = max_message_bytes
        self.on_valid = on_valid
        self.rejected = 0
        self.accepted = 0
        self._server: asyncio.Server | None = None
        self._conns: set[asyncio.Task[None]] = set()

    async def start(self) -> int:
        """Listen; returns the bound port (useful with port 0)."""
        self._server = await asyncio.start_server(self._client, self.host, self.port, limit=self.max_message_bytes * 2)
        return int(self._server.sockets[0].getsockname()[1])

    async def close(self) -> None:
        """Stop listening and drop the connections."""
        if self._server is not None:
            self._server.close()
            for t in list(self._conns):
                t.cancel()
            for t in list(self._conns):
                try:
                    await t
                except (asyncio.CancelledError, Exception):
                    pass
            await self._server.wait_closed()
            self._server = None

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._conns.add(task)
        last_seq: int | None = None
        buf = b""
        discarding = False
        try:
            while True:
                chunk = await reader.read(4096)
                if not chunk:
                    return
                buf += chunk
                while True:
                    nl = buf.find(b"\n")
                    if nl < 0:
                        if len(buf) > self.max_message_bytes:
                            if not discarding:
                                await self._reply(writer, {"ok": False, "seq": None,
                                                           "error": f"message longer than {self.max_message_bytes} bytes"})
                                self.rejected += 1
                            discarding = True
                            buf = b""
                        break
                    line, buf = buf[:nl], buf[nl + 1 :]
                    if discarding:  # the tail of an oversized message
                        discarding = False
                        continue
                    if len(line) > self.max_message_bytes:
                        self.rejected += 1
                        await self._reply(writer, {"ok": False, "seq": None,
                                                   "error": f"message longer than {self.max_message_bytes} bytes"})
                        continue
                    if not line.strip():
                        continue
                    reply, last_seq = await self._handle(line, last_seq)
                    await self._reply(writer, reply)
        except (ConnectionError, asyncio.IncompleteReadError):
            return
        finally:
            self._conns.discard(task)
            writer.close()

    async def _handle(self, line: bytes, last_seq: int | None) -> tuple[dict[str, Any], int | None]:
        try:
            cmd = parse_command(line, self.token, last_seq)
        except Rejected as err:
            self.rejected += 1
            return {"ok": False, "seq": err.seq, "error": str(err)}, last_seq
        if self.on_valid is not None:
            self.on_valid()
        try:
            result = await self.handler(cmd)
        except (ValueError, RuntimeError, TimeoutError) as err:
            self.rejected += 1
            return {"ok": False, "seq": cmd.seq, "error": f"{cmd.cmd}: {err}"}, cmd.seq
        except Exception as err:  # a bug must still get a reply, and must not kill the server
            self.rejected += 1
            return {"ok": False, "seq": cmd.seq, "error": f"{cmd.cmd}: internal error {type(err).__name__}: {err}"}, cmd.seq
        self.accepted += 1
        return {"ok": True, "seq": cmd.seq, "result": result}, cmd.seq

    @staticmethod
    async def _reply(writer: asyncio.StreamWriter, obj: dict[str, Any]) -> None:
        writer.write(json.dumps(obj, separators=(",", ":"), default=str).encode() + b"\n")
        await writer.drain()


def send_command(
    host: str, cmd: str, args: dict[str, Any] | None = None, *, token: str, port: int = DEFAULT_PORT,
    timeout_s: float = 3.0,
) -> dict[str, Any]:
    """PC side: send one command on a fresh connection and return its `result`.

    Raises `RobotUnreachable` (bad host, refused, timeout) or `CommandError` (the robot refused).
    """
    msg = {"token": token, "seq": 1, "cmd": cmd, "args": args or {}}
    try:
        with socket.create_connection((host, port), timeout=timeout_s) as sock:
            sock.sendall(json.dumps(msg).encode() + b"\n")
            data = b""
            while not data.endswith(b"\n"):
                chunk = sock.recv(65536)
                if not chunk:
                    break
                data += chunk
    except socket.gaierror as err:
        raise RobotUnreachable(f"robot host {host!r} cannot be resolved ({err.strerror})") from None
    except (TimeoutError, socket.timeout):
        raise RobotUnreachable(f"no answer from {host}:{port} within {timeout_s} s") from None
    except OSError as err:
        raise RobotUnreachable(f"cannot reach the robot at {host}:{port} ({err.strerror or err})") from None
    try:
        reply = json.loads(data)
    except ValueError:
        raise CommandError(f"garbled reply from {host}:{port}") from None
    if not isinstance(reply, dict) or "ok" not in reply:
        raise CommandError(f"garbled reply from {host}:{port}")
    if not reply["ok"]:
        raise CommandError(f"robot refused {cmd}: {reply.get('error')}")
    result = reply.get("result")
    return result if isinstance(result, dict) else {"result": result}
