"""The PC side of the command channel: one signed command on a fresh connection (`send_command`), a
held connection (`RobotLink`), and the reserved UDP path (`send_reserved_datagram`), plus the two
requests that use both paths: `robot_status` and `robot_disarm`.

Raises `RobotUnreachable` (bad host, refused, timeout, dropped) or `CommandError` (the robot refused).
"""

from __future__ import annotations

import contextlib
import json
import socket
import time
from typing import Any

from rimless.firmware.errors import CommandError, RobotUnreachable
from rimless.firmware.link.protocol import (
    DEFAULT_PORT,
    HELLO,
    PROTOCOL_VERSION,
    check_reply,
    command_mac,
    new_client_nonce,
    reserved_request,
)


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
        except TimeoutError:
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
        if hello.get("version") != PROTOCOL_VERSION:
            self.sock.close()
            raise CommandError(
                f"the robot at {host}:{port} speaks protocol version {hello.get('version')}, this PC version "
                f"{PROTOCOL_VERSION}: install the same rimless release on both (see CHANGELOG.md)"
            )
        self.nonce = nonce
        self.boot = hello.get("boot")

    def _read_obj(self) -> dict[str, Any]:
        try:
            while b"\n" not in self._buf:
                chunk = self.sock.recv(65536)
                if not chunk:
                    raise RobotUnreachable(f"the robot at {self.host}:{self.port} closed the connection")
                self._buf += chunk
        except TimeoutError:
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
        msg = {
            "seq": self._seq,
            "cmd": cmd,
            "args": args,
            "mac": command_mac(self._token, self.nonce, self._seq, cmd, args),
        }
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


RESEND_FIRST_S = 0.05  # the reserved path's first resend, then doubling: a dropped copy costs 50 ms, not 1/3 s
RESEND_MAX_S = 0.2  # and at least every 0.2 s until the deadline: under a flood each copy is a new chance


def send_reserved_datagram(
    host: str, kind: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 1.0, copies: int = 20
) -> dict[str, Any]:
    """PC side: `disarm` or `status` over the reserved UDP path (challenge and response, see `protocol`);
    returns the robot's authenticated answer with the status.

    The first request carries no challenge: a disarm is acted on at once, and the robot's signed answer (bound
    to this request's random nonce) says so and brings its challenge; the second, a status, answers the
    challenge and gets the status. Up to `copies` datagrams per round (UDP may drop one: a flood can fill the robot's socket
    buffer), each with a new nonce, the next one `RESEND_FIRST_S` after the first and then twice as long up to
    `RESEND_MAX_S`, the last waiting for what is left of `timeout_s`; only answers whose MAC holds count. Neither this PC's clock
    nor any earlier datagram matters. Raises `RobotUnreachable` when the robot does not answer; a disarm
    answered without its status (the second round lost) returns that answer (`"disarmed": true`).
    """
    try:
        info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
    except socket.gaierror as err:
        raise RobotUnreachable(f"robot host {host!r} cannot be resolved ({err.strerror})") from None
    deadline = time.monotonic() + timeout_s
    with socket.socket(info[0], socket.SOCK_DGRAM) as sock:
        first = _round(sock, info[4], token, kind, None, deadline, copies)
        if first is None:
            raise RobotUnreachable(f"no answer to the UDP {kind} from {host}:{port} within {timeout_s} s")
        if "status" in first:
            return first
        challenge = first.get("challenge") if isinstance(first.get("challenge"), dict) else {}
        second = _round(sock, info[4], token, "status", challenge, deadline, copies)  # a disarm is done: read
    if second is not None and "status" in second:
        return {**second, "disarmed": True} if kind == "disarm" else second
    if kind == "disarm":
        return first  # acted on and confirmed; the status did not come back in time
    raise RobotUnreachable(f"no status in the answers to the UDP {kind} from {host}:{port} within {timeout_s} s")


def _round(
    sock: socket.socket,
    address: Any,
    token: str,
    kind: str,
    challenge: dict[str, Any] | None,
    deadline: float,
    copies: int,
) -> dict[str, Any] | None:
    """Send up to `copies` requests (each a new nonce) until one is answered; the answer, or None."""
    sent: dict[str, None] = {}
    boot = challenge.get("boot") if challenge else None
    t = challenge.get("t") if challenge else None
    for k in range(copies):
        nonce = new_client_nonce()
        sent[nonce] = None
        data = reserved_request(
            token, kind, nonce, boot if isinstance(boot, str) else None, t if isinstance(t, int) else None
        )
        wait_s = min(RESEND_MAX_S, RESEND_FIRST_S * 2**k)
        until = deadline if k == copies - 1 else min(deadline, time.monotonic() + wait_s)
        try:
            sock.sendto(data, address)
        except ConnectionRefusedError:
            continue
        except OSError as err:
            raise RobotUnreachable(f"cannot reach the robot at {address} ({err.strerror or err})") from None
        while (left := until - time.monotonic()) > 0:
            sock.settimeout(left)
            try:
                reply, _ = sock.recvfrom(65536)
            except (TimeoutError, ConnectionRefusedError):
                break
            except OSError as err:
                raise RobotUnreachable(f"cannot reach the robot at {address} ({err.strerror or err})") from None
            for n in sent:
                obj = check_reply(token, reply, n)
                if obj is not None:
                    return obj
        if time.monotonic() >= deadline:
            break
    return None


def send_disarm_datagram(
    host: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 1.0, copies: int = 20
) -> dict[str, Any]:
    """PC side: disarm over the reserved UDP path (see `send_reserved_datagram`)."""
    return send_reserved_datagram(host, "disarm", token=token, port=port, timeout_s=timeout_s, copies=copies)


def send_command(
    host: str,
    cmd: str,
    args: dict[str, Any] | None = None,
    *,
    token: str,
    port: int = DEFAULT_PORT,
    timeout_s: float = 3.0,
) -> dict[str, Any]:
    """PC side: send one command on a fresh connection and return its `result`.

    Raises `RobotUnreachable` (bad host, refused, timeout) or `CommandError` (the robot refused).
    """
    with RobotLink(host, token=token, port=port, timeout_s=timeout_s) as link:
        return link.call(cmd, args)


def robot_status(host: str, *, token: str, port: int = DEFAULT_PORT, udp_timeout_s: float = 0.5) -> dict[str, Any]:
    """The robot's full status over TCP; when TCP does not answer, the short status of the reserved UDP
    path (armed, faults, engaged clutches) with "via": "udp" and "tcp_error". Raises the TCP error when
    neither answers."""
    try:
        return send_command(host, "status", token=token, port=port)
    except RobotUnreachable as err:
        try:
            reply = send_reserved_datagram(host, "status", token=token, port=port, timeout_s=udp_timeout_s)
        except RobotUnreachable:
            raise err from None
        return {**reply.get("status", {}), "via": "udp", "tcp_error": str(err)}


def robot_disarm(host: str, *, token: str, port: int = DEFAULT_PORT, udp_timeout_s: float = 0.5) -> dict[str, Any]:
    """Disarm over the reserved UDP path first (no connection to wait for), then confirm over TCP.

    Returns the robot's state from TCP, or {"armed": False, "disarmed_via": "udp", "tcp_error": ...}
    when only the UDP disarm was answered. Raises `RobotUnreachable` when neither path answers.
    """
    try:
        send_disarm_datagram(host, token=token, port=port, timeout_s=udp_timeout_s)
        udp_ok = True
    except RobotUnreachable:
        udp_ok = False
    try:
        return send_command(host, "disarm", token=token, port=port)
    except RobotUnreachable as err:
        if not udp_ok:
            raise
        return {"armed": False, "disarmed_via": "udp", "tcp_error": str(err)}
