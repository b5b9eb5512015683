"""Fixtures shared across the test folders.

Under pytest-xdist (`-n 2`) session fixtures run once per worker; the expensive ones below are computed once per
test run: the first worker to need one computes it under a file lock in the run's shared temporary root, the
others read what it wrote.
"""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest


@dataclass(frozen=True)
class DemoRun:
    """One `rimless demo --out DIR` run as a user starts it: its folder, stdout, stderr and exit code."""

    out: Path
    stdout: str
    stderr: str
    returncode: int


def shared_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder every xdist worker of this run sees (the basetemp's parent under xdist, the basetemp otherwise)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if base.name.startswith("popen-gw") else base


def once_per_run(tmp_path_factory: pytest.TempPathFactory, name: str, compute: Callable[[Path], dict[str, Any]]
                 ) -> tuple[Path, dict[str, Any]]:
    """`compute(folder)` run once per test run whatever the number of workers; its JSON-able result is kept in
    `name.json` beside `folder` and read back by the other workers."""
    root = shared_root(tmp_path_factory)
    folder = root / f"shared-{name}"
    done = root / f"shared-{name}.json"
    with open(root / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not done.exists():
            folder.mkdir(exist_ok=True)
            done.write_text(json.dumps(compute(folder)))
    return folder, json.loads(done.read_text())


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> DemoRun:
    """The demo, run once per test run (it takes about a minute) for the tests that read what it wrote."""

    def run(folder: Path) -> dict[str, Any]:
        res = subprocess.run([sys.executable, "-m", "rimless", "demo", "--out", str(folder / "demo")],
                             capture_output=True, text=True, timeout=900, stdin=subprocess.DEVNULL)
        return {"stdout": res.stdout, "stderr": res.stderr, "returncode": res.returncode}

    folder, got = once_per_run(tmp_path_factory, "demo", run)
    return DemoRun(out=folder / "demo", **got)


def pytest_sessionstart(session: pytest.Session) -> None:
    """With `-n N`, compile the simulator's kernels into numba's on-disk cache once, in the controller, before
    the workers start: otherwise each worker compiles the same kernels at the same time (minutes of CPU each on
    a cold cache). A warm cache makes this a second or two. Without xdist the first test that needs a kernel
    compiles it, as before."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    head = ("import numpy as np\n"
            "from rimless.sim import fast\n"
            "from rimless.sim.model.params import WheelParams\n")
    codes = [head + "fast.warm_up()\n"
             "fast.fast_step(WheelParams(), 've', np.array([-0.465155, 2.604441]), bilateral=True)\n"]
    try:
        cores = int(config.option.numprocesses)
    except (TypeError, ValueError):  # "auto" not yet resolved
        cores = os.cpu_count() or 1
    if cores > 1:
        # on a second core meanwhile: the sliding-leg step kernel, which tests/sim/fast compiles otherwise
        # inside a worker (one mass model per kernel: rimless.sim.fast.step.STEP_MAP_CONTACT)
        codes.append(head + "try:\n"
                     "    fast.fast_step(WheelParams(mass_model='sliding-leg'), 'er', np.array([-0.465155, 2.604441]),"
                     " jacobian=True)\n"
                     "except Exception:\n"
                     "    pass\n")
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              stdin=subprocess.DEVNULL) for code in codes]
    for proc in procs:
        try:
            proc.wait(timeout=1800)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
