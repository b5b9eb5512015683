"""rimless.sim.fast.ahead: the plan names real kernels with their arity, its types, and the second process's
life (not started when turned off, stopped when the compile ends). That the plan's types are the ones the step
kernel uses is checked on a cold compile in tests/test_first_use.py."""

from __future__ import annotations

import inspect
import os
import signal
import subprocess
import sys
import time

import psutil  # with dask.distributed
import pytest
from numba.core import types

from rimless.second_process import second_process_allowed
from rimless.sim.fast import ahead


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
    proc = subprocess.Popen(
        [sys.executable, "-m", "rimless", "sim", "fixed-point", "--model", "er"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 60
        children: list = []
        while not children and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            children = psutil.Process(proc.pid).children(recursive=True)
        assert children, "no second process while the step kernel compiled cold"
        time.sleep(1.0)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err[-2000:]
    assert [line for line in err.splitlines() if line.strip()][-1:] == ["interrupted"], err[-2000:]
    time.sleep(0.5)
    assert not [c for c in children if c.is_running() and c.status() != psutil.STATUS_ZOMBIE]
