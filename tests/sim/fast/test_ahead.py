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


#: in a fresh process: warm_up, then the friction Jacobian's entry points' versions (compiled or loaded: numba's
#: overloads), then one friction step with its Jacobian on another wheel and model, then the versions again
_FRICTION_PROBE = """
import numpy as np
from rimless.sim import fast
from rimless.sim.fast import ahead, friction as fj
from rimless.sim.model.params import WheelParams
from rimless.sim.step.fast_map import friction_step
kernels = (fj.SECTION[0], fj.EVENT_TANGENT[0], fj.TOUCHDOWN_TANGENT[0])
fast.warm_up(("er",))
print(*(len(k.overloads) for k in kernels))
away = dict(hub_mass_kg=2.3, leg_mass_kg=0.05, inertia_kg_m2=0.06, stiffness_n_per_m=1800.0, damping_ns_per_m=4.0)
r = friction_step(WheelParams(guide_friction_n=0.1, **away), "ve", np.array([-0.42, 2.3]), jacobian=True)
print(*(len(k.overloads) for k in kernels), len(r.events))
print(ahead.compile_friction(0), *(len(k.overloads) for k in kernels))
"""


def test_warm_up_compiles_the_friction_jacobians_kernels_as_a_friction_step_calls_them():
    """`warm_up` (and the second process, `compile_friction`) compile the exact friction Jacobian's entry points
    with the argument types friction_step(jacobian=True) uses: after it, a friction step with its Jacobian (another
    wheel, model and F_c) adds no version of them, i.e. compiles nothing on first use. On main warm_up left them
    out (0 versions after it; the first such step compiled them: 6.7 s CPU at load 10, session 23)."""
    res = subprocess.run(
        [sys.executable, "-c", _FRICTION_PROBE], capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL
    )
    assert res.returncode == 0, res.stderr[-2000:]
    warmed, stepped, again = (line.split() for line in res.stdout.splitlines()[-3:])
    assert warmed == ["1", "1", "1"], res.stdout
    assert stepped[:3] == warmed and int(stepped[3]) > 2, res.stdout  # events crossed: lift-off, slips, touchdown
    assert again == ["True", *warmed], res.stdout


def test_the_second_process_compiles_the_friction_jacobian_last(monkeypatch):
    """compile_plan: the PLAN entries, the recorder, then the friction Jacobian's entry points (after the step
    kernel's own callees: a cold step kernel waits on those, a friction step later on these)."""
    calls: list[str] = []
    monkeypatch.setattr(ahead, "compile_entry", lambda module, name, spec, mi: calls.append(f"{module}.{name}"))
    monkeypatch.setattr(ahead, "compile_recorder", lambda mi: calls.append("recorder"))
    monkeypatch.setattr(ahead, "compile_friction", lambda mi: calls.append(f"friction {mi}"))
    ahead.compile_plan(1)
    assert calls == [*(f"{m}.{n}" for m, n, _ in ahead.PLAN), "recorder", "friction 1"]


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
