"""`rimless sim basin` on Dask (issue 33): the grid's rows on a real 2-worker local cluster give the same fates as
in this process, and a Ctrl-C while the workers compute is exit 130 with `interrupted` and nothing left behind."""

from __future__ import annotations

import os
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest

from rimless.sim.studies.basin import DASK_MIN_POINTS, WheelSlopeMap, resolve_scheduler
from tests.support.cli_lines import stderr_lines
from tests.support.interrupt import Watched


def test_the_wheels_map_pickles_as_its_recipe_and_gives_the_same_step():
    from rimless.sim.model.params import WheelParams

    smap = WheelSlopeMap(WheelParams(), "er", "auto", 1e-10)
    z = np.array([-0.45, 2.5])
    before = smap(z, 0.05)
    copy = pickle.loads(pickle.dumps(smap))
    assert copy._map is None and smap._map is not None  # the compiled map stays where it was built
    assert np.array_equal(copy(z, 0.05), before)


def test_auto_puts_only_big_grids_on_a_cluster(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv("RIMLESS_NO_BACKGROUND", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: {0, 1})
    assert resolve_scheduler("auto", DASK_MIN_POINTS - 1) == "sync"
    assert resolve_scheduler("auto", DASK_MIN_POINTS) == "local"
    assert resolve_scheduler("sync", 10**6) == "sync" and resolve_scheduler("tcp://h:1", 4) == "tcp://h:1"
    monkeypatch.setenv("RIMLESS_NO_BACKGROUND", "1")
    assert resolve_scheduler("auto", DASK_MIN_POINTS) == "sync"


@pytest.mark.slow
def test_a_two_worker_cluster_gives_the_fates_of_this_process():
    """The ER wheel's basin on a 7 x 7 grid: every point's fate and step count, and the JSON, equal between the
    in-process scheduler and a real LocalCluster of two worker processes (rows in any order of completion)."""
    from rimless.sim import Wheel

    wheel = Wheel(model="er")
    seen: list[tuple[int, int]] = []
    sync = wheel.basin(grid=7, steps=60, scheduler="sync")
    dask = wheel.basin(grid=7, steps=60, scheduler="local", workers=2, progress=lambda i, n: seen.append((i, n)))
    assert (sync.data["scheduler"], dask.data["scheduler"], dask.data["workers"]) == ("sync", "local", 2)
    assert list(sync.points["fate"]) == list(dask.points["fate"])
    assert np.array_equal(sync.points["steps"], dask.points["steps"])
    assert len(set(sync.points["fate"])) >= 2  # a grid with more than one fate, so the order matters
    a, b = dict(sync.data), dict(dask.data)
    for d in (a, b):
        del d["scheduler"], d["workers"]
    assert a == b
    assert seen[-1] == (49, 49) and [i for i, _ in seen] == sorted(i for i, _ in seen)


@pytest.mark.slow
def test_ctrl_c_while_the_workers_compute_the_basin(tmp_path: Path):
    """SIGINT to the process group (a terminal's Ctrl-C) once the rows are on the two workers."""
    args = ["sim", "basin", "--grid", "90", "--scheduler", "local", "--workers", "2"]
    with Watched([sys.executable, "-m", "rimless", *args], cwd=tmp_path, new_session=True) as cmd:
        cmd.wait_for(stage="grid points submitted to 2 worker(s)")
        assert cmd.proc.poll() is None, "".join(cmd.lines["stderr"])[-2000:]
        cmd.interrupt()
        res = cmd.finish(timeout_s=60)
    assert res.returncode == 130, res.stdout[-2000:] + res.stderr[-2000:]
    assert stderr_lines(res.stderr) == ["interrupted"], res.stderr[-3000:]
    assert "Traceback" not in res.stdout + res.stderr
    assert not list(tmp_path.iterdir())
