"""The first-use probe: a process that takes one eight-leg step (with the exact Jacobian) and prints the state
after it and, per generated function family, how many signatures each mass model's version has in this process
(compiled here); then it takes the step recorded, as `rimless sim fixed-point` does, and prints the stale entries
of the ahead plan. tests/test_first_use.py checks its output from a cold cache; tests/conftest.py runs it as the
first thing of the suite's warm-up when the cache is cold (a fresh clone: CI), so that cold compile serves both.
Both run it with RIMLESS_NO_BACKGROUND=1: the whole compile in the probe's process (rimless.sim.fast.ahead
would otherwise compile part of it in a second process, whose signatures the probe does not see)."""

from __future__ import annotations

#: Environment variable naming the file where the suite's warm-up left the probe's output (cold cache only).
RECORD_ENV = "RIMLESS_TEST_FIRST_USE_PROBE"

#: Lines the probe prints.
LINES = 9
#: Python code: prints "cold" or "warm" (was the eight-leg step kernel compiled or cached before?), then the
#: state after the step, then one line per family: name and the signature counts of mass models 0, 1, 2; then
#: "strings" and the functions of numba's string formatting the step compiled (its own messages); last
#: "stale" and the entries of rimless.sim.fast.ahead.PLAN that the step kernel did not use as written, and the
#: recorder entry if the recorded step (as `rimless sim fixed-point` takes it) called it otherwise.
PROBE = (
    "from numba.core import event\n"
    "compiled = []\n"
    "class Compiled(event.Listener):\n"
    "    def on_start(self, ev):\n"
    "        d = (ev.data or {}).get('dispatcher')\n"
    "        compiled.append(f'{d.py_func.__module__}.{d.py_func.__qualname__}' if d is not None else '')\n"
    "    def on_end(self, ev):\n"
    "        pass\n"
    "event.register('numba:compile', Compiled())\n"
    "import numpy as np\n"
    "from rimless.sim import fast\n"
    "from rimless.sim.fast import compiling, model as fm, step as fs\n"
    "from rimless.sim.model.params import WheelParams\n"
    "print('warm' if compiling.is_cached(fs.STEP_MAP_CONTACT[0]) else 'cold')\n"
    "r = fast.fast_step(WheelParams(), 'er', np.array([-0.465155, 2.604441]), jacobian=True)\n"
    "print(r.z_next[0], r.z_next[1])\n"
    "for name in ('_M', '_DL', '_DLD', '_DM', '_T'):\n"
    "    print(name, *(len(getattr(fm, name + str(i)).signatures) for i in range(3)), flush=True)\n"
    "print('strings', *(n for n in compiled if n.startswith('numba.cpython.unicode')\n"
    "                   or 'raise_with_shape_context' in n), flush=True)\n"
    "from rimless.sim.step.backend import make_map\n"
    "make_map(WheelParams(), 'er').step(np.array([-0.465155, 2.604441]), diagnostics=True)\n"
    "from rimless.sim.fast import ahead\n"
    "print('stale', *ahead.stale_entries(0), flush=True)\n"
)
