"""rimless.sim.fast.ahead: the plan names real kernels with their arity, its types, and the second process's
life (not started when turned off, stopped when the compile ends). That the plan's types are the ones the step
kernel uses is checked on a cold compile in tests/test_first_use.py."""

from __future__ import annotations

import inspect
import subprocess
import sys

from numba.core import types

from rimless.sim.fast import ahead


def test_every_plan_entry_is_a_kernel_with_one_type_per_parameter():
    for module, name, spec in ahead.PLAN:
        disp = ahead.dispatcher(module, name)
        assert hasattr(disp, "compile") and hasattr(disp, "py_func"), (module, name)
        assert len(inspect.signature(disp.py_func).parameters) == len(spec.split()), (module, name, spec)


def test_types_of_an_entry():
    got = ahead._types("mi i f b f1 f2", 2)
    assert got == (types.literal(2), types.int64, types.float64, types.boolean,
                   types.Array(types.float64, 1, "C"), types.Array(types.float64, 2, "C"))


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
