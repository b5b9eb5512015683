"""An MCAP recording of the telemetry (`rimless robot listen --mcap FILE`) that Foxglove opens as it is.

One concept: telemetry objects to MCAP messages. Every message is JSON (`message_encoding` "json") with a
JSON Schema (`schema_encoding` "jsonschema"), one topic per series so that Foxglove plots each one on its
own:

- `/leg`: the stance leg's sample (`seq`, `ch`, `stance`, `position_m`, `velocity_m_s`, `compression_m`,
  `phase`, `clutch_mask`);
- `/leg0` ... `/leg7`: the same velocity, compression and phase under each leg's own topic, while it stands;
- `/sensor`: `squal`, `shutter`, `max_pixel` of the channel `ch`;
- `/loop`: `armed`, `latency_ms`;
- `/events`: every event (`name`, `code`, `event_seq` and its fields).

Times: `log_time` and `publish_time` are the robot's own timestamp of the object (epoch ns, the telemetry's
`timestamp`), so the timeline is the robot's clock, not the arrival; the message's `sequence` is the
object's telemetry number `tseq` (gaps are lost objects). The `mcap` package is a PC dependency (extra
`pc`): it is imported only when a recording starts, so the robot runs without it.
"""

from __future__ import annotations

import json
from typing import Any, BinaryIO

from rimless.firmware.errors import CommandError

_NUM = {"type": "number"}
_INT = {"type": "integer"}
SCHEMAS: dict[str, dict[str, Any]] = {
    "rimless.Leg": {
        "seq": _INT,
        "ch": _INT,
        "stance": _INT,
        "position_m": _NUM,
        "velocity_m_s": _NUM,
        "compression_m": _NUM,
        "phase": _INT,
        "clutch_mask": _INT,
    },
    "rimless.LegOwn": {"leg": _INT, "velocity_m_s": _NUM, "compression_m": _NUM, "phase": _INT},
    "rimless.Sensor": {"ch": _INT, "squal": _INT, "shutter": _INT, "max_pixel": _INT},
    "rimless.Loop": {"armed": _INT, "latency_ms": _NUM},
    "rimless.Event": {"name": {"type": "string"}, "code": _INT, "event_seq": _INT},
}
TOPIC_SCHEMA = {"/leg": "rimless.Leg", "/sensor": "rimless.Sensor", "/loop": "rimless.Loop", "/events": "rimless.Event"}


def _schema_bytes(name: str) -> bytes:
    props = SCHEMAS[name]
    return json.dumps({"title": name, "type": "object", "properties": props}).encode()


class McapRecorder:
    """Telemetry objects to an open binary file as MCAP (see the module docstring); `flush` ends a chunk
    (the file is readable up to it, whatever happens next), `finish` writes the summary and index."""

    def __init__(self, fh: BinaryIO, *, metadata: dict[str, str] | None = None) -> None:
        try:
            from mcap.writer import Writer
        except ImportError:
            raise CommandError(
                "--mcap needs the `mcap` package, a PC dependency: pip install 'rimless[pc]' (or pip install mcap)"
            ) from None
        self._writer = Writer(fh)
        self._writer.start(profile="", library="rimless robot listen")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.messages = 0
        if metadata:
            self._writer.add_metadata("rimless", dict(metadata))
        fh.flush()  # the header on disk at once: a recording killed before its first chunk is not 0 bytes

    def _channel(self, topic: str, schema: str) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            if schema not in self._schemas:
                self._schemas[schema] = self._writer.register_schema(schema, "jsonschema", _schema_bytes(schema))
            ch = self._writer.register_channel(topic, "json", self._schemas[schema])
            self._channels[topic] = ch
        return ch

    def _add(self, topic: str, schema: str, t_ns: int, seq: int, body: dict[str, Any]) -> None:
        data = json.dumps(body, separators=(",", ":"), allow_nan=False, default=str).encode()
        self._writer.add_message(
            self._channel(topic, schema), log_time=t_ns, data=data, publish_time=t_ns, sequence=seq
        )
        self.messages += 1

    def write(self, objs: list[dict[str, Any]]) -> None:
        """Record the objects of one datagram (objects without a numeric `timestamp` were refused before)."""
        for obj in objs:
            t_ns = max(0, round(float(obj["timestamp"]) * 1e9))
            seq = obj.get("tseq")
            seq = seq & 0xFFFFFFFF if isinstance(seq, int) and not isinstance(seq, bool) else 0
            ev = obj.get("event")
            if isinstance(ev, dict):
                self._add("/events", "rimless.Event", t_ns, seq, ev)
                continue
            raw_leg = obj.get("leg")
            leg = raw_leg if isinstance(raw_leg, dict) else {}
            ch = obj.get("ch")
            self._add("/leg", "rimless.Leg", t_ns, seq, {"seq": obj.get("seq"), "ch": ch, **leg})
            stance = leg.get("stance")
            own = obj.get(f"leg{stance}")
            if isinstance(stance, int) and isinstance(own, dict):
                self._add(f"/leg{stance}", "rimless.LegOwn", t_ns, seq, {"leg": stance, **own})
            if isinstance(obj.get("sensor"), dict):
                self._add("/sensor", "rimless.Sensor", t_ns, seq, {"ch": ch, **obj["sensor"]})
            if isinstance(obj.get("loop"), dict):
                self._add("/loop", "rimless.Loop", t_ns, seq, dict(obj["loop"]))

    def flush(self) -> None:
        """End the chunk in progress and push it to the file (`mcap`'s `Writer.flush`): a process killed after
        this leaves a file that mcap's readers read up to this chunk (without the summary `finish` writes)."""
        self._writer.flush()

    def finish(self) -> None:
        """Write the MCAP summary, index and footer."""
        self._writer.finish()
