"""LAN telemetry: batched JSON over UDP that PlotJuggler's "UDP Server" plots without configuration.

Each datagram is a JSON array of samples (PlotJuggler >= 3.16 parses every element as its own sample)
or, with `batch = false`, one object (older PlotJuggler). Every object has a numeric `timestamp` in
epoch seconds and nested numeric fields (`leg/velocity_m_s`, `sensor/squal`, ...); events and faults
are objects with numeric codes, since PlotJuggler ignores strings. Datagrams stay under
`max_datagram_bytes` (default 1200, below the Ethernet MTU; an old PlotJuggler read 2048 at most).
Sending is non-blocking: with nobody listening, datagrams are dropped and counted, never waited on.

Authentication (protocol version 3): with the command token, every datagram ends with a tag,

    [obj, ..., obj, {"timestamp": T, "rimless_auth": "3.<boot nonce>.<mac>"}]     (batch)
    {..., "rimless_auth": "3.<boot nonce>.<mac>"}                                 (one object)

mac = the first 16 bytes (hex) of HMAC-SHA256(key, the datagram's bytes before the tag), key =
HMAC-SHA256(token, "rimless telemetry\n" + boot nonce): a key per start of the robot, the token never on the
wire. PlotJuggler ignores the tag (a string); `verify_datagram` checks it and gives back the datagram without
it. A receiver with the token accepts only what the robot sent, from any address, and tells the robot's starts
apart by the nonce.
"""

from __future__ import annotations

import hmac
import json
import re
import secrets
import socket
import time
from collections.abc import Iterable, Iterator
from typing import Any

from rimless.firmware.control.controller import EventRecord, Record, SampleRecord
from rimless.firmware.control.faults import Fault

EVENT_CODES = {
    "touchdown": 1,
    "lock": 2,
    "release": 3,
    "no_zero_crossing": 4,
    "arm": 5,
    "disarm": 6,
    "param": 7,
    "trial_start": 8,
    "trial_stop": 9,
    "stop": 10,
    "fault": 11,
    "sync_lost": 12,
    "lock_unsynced": 13,
    "signal": 14,
    "lock_withheld": 15,
    "log_degraded": 16,
    "touchdown_dismissed": 17,
}


class WallClock:
    """Maps `monotonic_ns` to epoch seconds (PlotJuggler aligns on wall time)."""

    def __init__(self) -> None:
        self.offset_s = time.time() - time.monotonic_ns() * 1e-9

    def epoch_s(self, t_ns: int) -> float:
        """Epoch seconds of a monotonic timestamp."""
        return round(self.offset_s + t_ns * 1e-9, 6)


def record_to_json(rec: Record, clock: WallClock) -> dict[str, Any]:
    """The JSON object of one record (also the trial-log line)."""
    if isinstance(rec, SampleRecord):
        return {
            "timestamp": clock.epoch_s(rec.t_ns),
            "t_mono_s": round(rec.t_ns * 1e-9, 6),
            "seq": rec.seq,
            "ch": rec.channel,
            "leg": {
                "position_m": round(rec.position_m, 7),
                "velocity_m_s": round(rec.velocity_m_s, 5),
                "compression_m": round(rec.compression_m, 7),
                "phase": rec.phase,
                "stance": rec.stance_leg,
                "clutch_mask": rec.clutch_mask,
            },
            # the same leg values again under the stance leg's own name: one PlotJuggler series per leg
            f"leg{rec.stance_leg}": {
                "velocity_m_s": round(rec.velocity_m_s, 5),
                "compression_m": round(rec.compression_m, 7),
                "phase": rec.phase,
            },
            "sensor": {"squal": rec.squal, "shutter": rec.shutter, "max_pixel": rec.max_pixel},
            "loop": {"armed": int(rec.armed), "latency_ms": round(rec.latency_ns * 1e-6, 4)},
        }
    assert isinstance(rec, EventRecord)
    body: dict[str, Any] = dict(rec.fields)
    body["name"] = rec.name  # never overridden by a field
    body["code"] = EVENT_CODES.get(rec.name, 0)
    if rec.name == "fault":
        body["fault_code"] = Fault(rec.fields["fault"]).code
    return {"timestamp": clock.epoch_s(rec.t_ns), "t_mono_s": round(rec.t_ns * 1e-9, 6), "event": body}


AUTH_VERSION = 3
AUTH_TAG_BYTES = 128  # room the tag takes at most (a batch's tag with a 20-digit timestamp: about 110 bytes)
_BATCH_TAIL = re.compile(rb',\{"timestamp":[-0-9.eE+]{1,24},"rimless_auth":"3\.([0-9a-f]{32})\.([0-9a-f]{32})"\}\]')
_SINGLE_TAIL = re.compile(rb',"rimless_auth":"3\.([0-9a-f]{32})\.([0-9a-f]{32})"\}')


def telemetry_key(token: str, boot: str) -> bytes:
    """The telemetry key of one start of the robot: HMAC-SHA256(token, "rimless telemetry\\n" + boot)."""
    return hmac.digest(token.encode("utf-8"), b"rimless telemetry\n" + boot.encode("ascii"), "sha256")


def _tag_mac(key: bytes, signed: bytes) -> bytes:
    return hmac.digest(key, signed, "sha256")[:16].hex().encode()


def sign_datagram(data: bytes, key: bytes, boot: str) -> bytes:
    """`data` (a batch `[...]` or one object `{...}`, as `pack_datagrams` makes them) with its tag appended."""
    if data.startswith(b"["):
        body = data[:-1]
        ts = re.search(rb'"timestamp":([-0-9.eE+]{1,24})', body)
        t = ts.group(1) if ts else b"0"
        return (
            body + b',{"timestamp":' + t + b',"rimless_auth":"3.' + boot.encode() + b"." + _tag_mac(key, body) + b'"}]'
        )
    body = data[:-1]
    return body + b',"rimless_auth":"3.' + boot.encode() + b"." + _tag_mac(key, body) + b'"}'


def has_tag(data: bytes) -> bool:
    """Whether `data` ends with a telemetry tag (not checked: anyone can write one)."""
    i = data.rfind(b',{"timestamp":') if data.endswith(b"]") else data.rfind(b',"rimless_auth":"')
    pattern = _BATCH_TAIL if data.endswith(b"]") else _SINGLE_TAIL
    return i > 0 and pattern.fullmatch(data, i) is not None


def strip_tag(data: bytes) -> bytes:
    """`data` without its tag (unchecked), or `data` as it is when it has none."""
    if not has_tag(data):
        return data
    if data.endswith(b"]"):
        return data[: data.rfind(b',{"timestamp":')] + b"]"
    return data[: data.rfind(b',"rimless_auth":"')] + b"}"


def verify_datagram(data: bytes, key_for: Any) -> tuple[str, bytes] | str:
    """(boot nonce, the datagram without its tag) if its tag holds under `key_for(boot)` (the key of that start),
    else why not (a string)."""
    batch = data.endswith(b"]")
    i = data.rfind(b',{"timestamp":') if batch else data.rfind(b',"rimless_auth":"')
    m = (_BATCH_TAIL if batch else _SINGLE_TAIL).fullmatch(data, i) if i > 0 else None
    if m is None:
        return "no authentication tag (a robot before protocol version 3, or not the robot)"
    boot, mac = m.group(1).decode(), m.group(2)
    if not hmac.compare_digest(_tag_mac(key_for(boot), data[:i]), mac):
        return "bad authentication tag (another token, or forged)"
    return boot, data[:i] + (b"]" if batch else b"}")


def _dumps(obj: Any) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False, default=str).encode()


def pack_datagrams(objs: Iterable[dict[str, Any]], max_bytes: int, *, batch: bool = True) -> Iterator[bytes]:
    """Group JSON objects into datagrams of at most `max_bytes` (an object too big alone is dropped)."""
    if not batch:
        for obj in objs:
            data = _dumps(obj)
            if len(data) <= max_bytes:
                yield data
        return
    parts: list[bytes] = []
    size = 2  # the brackets
    for obj in objs:
        data = _dumps(obj)
        if len(data) + 2 > max_bytes:
            continue
        if parts and size + len(data) + 1 > max_bytes:
            yield b"[" + b",".join(parts) + b"]"
            parts, size = [], 2
        parts.append(data)
        size += len(data) + (1 if len(parts) > 1 else 0)
    if parts:
        yield b"[" + b",".join(parts) + b"]"


class TelemetrySender:
    """Non-blocking UDP sender to one or more destinations (e.g. `rimless robot listen` and PlotJuggler
    at once); counts what it sends and what it drops, over all destinations.

    :param destinations: (host, port) pairs; each is resolved once, here.
    :param token: the command token: every datagram is signed with this start's key (module docstring).
    :param boot: this start's nonce (default: a fresh one).
    """

    def __init__(
        self,
        destinations: list[tuple[str, int]] | str,
        port: int | None = None,
        *,
        max_datagram_bytes: int = 1200,
        batch: bool = True,
        decimate: int = 1,
        token: str | None = None,
        boot: str | None = None,
    ) -> None:
        if isinstance(destinations, str):  # the one-destination form: TelemetrySender(host, port)
            destinations = [(destinations, int(port or 9870))]
        self.max_datagram_bytes = max_datagram_bytes
        self.batch = batch
        self.decimate = max(1, decimate)
        self.clock = WallClock()
        self.sent_datagrams = 0
        self.sent_bytes = 0
        self.dropped_datagrams = 0
        self.tseq = 0
        self._n = 0
        self.boot = boot or secrets.token_hex(16)
        self._key = None if token is None else telemetry_key(token, self.boot)
        self.socks: list[socket.socket] = []
        self.addresses: list[tuple[Any, ...]] = []
        try:
            for host, dport in destinations:
                # Resolve once: sendto() with a host name would do a (blocking) DNS lookup every time.
                try:
                    info = socket.getaddrinfo(host, dport, type=socket.SOCK_DGRAM)[0]
                except (socket.gaierror, UnicodeError) as err:
                    raise ValueError(f"telemetry host {host!r} cannot be resolved: {err}") from err
                sock = socket.socket(info[0], socket.SOCK_DGRAM)
                self.socks.append(sock)
                sock.setblocking(False)
                # Connected: the kernel reports an ICMP "port unreachable" as ECONNREFUSED on a later send,
                # so a dead receiver shows up in dropped_datagrams instead of vanishing silently.
                sock.connect(info[4])
                self.addresses.append(info[4])
        except BaseException:
            self.close()
            raise
        self.address = self.addresses[0] if self.addresses else None

    def send(self, records: Iterable[Record]) -> None:
        """Encode and send to every destination; never blocks, never raises on a network error."""
        objs = []
        for rec in records:
            if isinstance(rec, SampleRecord):
                self._n += 1
                if (self._n - 1) % self.decimate:
                    continue
            obj = record_to_json(rec, self.clock)
            self.tseq += 1
            obj["tseq"] = self.tseq  # every object sent, numbered: a receiver counts what it lost
            objs.append(obj)
        room = self.max_datagram_bytes - (AUTH_TAG_BYTES if self._key is not None else 0)
        for data in pack_datagrams(objs, room, batch=self.batch):
            if self._key is not None:
                data = sign_datagram(data, self._key, self.boot)
            for sock in self.socks:
                try:
                    sock.send(data)
                except OSError:  # nobody listening (ICMP refused), buffer full, network down: drop it
                    self.dropped_datagrams += 1
                else:
                    self.sent_datagrams += 1
                    self.sent_bytes += len(data)

    def close(self) -> None:
        """Close the sockets."""
        for sock in self.socks:
            sock.close()


def parse_datagram(data: bytes) -> list[dict[str, Any]]:
    """Decode one datagram into its objects (array or single object); ValueError if garbled."""
    obj = json.loads(data)
    items = obj if isinstance(obj, list) else [obj]
    out = []
    for item in items:
        if not isinstance(item, dict) or not isinstance(item.get("timestamp"), (int, float)):
            raise ValueError("telemetry object without a numeric timestamp")
        out.append(item)
    return out
