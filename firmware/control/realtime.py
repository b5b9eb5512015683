"""Real-time settings for the control thread (Linux): SCHED_FIFO, one CPU, memory locked, the garbage
collector kept out of the way.

`apply_realtime` is called by the control thread itself at start (`sched_setscheduler` and `sched_setaffinity`
with pid 0 act on the calling thread only). Each setting is tried on its own and reported; one that is not
permitted (no root, no `LimitRTPRIO=`) leaves the others in force and is named in `RealtimeReport.errors`.

The GIL: the control thread wakes on time but must take the GIL from whichever thread holds it. A
SCHED_OTHER holder preempted by any busy process on its CPU keeps the GIL for a scheduler slice (several ms).
So the process's other threads (event loop, reserved UDP path, watchdog, log writer, and the threads they
start later, which inherit it) become SCHED_FIFO at the lowest priority, `OTHERS_PRIORITY`, on the CPUs the
control thread does not use: no ordinary process preempts a GIL holder any more, and the kernel's real-time
throttling (95 % of each second by default) still leaves ordinary processes a share. `restore_others` puts
them back as they were when the control thread ends.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
import threading
from dataclasses import dataclass, field

MCL_CURRENT, MCL_FUTURE = 1, 2
OTHERS_PRIORITY = 1  # SCHED_FIFO priority of the process's other threads (the GIL holders)


@dataclass
class RealtimeReport:
    """What `apply_realtime` achieved."""

    policy: str = "SCHED_OTHER"
    priority: int = 0
    cpu: int | None = None
    memory_locked: bool = False
    gc_frozen: bool = False
    others_policy: str = "SCHED_OTHER"  # the process's other threads
    others_cpus: list[int] | None = None
    errors: list[str] = field(default_factory=list)
    # (policy, priority, CPUs) the other threads had, restored by `restore_others`
    _others_before: tuple[int, int, set[int]] | None = None
    _own_tid: int = 0

    def to_json(self) -> dict[str, object]:
        return {
            "policy": self.policy,
            "priority": self.priority,
            "cpu": self.cpu,
            "memory_locked": self.memory_locked,
            "gc_frozen": self.gc_frozen,
            "others_policy": self.others_policy,
            "others_cpus": self.others_cpus,
            "errors": list(self.errors),
        }


def _other_tids(own: int) -> list[int]:
    try:
        return [int(t) for t in os.listdir("/proc/self/task") if int(t) != own]
    except OSError:
        return []


def _raise_others(rep: RealtimeReport, own: int, cpus: set[int] | None) -> None:
    """The other threads SCHED_FIFO at `OTHERS_PRIORITY`, on `cpus` (None: where they are)."""
    tids = _other_tids(own)
    if not tids:
        return
    try:
        first = tids[0]
        before = (os.sched_getscheduler(first), os.sched_getparam(first).sched_priority, os.sched_getaffinity(first))
        for tid in tids:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(OTHERS_PRIORITY))
            if cpus:
                os.sched_setaffinity(tid, cpus)
        rep._others_before = before
        rep.others_policy = "SCHED_FIFO"
        rep.others_cpus = sorted(cpus) if cpus else None
    except (OSError, AttributeError) as err:
        rep.errors.append(f"other threads SCHED_FIFO: {getattr(err, 'strerror', None) or err}")


def restore_others(rep: RealtimeReport) -> None:
    """Every other thread of the process that is SCHED_FIFO at `OTHERS_PRIORITY` back to the policy and CPUs
    they had before `apply_realtime` (called from the control thread as it ends)."""
    if rep._others_before is None:
        return
    policy, prio, cpus = rep._others_before
    for tid in _other_tids(rep._own_tid):
        try:
            if os.sched_getscheduler(tid) == os.SCHED_FIFO and os.sched_getparam(tid).sched_priority == OTHERS_PRIORITY:
                os.sched_setscheduler(tid, policy, os.sched_param(prio))
                os.sched_setaffinity(tid, cpus)
        except OSError:  # the thread ended meanwhile
            continue
    rep._others_before = None


def apply_realtime(priority: int = 50, cpu: int | None = -1) -> RealtimeReport:
    """Make the calling thread real-time: SCHED_FIFO at `priority`, pinned to `cpu` (-1: the last CPU this
    process may use; None: no pinning), `mlockall(MCL_CURRENT | MCL_FUTURE)`, and the objects alive now
    frozen out of the collector's generations with a higher gen-0 threshold (fewer, shorter pauses); the
    process's other threads SCHED_FIFO at `OTHERS_PRIORITY` on the remaining CPUs (see the module docstring)."""
    rep = RealtimeReport()
    rep._own_tid = threading.get_native_id()
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        rep.policy, rep.priority = "SCHED_FIFO", priority
    except (OSError, AttributeError) as err:
        rep.errors.append(f"SCHED_FIFO: {getattr(err, 'strerror', None) or err}")
    others: set[int] | None = None
    if cpu is not None:
        try:
            allowed = sorted(os.sched_getaffinity(0))
            target = allowed[-1] if cpu == -1 else cpu
            os.sched_setaffinity(0, {target})
            rep.cpu = target
            others = set(allowed) - {target}
        except (OSError, AttributeError, IndexError) as err:
            rep.errors.append(f"CPU affinity: {getattr(err, 'strerror', None) or err}")
    if rep.policy == "SCHED_FIFO":
        _raise_others(rep, rep._own_tid, others or None)
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
