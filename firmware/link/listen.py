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
from rimless.firmware.link.telemetry import (
    has_tag,
    parse_datagram,
    strip_tag,
    telemetry_key,
    verify_datagram,
)
from rimless.progress import stage

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


class SeqTracker:
    """Counts the numbers of one numbered stream (the objects' `tseq`, the events' `event_seq`) that never came,
    so that no single number can poison the count: duplicates are ignored, a late one (reordered) fills its gap,
    one more than `WINDOW` below the highest is stale, and with `confirm_jumps` (an unauthenticated stream) a
    number more than `MAX_JUMP` ahead is held until the next number confirms it (a forged 1e9 alone moves
    nothing). Lost = (highest - first + 1) - distinct numbers seen, summed over confirmed jumps."""

    WINDOW = 4096
    MAX_JUMP = 1 << 16

    def __init__(self, *, confirm_jumps: bool = False) -> None:
        self.confirm_jumps = confirm_jumps
        self.first: int | None = None
        self.high = 0
        self.distinct = 0
        self.duplicates = 0
        self.stale = 0
        self.held = 0  # numbers far ahead not (yet) confirmed
        self._lost_before = 0
        self._seen: set[int] = set()
        self._pending: int | None = None

    @property
    def lost(self) -> int:
        """Numbers that never came (so far)."""
        if self.first is None:
            return 0
        return self._lost_before + max(0, self.high - self.first + 1 - self.distinct)

    def add(self, n: int) -> bool:
        """Account for number `n`; True if it is new (to be recorded)."""
        if self.first is None:
            self.first = self.high = n
            self.distinct = 1
            self._seen = {n}
            return True
        if n in self._seen:
            self.duplicates += 1
            return False
        if n < self.high - self.WINDOW:
            self.stale += 1
            return False
        if self.confirm_jumps and n > self.high + self.MAX_JUMP:
            if self._pending is None or not 0 < n - self._pending <= self.MAX_JUMP:
                self._pending = n
                self.held += 1
                return False
            self._lost_before = self.lost + (self._pending - self.high - 1)
            self.first, self.high, self.distinct = self._pending, self._pending, 1
            self._seen = {self._pending}
            self.held -= 1
        self._pending = None
        self._seen.add(n)
        self.distinct += 1
        self.high = max(self.high, n)
        if len(self._seen) > 2 * self.WINDOW:
            self._seen = {k for k in self._seen if k >= self.high - self.WINDOW}
        return True


class Summary:
    """Running counts over the received telemetry, and the recent history the live view draws."""

    def __init__(self, history: int = 600, *, authenticated: bool = False) -> None:
        self.datagrams = 0
        self.samples = 0
        self.events = 0
        self.faults: list[str] = []
        self.garbled = 0
        self.foreign = 0  # datagrams from another sender than the robot, ignored
        self.unauthenticated = 0  # of them: datagrams whose tag is missing or does not hold
        self.duplicates = 0  # objects received twice (a replay, or the network), recorded once
        self.restarts = 0  # the robot started again (a new boot nonce) during the recording
        self.authenticated = authenticated
        self._seq: list[tuple[SeqTracker, SeqTracker]] = []  # (tseq, event_seq) per start of the robot
        self.new_start()
        self.last: dict[str, Any] | None = None
        self._window: list[float] = []
        self.velocity: deque[float] = deque(maxlen=history)
        self.compression: deque[float] = deque(maxlen=history)
        self.mask: deque[int] = deque(maxlen=history)

    def new_start(self) -> None:
        """The robot started again: its numbers start again (the losses so far are kept)."""
        confirm = not self.authenticated
        self._seq.append((SeqTracker(confirm_jumps=confirm), SeqTracker(confirm_jumps=confirm)))

    @property
    def lost_objects(self) -> int:
        """Gaps in the objects' `tseq`, over every start of the robot."""
        return sum(t.lost for t, _ in self._seq)

    @property
    def lost_events(self) -> int:
        """Gaps in the events' `event_seq`, over every start of the robot."""
        return sum(e.lost for _, e in self._seq)

    def add(self, objs: list[dict[str, Any]], now_s: float) -> list[dict[str, Any]]:
        """Account for one datagram's objects; returns those to record (not seen before)."""
        self.datagrams += 1
        tseq, eseq = self._seq[-1]
        new = []
        for obj in objs:
            t = obj.get("tseq")
            if isinstance(t, int) and not isinstance(t, bool) and not tseq.add(t):
                self.duplicates += 1
                continue
            new.append(obj)
            ev = obj.get("event")
            es = ev.get("event_seq") if isinstance(ev, dict) else None
            if isinstance(es, int) and not isinstance(es, bool):
                eseq.add(es)
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
        return new

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
            + (f" ({self.unauthenticated} unauthenticated)" if self.unauthenticated else "")
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
        """Push the buffers to the files; the MCAP file ends its chunk (readable up to here, whatever kills
        the process next)."""
        for fh in (self._jsonl, self._csv_fh):
            if fh is not None:
                fh.flush()
        if self._mcap is not None:
            self._mcap.flush()

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


def _parse(data: bytes, summary: Summary) -> list[dict[str, Any]] | None:
    """The objects of a datagram, or None (counted as garbled)."""
    try:
        return parse_datagram(data)
    except ValueError:
        summary.garbled += 1
        return None


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
    token: str | None = None,
    max_datagrams: int | None = None,
) -> Summary:
    """Receive until `duration_s`, until `max_datagrams` of the robot's datagrams are in (None: no limit), or
    Ctrl-C; record and show as the module docstring says.

    Until the first datagram the summary line says what it waits for instead of counting zero samples. When
    nothing arrives for `timeout_s` (0: wait forever), `RunFailure` says that no robot is sending (the command
    exits 1): if no datagram arrived at all, no file is left behind; if the robot stopped sending, the files are
    completed (the recording up to then) and the message names them.

    With `token` (the command token), only datagrams whose authentication tag holds are the robot's (see
    `telemetry`), from whatever address, and (with `robot` too) only from that address; a new boot nonce whose
    objects are newer than the last recorded is the robot starting again (said, and its numbers start again),
    an older one a replay (ignored). Without a token, nothing can be authenticated (said once at the start):
    the robot is `robot` (a host name or address), else the first sender whose datagrams carry a tag. Every other
    datagram is counted (`foreign`, of them `unauthenticated`) and ignored. Objects received twice are recorded
    once; gaps in the objects' `tseq` and the events' `event_seq` are counted (`SeqTracker`: no single number
    can poison the count) and shown (a lost fault event does not go unnoticed).

    Stages (`rimless.progress.stage`, for tests that wait on events): ``listen: listening`` once bound,
    ``listen: datagram N from the robot`` as each is accounted for, ``listen: data stopped``, ``listen: data
    resumed``."""
    try:
        sock = socket.socket(socket.AF_INET6 if ":" in bind else socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((bind, port))
    except OSError as err:
        raise CommandError(f"cannot listen on {bind}:{port} ({err.strerror or err})") from None
    sock.settimeout(0.1)
    stage("listen: listening")
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
    summary = Summary(authenticated=token is not None)
    keys: dict[str, bytes] = {}

    def key_for(boot: str) -> bytes:
        if boot not in keys:
            if len(keys) > 64:
                keys.clear()
            keys[boot] = telemetry_key(token or "", boot)
        return keys[boot]

    boot: str | None = None
    last_t = float("-inf")  # the newest robot timestamp recorded (a replayed older start is refused by it)
    if token is None:
        echo(
            "telemetry not authenticated: without the command token (--token-file, $RIMLESS_TOKEN_FILE or "
            "$RIMLESS_TOKEN) any host on the LAN can forge it"
        )
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
            objs: list[dict[str, Any]] | None = None
            if data and addr is not None:
                if robot_ip is not None and addr[0] != robot_ip:
                    summary.foreign += 1
                elif token is not None:
                    checked = verify_datagram(data, key_for)
                    if isinstance(checked, str):
                        summary.foreign += 1
                        summary.unauthenticated += 1
                    else:
                        objs = _parse(checked[1], summary)
                        if objs is not None and checked[0] != boot:
                            newest = max((float(o["timestamp"]) for o in objs), default=float("-inf"))
                            if boot is None:
                                echo(f"receiving from {addr[0]} (authenticated: the robot's start {checked[0][:8]})")
                            elif newest > last_t:
                                summary.restarts += 1
                                summary.new_start()
                                echo(f"the robot started again (start {checked[0][:8]}): its numbers start again")
                            else:
                                summary.foreign += 1  # an older start's datagram: a replay
                                objs = None
                            if objs is not None:
                                boot = checked[0]
                elif robot_ip is None and not has_tag(data):
                    summary.foreign += 1
                    summary.unauthenticated += 1
                else:
                    if robot_ip is None:
                        robot_ip = addr[0]
                        echo(f"receiving from {robot_ip} (datagrams from any other sender are ignored)")
                    objs = _parse(strip_tag(data), summary)  # the tag cannot be checked without the token
            now = time.monotonic()
            if objs is not None:
                if stale and last_data is not None:
                    echo(f"data resumed after {now - last_data:.1f} s")
                    stage("listen: data resumed")
                stale = False
                last_data = now
                new = summary.add(objs, now)
                if new:
                    last_t = max(last_t, max(float(o["timestamp"]) for o in new))
                    rec.write(new)
                stage(f"listen: datagram {summary.datagrams} from the robot")
                if max_datagrams is not None and summary.datagrams >= max_datagrams:
                    break
            elif last_data is not None and not stale and now - last_data >= stale_s:
                stale = True
                wall = time.strftime("%H:%M:%S", time.localtime(time.time() - (now - last_data)))
                echo(f"data stopped: nothing for {stale_s:g} s (last datagram at {wall})")
                stage("listen: data stopped")
            quiet_s = now - (start if last_data is None else last_data)
            if timeout_s > 0 and quiet_s >= timeout_s:
                silent_for = quiet_s
                break
            if now >= next_line and last_data is None:
                echo(
                    f"waiting for telemetry on {bind}:{port}: no robot sending for {quiet_s:.0f} s"
                    + (f" (giving up after {timeout_s:g} s)" if timeout_s > 0 else "")
                    + (
                        f"; {summary.foreign} datagrams ignored ({summary.unauthenticated} without a valid "
                        "authentication tag: another token, or a robot before protocol version 3?)"
                        if summary.foreign
                        else ""
                    )
                )
                next_line = now + summary_every_s
            elif now >= next_line:
                rec.flush()  # before the line: a line seen means the files hold what it counts
                if live and write_screen is not None:
                    write_screen("\x1b[H\x1b[J" + "\n".join(summary.view(now, summary_every_s)) + "\n")
                else:
                    echo(summary.line(now, summary_every_s))
                next_line = now + summary_every_s
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
