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
    RESERVED_PAD_BYTES,
    command_mac,
    reserved_counter,
    reserved_mac,
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
        self.nonce = nonce

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


def send_reserved_datagram(
    host: str, kind: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 1.0, copies: int = 5
) -> dict[str, Any]:
    """PC side: `disarm` or `status` over the reserved UDP path; returns the robot's answer.

    Sends up to `copies` datagrams (UDP may drop one: a flood can fill the robot's socket buffer), each with
    a new number, the next one `RESEND_FIRST_S` after the first and then twice as long each time, the last
    waiting for what is left of `timeout_s`; an answer to any of them counts. Raises `RobotUnreachable` when
    none comes.
    """
    try:
        info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
    except socket.gaierror as err:
        raise RobotUnreachable(f"robot host {host!r} cannot be resolved ({err.strerror})") from None
    sent: set[int] = set()
    deadline = time.monotonic() + timeout_s
    with socket.socket(info[0], socket.SOCK_DGRAM) as sock:
        for k in range(copies):
            n = max(reserved_counter(), max(sent, default=0) + 1)  # every copy a new number (no replay)
            sent.add(n)
            body: dict[str, Any] = {kind: n, "mac": reserved_mac(token, kind, n)}
            body["pad"] = "x" * max(0, RESERVED_PAD_BYTES - len(json.dumps(body)) - 10)  # room for the answer
            until = deadline if k == copies - 1 else min(deadline, time.monotonic() + RESEND_FIRST_S * 2**k)
            try:
                sock.sendto(json.dumps(body).encode(), info[4])
            except ConnectionRefusedError:
                continue
            except OSError as err:
                raise RobotUnreachable(f"cannot reach the robot at {host}:{port} ({err.strerror or err})") from None
            while (left := until - time.monotonic()) > 0:
                sock.settimeout(left)
                try:
                    reply, _ = sock.recvfrom(65536)
                except (TimeoutError, ConnectionRefusedError):
                    break
                except OSError as err:
                    raise RobotUnreachable(f"cannot reach the robot at {host}:{port} ({err.strerror or err})") from None
                try:
                    obj = json.loads(reply)
                except ValueError:
                    continue
                if isinstance(obj, dict) and obj.get("ok") and obj.get("n") in sent:
                    return obj
    raise RobotUnreachable(f"no answer to the UDP {kind} from {host}:{port} within {timeout_s} s")


def send_disarm_datagram(
    host: str, *, token: str, port: int = DEFAULT_PORT, timeout_s: float = 1.0, copies: int = 5
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
