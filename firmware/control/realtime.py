"""Real-time settings for the control thread (Linux): SCHED_FIFO, one CPU, memory locked, the garbage
collector kept out of the way.

`apply_realtime` is called by the control thread itself at start (`sched_setscheduler` and `sched_setaffinity`
with pid 0 act on the calling thread only): the event loop and the other threads stay SCHED_OTHER on the
other CPUs. Each setting is tried on its own and reported; one that is not permitted (no root, no
`LimitRTPRIO=`) leaves the others in force and is named in `RealtimeReport.errors`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
from dataclasses import dataclass, field

MCL_CURRENT, MCL_FUTURE = 1, 2


@dataclass
class RealtimeReport:
    """What `apply_realtime` achieved."""

    policy: str = "SCHED_OTHER"
    priority: int = 0
    cpu: int | None = None
    memory_locked: bool = False
    gc_frozen: bool = False
    errors: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        return {"policy": self.policy, "priority": self.priority, "cpu": self.cpu,
                "memory_locked": self.memory_locked, "gc_frozen": self.gc_frozen, "errors": list(self.errors)}


def apply_realtime(priority: int = 50, cpu: int | None = -1) -> RealtimeReport:
    """Make the calling thread real-time: SCHED_FIFO at `priority`, pinned to `cpu` (-1: the last CPU this
    process may use; None: no pinning), `mlockall(MCL_CURRENT | MCL_FUTURE)`, and the objects alive now
    frozen out of the collector's generations with a higher gen-0 threshold (fewer, shorter pauses)."""
    rep = RealtimeReport()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        rep.policy, rep.priority = "SCHED_FIFO", priority
    except (OSError, AttributeError) as err:
        rep.errors.append(f"SCHED_FIFO: {getattr(err, 'strerror', None) or err}")
    if cpu is not None:
        try:
            allowed = sorted(os.sched_getaffinity(0))
            target = allowed[-1] if cpu == -1 else cpu
            os.sched_setaffinity(0, {target})
            rep.cpu = target
        except (OSError, AttributeError, IndexError) as err:
            rep.errors.append(f"CPU affinity: {getattr(err, 'strerror', None) or err}")
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0:
            rep.memory_locked = True
        else:
            rep.errors.append(f"mlockall: {os.strerror(ctypes.get_errno())}")
    except OSError as err:
        rep.errors.append(f"mlockall: {err}")
    gc.freeze()
    gc.set_threshold(50_000, 20, 20)
    rep.gc_frozen = True
    return rep
