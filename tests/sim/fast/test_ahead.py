"""rimless.sim.fast.ahead: the plan names real kernels with their arity, its types, and the second process's
life (not started when turned off, stopped when the compile ends). That the plan's types are the ones the step
kernel uses is checked on a cold compile in tests/test_first_use.py."""

from __future__ import annotations

import inspect
import os
import subprocess
import sys

import psutil  # with dask.distributed
import pytest
from numba.core import types

from rimless.second_process import second_process_allowed
from rimless.sim.fast import ahead
from tests.support.interrupt import Watched


def test_every_plan_entry_is_a_kernel_with_one_type_per_parameter():
    for module, name, spec in ahead.PLAN:
        disp = ahead.dispatcher(module, name)
        assert hasattr(disp, "compile") and hasattr(disp, "py_func"), (module, name)
        assert len(inspect.signature(disp.py_func).parameters) == len(spec.split()), (module, name, spec)


def test_types_of_an_entry():
    got = ahead._types("mi i f b f1 f2", 2)
    assert got == (
        types.literal(2),
        types.int64,
        types.float64,
        types.boolean,
        types.Array(types.float64, 1, "C"),
        types.Array(types.float64, 2, "C"),
    )


def test_turned_off_it_starts_nothing(monkeypatch):
    monkeypatch.setenv("RIMLESS_NO_BACKGROUND", "1")
    assert ahead.start(0) is None
    with ahead.compiling_ahead(0):
        pass


def test_stop_ends_a_running_second_process():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    ahead.stop(proc)
    assert proc.poll() is not None
    ahead.stop(proc)  # again: nothing to do
    ahead.stop(None)


def test_ctrl_c_during_a_cold_compile_stops_both_processes(tmp_path):
    """A terminal's Ctrl-C (SIGINT to the process group) while the step kernel compiles cold with the second
    process beside it: one line `interrupted`, exit 130, no process left."""
    if not second_process_allowed():
        pytest.skip("one core: no second process")
    env = {**os.environ, "RIMLESS_CACHE_DIR": str(tmp_path)}
    env.pop("RIMLESS_NO_BACKGROUND", None)
    with Watched(
        [sys.executable, "-m", "rimless", "sim", "fixed-point", "--model", "er"],
        cwd=tmp_path,
        env=env,
        new_session=True,
    ) as cmd:
        # the event: the second process has started beside the cold compile (rimless.sim.fast.ahead)
        cmd.wait_for(stage="compiling ahead in a second process")
        children = psutil.Process(cmd.proc.pid).children(recursive=True)
        assert children, "no second process while the step kernel compiled cold"
        cmd.interrupt()  # to the process group
        res = cmd.finish(timeout_s=60)
    assert res.returncode == 130, res.stderr[-2000:]
    assert [line for line in res.stderr.splitlines() if line.strip()][-1:] == ["interrupted"], res.stderr[-2000:]
    _, alive = psutil.wait_procs(children, timeout=60)  # the event: each one's end
    assert not [c for c in alive if c.is_running() and c.status() != psutil.STATUS_ZOMBIE]
