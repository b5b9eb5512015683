"""The control thread's real-time settings raise the process's other threads (the GIL holders) to the lowest
SCHED_FIFO priority on the other CPUs, and put them back when it ends. Run in a child process (the settings
are per thread and would outlive the test otherwise); as root only (elsewhere SCHED_FIFO is refused)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

CHILD = r"""
import json, os, threading
from rimless.firmware.control.realtime import OTHERS_PRIORITY, apply_realtime, restore_others

stop = threading.Event()
other = threading.Thread(target=stop.wait)  # a thread that exists before: the event loop's place
other.start()
out = {}

def control():
    rep = apply_realtime(50, -1)
    late = threading.Thread(target=stop.wait)  # started by the main thread later: inherits its setting
    out["report"] = rep.to_json()
    t = other.native_id
    out["during"] = [os.sched_getscheduler(t) == os.SCHED_FIFO, os.sched_getparam(t).sched_priority,
                     sorted(os.sched_getaffinity(t)), os.sched_getscheduler(0) == os.SCHED_FIFO,
                     os.sched_getparam(0).sched_priority]
    restore_others(rep)
    out["after"] = [os.sched_getscheduler(t) == os.SCHED_OTHER, sorted(os.sched_getaffinity(t))]

th = threading.Thread(target=control)
th.start(); th.join()
stop.set(); other.join()
out["main_after"] = os.sched_getscheduler(0) == os.SCHED_OTHER
out["ncpu"] = sorted(os.sched_getaffinity(0))
print(json.dumps(out))
"""


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="SCHED_FIFO needs root")
def test_the_gil_holders_run_sched_fifo_below_the_control_thread_and_are_restored() -> None:
    """Fails before this change: the other threads stayed SCHED_OTHER, so a busy process preempted the GIL
    holder and the control thread waited for the GIL for a scheduler slice (1.2-2.4 ms p99 lateness)."""
    proc = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    rep = out["report"]
    assert rep["policy"] == "SCHED_FIFO" and rep["others_policy"] == "SCHED_FIFO", rep
    is_fifo, prio, cpus, control_fifo, control_prio = out["during"]
    assert is_fifo and prio == 1 and control_fifo and control_prio == 50
    if len(out["ncpu"]) > 1:
        assert rep["cpu"] not in cpus and cpus == rep["others_cpus"]
    assert out["after"][0] and out["after"][1] == out["ncpu"]
    assert out["main_after"]
