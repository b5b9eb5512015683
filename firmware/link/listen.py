"""PC side of the telemetry: receive the robot's UDP datagrams, record them, show them live.

Records every object as one JSON line (`out`), the samples and events as CSV rows (`csv_out`) and as
MCAP messages, one topic per series (`mcap_out`, see `mcap_record`); each file is written under a `.part`
name and renamed when the recording ends (removed instead when it gave up on a robot that never sent). In a terminal the live view
redraws sparklines of leg velocity and compression and a strip per clutch; elsewhere it prints a
summary line every `summary_every_s`. When no datagram arrives for `stale_s`, it says so once, and
again when data resume. With a `heartbeat`, the command link is kept alive meanwhile.
"""

from __future__ import annotations

import csv
import json
import os
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO, TextIO

from rimless.errors import RunFailure
from rimless.firmware.errors import CommandError, Interrupted
from rimless.firmware.link.telemetry import parse_datagram

CSV_COLUMNS = (
    "timestamp",
    "t_mono_s",
    "seq",
    "ch",
    "leg/position_m",
    "leg/velocity_m_s",
    "leg/compression_m",
    "leg/phase",
    "leg/stance",
    "leg/clutch_mask",
    "sensor/squal",
    "sensor/shutter",
    "sensor/max_pixel",
    "loop/armed",
    "loop/latency_ms",
    "event/name",
    "event/code",
    "event/fault",
    "event/detail",
)
SPARK = " ▁▂▃▄▅▆▇█"


def _flat(obj: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in obj.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flat(v, key + "/"))
        else:
            out[key] = v
    return out


def sparkline(values: list[float], width: int) -> str:
    """Unicode block sparkline of the last `width` values, scaled to their own range."""
    vals = values[-width:]
    if not vals:
        return ""
    lo, hi = min(vals), max(vals)
    span = hi - lo
    if span <= 0:
        return SPARK[1] * len(vals)
    return "".join(SPARK[1 + int((v - lo) / span * (len(SPARK) - 2) + 0.5)] for v in vals)


class Summary:
    """Running counts over the received telemetry, and the recent history the live view draws."""

    def __init__(self, history: int = 600) -> None:
        self.datagrams = 0
        self.samples = 0
        self.events = 0
        self.faults: list[str] = []
        self.garbled = 0
        self.foreign = 0  # datagrams from another sender than the robot, ignored
        self.lost_objects = 0  # gaps in the objects' `tseq`
        self.lost_events = 0  # gaps in the events' `event_seq`
        self._tseq: int | None = None
        self._event_seq: int | None = None
        self.last: dict[str, Any] | None = None
        self._window: list[float] = []
        self.velocity: deque[float] = deque(maxlen=history)
        self.compression: deque[float] = deque(maxlen=history)
        self.mask: deque[int] = deque(maxlen=history)

    def add(self, objs: list[dict[str, Any]], now_s: float) -> None:
        """Account for one datagram's objects."""
        self.datagrams += 1
        for obj in objs:
            t = obj.get("tseq")
            if isinstance(t, int) and not isinstance(t, bool):
                if self._tseq is not None and t > self._tseq + 1:
                    self.lost_objects += t - self._tseq - 1
                if self._tseq is None or t > self._tseq:
                    self._tseq = t
            ev = obj.get("event")
            es = ev.get("event_seq") if isinstance(ev, dict) else None
            if isinstance(es, int) and not isinstance(es, bool):
                if self._event_seq is not None and es > self._event_seq + 1:
                    self.lost_events += es - self._event_seq - 1
                if self._event_seq is None or es > self._event_seq:
                    self._event_seq = es
            if isinstance(ev, dict):
                self.events += 1
                if ev.get("name") == "fault":
                    self.faults.append(str(ev.get("fault")))
            else:
                self.samples += 1
                self.last = obj
                self._window.append(now_s)
                raw_leg = obj.get("leg")
                leg = raw_leg if isinstance(raw_leg, dict) else {}
                for name, dq in (("velocity_m_s", self.velocity), ("compression_m", self.compression)):
                    v = leg.get(name)
                    if isinstance(v, (int, float)):
                        dq.append(float(v))
                m = leg.get("clutch_mask")
                if isinstance(m, int):
                    self.mask.append(m)

    def rate(self, now_s: float, span_s: float) -> float:
        """Samples per second over the last `span_s`."""
        self._window = [t for t in self._window if now_s - t <= span_s]
        return len(self._window) / span_s if span_s > 0 else 0.0

    def line(self, now_s: float, span_s: float) -> str:
        """One summary line."""
        rate = self.rate(now_s, span_s)
        leg = (self.last or {}).get("leg", {})
        return (
            f"{self.samples} samples ({rate:.0f}/s), {self.events} events, faults: {', '.join(self.faults[-3:]) or 'none'}"
            f" | stance {leg.get('stance', '-')}, phase {leg.get('phase', '-')}, v {leg.get('velocity_m_s', 0):+.3f} m/s,"
            f" clutch mask {leg.get('clutch_mask', 0)}"
            + (f", {self.garbled} garbled" if self.garbled else "")
            + (f", LOST {self.lost_objects} objects ({self.lost_events} events)" if self.lost_objects else "")
            + (f", {self.foreign} foreign datagrams ignored" if self.foreign else "")
        )

    def view(self, now_s: float, span_s: float, width: int = 60, legs: int = 8) -> list[str]:
        """The live view's lines: summary, velocity and compression sparklines, one strip per clutch."""
        v, c, m = list(self.velocity), list(self.compression), list(self.mask)[-width:]
        lines = [self.line(now_s, span_s)[: width + 19]]
        if v:
            lines.append(f"velocity    {sparkline(v, width)}  {min(v[-width:]):+.3f}..{max(v[-width:]):+.3f} m/s")
        if c:
            lines.append(
                f"compression {sparkline([x * 1e3 for x in c], width)}  "
                f"{1e3 * min(c[-width:]):.1f}..{1e3 * max(c[-width:]):.1f} mm"
            )
        for k in range(legs):
            lines.append(f"clutch {k}    " + "".join("█" if (x >> k) & 1 else "·" for x in m))
        return lines


class Recorder:
    """JSON Lines, CSV and MCAP files written under `.part` names, renamed by `close`."""

    def __init__(
        self,
        out: Path | None,
        csv_out: Path | None,
        mcap_out: Path | None = None,
        mcap_metadata: dict[str, str] | None = None,
    ) -> None:
        self.paths: list[Path] = []
        self._parts: list[tuple[Path, Path]] = []
        self._jsonl: TextIO | None = None
        self._csv_fh: TextIO | None = None
        self._csv: Any = None
        self._mcap_fh: BinaryIO | None = None
        self._mcap: Any = None
        self._mcap_part: Path | None = None
        self.lines = 0
        try:
            if out is not None:
                self._jsonl = self._open(out)
            if csv_out is not None:
                self._csv_fh = self._open(csv_out)
                self._csv = csv.DictWriter(self._csv_fh, CSV_COLUMNS, extrasaction="ignore")
                self._csv.writeheader()
            if mcap_out is not None:
                from rimless.firmware.link.mcap_record import McapRecorder

                self._mcap_fh = self._open(mcap_out, binary=True)
                self._mcap_part = self._parts[-1][0]
                self._mcap = McapRecorder(self._mcap_fh, metadata=mcap_metadata)
        except OSError as err:
            self._abandon()
            raise CommandError(f"cannot write {err.filename} ({err.strerror or err})") from None
        except BaseException:
            self._abandon()
            raise

    def discard(self) -> None:
        """Close and remove every `.part` file: a recording that holds nothing leaves no file behind."""
        self._mcap = None
        self._abandon()

    def _abandon(self) -> None:
        """Close and remove the `.part` files of a recording that could not start (or holds nothing)."""
        for fh in (self._jsonl, self._csv_fh, self._mcap_fh):
            if fh is not None:
                fh.close()
        for part, _final in self._parts:
            part.unlink(missing_ok=True)
        self._parts = []
        self._jsonl = self._csv_fh = self._mcap_fh = None

    def _open(self, path: Path, *, binary: bool = False) -> Any:
        part = path.with_name(path.name + ".part")
        if binary:
            fh: Any = open(part, "wb")
        else:
            fh = open(part, "w", encoding="utf-8", newline="")
        self._parts.append((part, path))
        return fh

    def write(self, objs: list[dict[str, Any]]) -> None:
        """Record the objects of one datagram."""
        for obj in objs:
            self.lines += 1
            if self._jsonl is not None:
                self._jsonl.write(json.dumps(obj, separators=(",", ":")) + "\n")
            if self._csv is not None:
                self._csv.writerow(_flat(obj))
        if self._mcap is not None:
            self._mcap.write(objs)

    def flush(self) -> None:
        """Push the buffers to the files."""
        for fh in (self._jsonl, self._csv_fh):
            if fh is not None:
                fh.flush()

    def close(self) -> list[Path]:
        """Close and rename every file to its final name; returns the final paths. An MCAP file gets its
        summary and index first; if that fails, it keeps its `.part` name."""
        mcap_ok = True
        if self._mcap is not None:
            try:
                self._mcap.finish()
            except Exception:  # noqa: BLE001 - the other files are still completed
                mcap_ok = False
            self._mcap = None
        for fh in (self._jsonl, self._csv_fh, self._mcap_fh):
            if fh is not None:
                fh.close()
        if not mcap_ok:
            self._parts = [(p, f) for p, f in self._parts if p != self._mcap_part]
        self._jsonl = self._csv_fh = self._mcap_fh = None
        for part, final in self._parts:
            if part.exists():
                os.replace(part, final)
                self.paths.append(final)
        self._parts = []
        return self.paths


def listen(
    *,
    bind: str,
    port: int,
    out: Path | None,
    duration_s: float | None,
    summary_every_s: float = 1.0,
    echo: Callable[[str], None] = print,
    csv_out: Path | None = None,
    stale_s: float = 1.0,
    live: bool = False,
    write_screen: Callable[[str], object] | None = None,
    heartbeat: Any = None,
    timeout_s: float = 10.0,
    robot: str | None = None,
    mcap_out: Path | None = None,
) -> Summary:
    """Receive until `duration_s` (or Ctrl-C); record and show as the module docstring says.

    Until the first datagram the summary line says what it waits for instead of counting zero samples. When
    nothing arrives for `timeout_s` (0: wait forever), `RunFailure` says that no robot is sending (the command
    exits 1): if no datagram arrived at all, no file is left behind; if the robot stopped sending, the files are
    completed (the recording up to then) and the message names them.

    Only one sender is the robot: `robot` (a host name or address), else the first sender heard; datagrams
    from any other are counted (`foreign`) and ignored. Gaps in the objects' `tseq` and the events'
    `event_seq` are counted and shown (a lost fault event does not go unnoticed)."""
    try:
        sock = socket.socket(socket.AF_INET6 if ":" in bind else socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((bind, port))
    except OSError as err:
        raise CommandError(f"cannot listen on {bind}:{port} ({err.strerror or err})") from None
    sock.settimeout(0.1)
    robot_ip: str | None = None
    if robot is not None:
        try:
            robot_ip = str(socket.getaddrinfo(robot, None, type=socket.SOCK_DGRAM)[0][4][0])  # an IP address
        except (socket.gaierror, UnicodeError) as err:
            sock.close()
            raise CommandError(f"--robot {robot!r} cannot be resolved ({err})") from None
    try:
        rec = Recorder(out, csv_out, mcap_out, {"bind": f"{bind}:{port}", "robot": robot or "first sender heard"})
    except BaseException:
        sock.close()
        raise
    hb_thread = None
    if heartbeat is not None:
        hb_thread = threading.Thread(target=heartbeat.run, name="rimless-heartbeat", daemon=True)
        hb_thread.start()
    summary = Summary()
    start = time.monotonic()
    next_line = start + summary_every_s
    last_data: float | None = None
    stale = False
    stopped_by: BaseException | None = None
    silent_for: float | None = None
    try:
        while duration_s is None or time.monotonic() - start < duration_s:
            try:
                data, addr = sock.recvfrom(65536)
            except TimeoutError:
                data, addr = None, None
            if data and addr is not None:
                if robot_ip is None:
                    robot_ip = addr[0]
                    echo(f"receiving from {robot_ip} (datagrams from any other sender are ignored)")
                elif addr[0] != robot_ip:
                    summary.foreign += 1
                    data = None
            now = time.monotonic()
            if data:
                try:
                    objs = parse_datagram(data)
                except ValueError:
                    summary.garbled += 1
                else:
                    if stale and last_data is not None:
                        echo(f"data resumed after {now - last_data:.1f} s")
                    stale = False
                    last_data = now
                    summary.add(objs, now)
                    rec.write(objs)
            elif last_data is not None and not stale and now - last_data >= stale_s:
                stale = True
                wall = time.strftime("%H:%M:%S", time.localtime(time.time() - (now - last_data)))
                echo(f"data stopped: nothing for {stale_s:g} s (last datagram at {wall})")
            quiet_s = now - (start if last_data is None else last_data)
            if timeout_s > 0 and quiet_s >= timeout_s:
                silent_for = quiet_s
                break
            if now >= next_line and last_data is None:
                echo(
                    f"waiting for telemetry on {bind}:{port}: no robot sending for {quiet_s:.0f} s"
                    + (f" (giving up after {timeout_s:g} s)" if timeout_s > 0 else "")
                )
                next_line = now + summary_every_s
            elif now >= next_line:
                if live and write_screen is not None:
                    write_screen("\x1b[H\x1b[J" + "\n".join(summary.view(now, summary_every_s)) + "\n")
                else:
                    echo(summary.line(now, summary_every_s))
                next_line = now + summary_every_s
                rec.flush()
    except (KeyboardInterrupt, Interrupted) as err:
        stopped_by = err
    finally:
        sock.close()
        if heartbeat is not None:
            heartbeat.stop()
            if hb_thread is not None:
                hb_thread.join(2.0)
        if silent_for is not None and last_data is None:  # nothing heard: a run without a result leaves no file
            rec.discard()
            paths = []
        else:
            paths = rec.close()
    if last_data is not None or silent_for is None:
        echo(summary.line(time.monotonic(), summary_every_s))
    if summary.lost_objects:
        echo(
            f"lost {summary.lost_objects} telemetry objects on the way, {summary.lost_events} of them events "
            "(a fault may be among them: see the robot's trial log or `rimless robot status`)"
        )
    for p in paths:
        echo(f"wrote {p}")
    if stopped_by is not None:
        raise stopped_by  # after the files are complete: the caller exits 130
    if silent_for is not None:
        what = "no robot is sending telemetry" if last_data is None else "the robot stopped sending telemetry"
        kept = (
            "nothing recorded"
            if last_data is None
            else (f"the recording up to then is kept ({', '.join(str(p) for p in paths)})" if paths else "")
        )
        raise RunFailure(
            f"{what} to {bind}:{port}: nothing for {silent_for:.1f} s (--timeout-s {timeout_s:g}); "
            "is this PC in the robot's [telemetry] destinations (or `robot run --telemetry`)?"
            + (f" ({kept})" if kept else "")
        )
    return summary
