"""PC side of the telemetry: receive the robot's UDP datagrams, record them, summarise them live."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from rimless.firmware.errors import CommandError
from rimless.firmware.telemetry import parse_datagram


class Summary:
    """Running counts over the received telemetry."""

    def __init__(self) -> None:
        self.datagrams = 0
        self.samples = 0
        self.events = 0
        self.faults: list[str] = []
        self.garbled = 0
        self.last: dict[str, Any] | None = None
        self._window: list[float] = []

    def add(self, objs: list[dict[str, Any]], now_s: float) -> None:
        """Account for one datagram's objects."""
        self.datagrams += 1
        for obj in objs:
            ev = obj.get("event")
            if isinstance(ev, dict):
                self.events += 1
                if ev.get("name") == "fault":
                    self.faults.append(str(ev.get("fault")))
            else:
                self.samples += 1
                self.last = obj
                self._window.append(now_s)

    def line(self, now_s: float, span_s: float) -> str:
        """One summary line."""
        self._window = [t for t in self._window if now_s - t <= span_s]
        rate = len(self._window) / span_s if span_s > 0 else 0.0
        leg = (self.last or {}).get("leg", {})
        return (
            f"{self.samples} samples ({rate:.0f}/s), {self.events} events, faults: {', '.join(self.faults[-3:]) or 'none'}"
            f" | stance {leg.get('stance', '-')}, phase {leg.get('phase', '-')}, v {leg.get('velocity_m_s', 0):+.3f} m/s,"
            f" clutch mask {leg.get('clutch_mask', 0)}" + (f", {self.garbled} garbled" if self.garbled else "")
        )


def listen(
    *, bind: str, port: int, out: Path | None, duration_s: float | None, summary_every_s: float = 1.0,
    echo: Callable[[str], None] = print,
) -> Summary:
    """Receive until `duration_s` (or Ctrl-C); each object goes to `out` as one JSON line."""
    try:
        sock = socket.socket(socket.AF_INET6 if ":" in bind else socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((bind, port))
    except OSError as err:
        raise CommandError(f"cannot listen on {bind}:{port} ({err.strerror or err})") from None
    sock.settimeout(0.1)
    fh: TextIO | None = None
    if out is not None:
        try:
            fh = open(out, "a", encoding="utf-8")  # noqa: SIM115 - closed in finally
        except OSError as err:
            sock.close()
            raise CommandError(f"cannot write {out} ({err.strerror or err})") from None
    summary = Summary()
    start = time.monotonic()
    next_line = start + summary_every_s
    try:
        while duration_s is None or time.monotonic() - start < duration_s:
            try:
                data = sock.recv(65536)
            except TimeoutError:
                data = None
            now = time.monotonic()
            if data:
                try:
                    objs = parse_datagram(data)
                except ValueError:
                    summary.garbled += 1
                else:
                    summary.add(objs, now)
                    if fh is not None:
                        for obj in objs:
                            fh.write(json.dumps(obj, separators=(",", ":")) + "\n")
            if now >= next_line:
                echo(summary.line(now, summary_every_s))
                next_line = now + summary_every_s
                if fh is not None:
                    fh.flush()
    except KeyboardInterrupt:
        pass
    finally:
        sock.close()
        if fh is not None:
            fh.close()
    echo(summary.line(time.monotonic(), summary_every_s))
    return summary
