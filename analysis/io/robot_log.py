"""The robot's trial log (``rimless-trial-log/1``, JSON Lines, written by `rimless.firmware.service.triallog`)
read for what a Vicon trial's report compares: when each leg's clutch locked and released.

Line 1 is the header (``{"format": "rimless-trial-log/1", ...}``); every other line is a sample or an event
``{"timestamp": epoch s, "t_mono_s": s, "event": {"name": ..., "leg": ..., "armed": ..., "released_leg": ...}}``.
A ``lock`` event of an armed robot engages the stance leg ``leg`` (disarmed, the decision is logged but no clutch
moves); any event carrying ``released_leg`` (the touchdown that hands the stance to the next leg, or a
``release``) frees that leg. A torn last line
(a power cut while writing) is skipped with a warning; any other bad line is an error naming file and line.

Read here without importing the firmware (the analysis does not depend on the robot's package); the format is
the firmware's (`FORMAT`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.errors import InputFileError

__all__ = ["FORMAT", "ClutchLog", "read_clutch_log"]

FORMAT = "rimless-trial-log/1"


@dataclass
class ClutchLog:
    """Clutch lock intervals from a robot trial log, in lock order.

    lock_s, release_s: monotonic times (s) of each lock and of the release of the same leg that followed it (NaN
    when the log ends with that clutch still locked); leg: the leg locked; clutched_s = release_s - lock_s."""

    path: str
    lock_s: np.ndarray
    release_s: np.ndarray
    leg: np.ndarray
    warnings: list[str] = field(default_factory=list)

    @property
    def clutched_s(self) -> np.ndarray:
        return self.release_s - self.lock_s

    def complete(self) -> np.ndarray:
        """The clutched times (s) of the locks that were released within the log."""
        c = self.clutched_s
        return c[np.isfinite(c)]


def read_clutch_log(path: str | Path) -> ClutchLog:
    """Lock/release pairs of a robot trial log; `InputFileError` (``file:line: reason``) when it is not one."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as err:
        raise InputFileError(f"{p}: cannot read the robot log ({err.strerror or err})") from None
    lines = raw.split(b"\n")
    warnings: list[str] = []
    if lines and lines[-1] != b"":
        warnings.append(f"{p}:{len(lines)}: torn last line (an interrupted write) skipped")
    lines = lines[:-1]
    events: list[tuple[float, str, dict[str, Any]]] = []
    for i, line in enumerate(lines, start=1):
        try:
            obj = json.loads(line)
            if not isinstance(obj, dict):
                raise ValueError("not a JSON object")
        except ValueError as err:
            raise InputFileError(f"{p}:{i}: not a line of a robot trial log ({err})") from None
        if i == 1:
            if obj.get("format") != FORMAT:
                raise InputFileError(
                    f"{p}:1: not a robot trial log (the header's format is {obj.get('format')!r}, expected {FORMAT!r})"
                )
            continue
        ev = obj.get("event")
        if not isinstance(ev, dict) or not (ev.get("name") == "lock" or "released_leg" in ev):
            continue
        t = obj.get("t_mono_s")
        if not isinstance(t, (int, float)) or not math.isfinite(t):
            raise InputFileError(f"{p}:{i}: field t_mono_s of a {ev.get('name')} event must be a number, got {t!r}")
        events.append((float(t), str(ev.get("name")), ev))
    if not lines:
        raise InputFileError(f"{p}: empty: not a robot trial log")
    lock_s: list[float] = []
    release_s: list[float] = []
    legs: list[int] = []
    open_lock: dict[int, int] = {}
    for t, name, ev in sorted(events, key=lambda e: e[0]):
        if "released_leg" in ev:
            leg = ev.get("released_leg")
            if isinstance(leg, int) and leg in open_lock:
                release_s[open_lock.pop(leg)] = t
        if name == "lock":
            leg = ev.get("leg")
            if not isinstance(leg, int) or ev.get("armed", True) is not True:
                continue
            if leg in open_lock:  # locked again without a release: the first interval is not known
                release_s[open_lock[leg]] = math.nan
            open_lock[leg] = len(lock_s)
            lock_s.append(t)
            release_s.append(math.nan)
            legs.append(leg)
    if not lock_s:
        warnings.append(f"{p}: no clutch lock in the log")
    return ClutchLog(str(p), np.array(lock_s, float), np.array(release_s, float), np.array(legs, np.int64), warnings)
