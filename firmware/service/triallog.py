"""The robot's local trial log: every sample and event of a trial, in JSON Lines.

Crash- and power-loss tolerant by construction: the file is append-only, whole lines are written in
one `write` and `fsync`ed every `flush_interval_s` (so at most that much is lost), and the directory
is fsynced when the file is created. A power cut can leave only a torn *last* line, which
`read_trial_log` reports and skips; a bad line anywhere else raises, because that is real corruption.

A write that fails (a full disk: ENOSPC, EDQUOT, EIO) never raises into the firmware: the file is cut back
to its last whole line (so it never ends torn while the process lives), the lines of that write are dropped
and counted (`dropped_lines`, `errors`, `last_error`), and the next write tries again.
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.firmware.control.controller import Record
from rimless.firmware.errors import FirmwareError
from rimless.firmware.link.telemetry import WallClock, record_to_json

FORMAT = "rimless-trial-log/1"
_NAME_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


class TrialLogError(FirmwareError, ValueError):
    """A trial log is corrupt (not just a torn last line)."""


def valid_trial_name(name: str) -> bool:
    """Letters, digits, `_.-`, 1-64 characters (the name becomes part of a file name)."""
    return bool(_NAME_RE.match(name)) and name not in (".", "..")


class TrialLog:
    """An open trial log file. `append` buffers encoded lines; `sync` writes and fsyncs them."""

    def __init__(
        self,
        directory: str | Path,
        name: str,
        header: dict[str, Any] | None = None,
        *,
        write: Callable[[int, Any], int] = os.write,
    ) -> None:
        if not valid_trial_name(name):
            raise ValueError(f"trial name {name!r}: use 1-64 letters, digits, '_', '.', '-'")
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        self.path = self.dir / f"{stamp}_{name}.jsonl"
        n = 1
        while self.path.exists():
            n += 1
            self.path = self.dir / f"{stamp}_{name}-{n}.jsonl"
        self.name = name
        self.clock = WallClock()
        self.lines = 0
        self.dropped_lines = 0
        self.errors = 0
        self.last_error = ""
        self._write = write
        self._size = 0  # bytes of whole lines in the file
        self._pending: list[bytes] = []
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
        head = {"format": FORMAT, "trial": name, "started_epoch_s": time.time(), **(header or {})}
        self._pending.append(_line(head))
        self.sync()
        _fsync_dir(self.dir)

    def append(self, records: Iterable[Record]) -> None:
        """Encode records into the pending buffer (no I/O)."""
        for rec in records:
            self._pending.append(_line(record_to_json(rec, self.clock)))

    def sync(self) -> int:
        """Write the pending lines in one write and fsync; returns the bytes written (0 when the write failed:
        see the module docstring). Blocking I/O: the app calls it through `asyncio.to_thread`."""
        if not self._pending or self._fd < 0:
            return 0
        data = b"".join(self._pending)
        n_lines = len(self._pending)
        self._pending = []
        view = memoryview(data)
        try:
            while view:
                n = self._write(self._fd, view)
                if n <= 0:
                    raise OSError(0, "write wrote nothing")
                view = view[n:]
        except OSError as err:
            self._failed(err, n_lines)
            try:
                os.ftruncate(self._fd, self._size)  # no torn line: back to the last whole one
            except OSError:
                pass
            return 0
        self._size += len(data)
        self.lines += n_lines
        try:
            os.fsync(self._fd)
        except OSError as err:
            self._failed(err, 0)
        return len(data)

    def _failed(self, err: OSError, n_lines: int) -> None:
        self.errors += 1
        self.dropped_lines += n_lines
        self.last_error = f"{self.path}: {err.strerror or err}"

    def close(self) -> None:
        """Sync and close (never raises for a failed write: it is counted)."""
        if self._fd >= 0:
            self.sync()
            try:
                os.close(self._fd)
            except OSError as err:
                self._failed(err, 0)
            self._fd = -1


def _line(obj: dict[str, Any]) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False, default=str).encode() + b"\n"


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@dataclass
class TrialLogContents:
    """A trial log read back: header, samples, events, and whether a torn last line was dropped."""

    header: dict[str, Any]
    samples: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    torn_tail: bool = False


def read_trial_log(path: str | Path) -> TrialLogContents:
    """Read a trial log; tolerate a torn last line, raise `TrialLogError` on corruption elsewhere."""
    raw = Path(path).read_bytes()
    lines = raw.split(b"\n")
    torn = False
    if lines and lines[-1] != b"":
        torn = True  # the last line has no newline: an interrupted write
    lines = lines[:-1]
    objs: list[dict[str, Any]] = []
    for i, line in enumerate(lines, start=1):
        try:
            obj = json.loads(line)
            if not isinstance(obj, dict):
                raise ValueError("not an object")
        except ValueError as err:
            raise TrialLogError(f"{path}: line {i} is corrupt ({err})") from None
        objs.append(obj)
    if not objs or objs[0].get("format") != FORMAT:
        raise TrialLogError(f"{path}: not a rimless trial log (missing header line)")
    out = TrialLogContents(header=objs[0], torn_tail=torn)
    for obj in objs[1:]:
        (out.events if "event" in obj else out.samples).append(obj)
    return out
