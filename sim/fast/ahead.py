"""Compiling ahead, in a second process, the kernels a cold step kernel reaches last.

numba compiles a kernel's callees depth first, one after the other, in the calling process: the step kernel of
one mass model (`rimless.sim.fast.step.STEP_MAP_CONTACT`) spends about 35 s of one core on a cold cache. Some of
its callees are reached only after the integrator (`rk.run_phase`, about half of it) is compiled: the guard
gradient, the impact, the single-support force, the energy, and inside the integrator the RK stages, the dense
output and the guard root finders. `start(mi)` compiles exactly those (same functions, same argument types, so
the same cache entries) in a second process on another core from the moment the step kernel starts; the step
kernel then loads them from numba's on-disk cache (`compiling.lock_cache_saves` makes the two processes' cache
writes safe) instead of compiling them. The machine code is the same whichever process compiled it.

Then, while the step kernel's own code is generated, the second process compiles the phase integrator's entry
from Python (`rk.RUN_PHASE[mi]`, as `FastIntegrator.run_phase` calls it: the recorded step of a command that
reports a gait), once `rk.run_phase` is in the cache (`compile_recorder`).

Last, the second process compiles the exact friction Jacobian's entry points (`friction_tangent_calls`:
rimless.sim.fast.friction's section, event and touchdown tangents, as
rimless.sim.step.fast_map.friction_step(jacobian=True) calls them; about 7 s of one core, measured at load 10):
without them a first `rimless sim gaits --guide-friction-n 0.3` compiled them itself (`warm_up` compiles them too).

`compiling_ahead(mi)` is the context a cold step kernel compiles in. `PLAN` names each function and its argument types (a token per argument, see `_types`); a plan entry that no
longer matches the code only costs the second core some work. Off with one core or ``RIMLESS_NO_BACKGROUND=1``.

May import: rimless.second_process; numba, numpy, rimless.sim.fast, rimless.sim.model (in the second process).
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

from rimless.second_process import second_process_allowed

#: (module of rimless.sim.fast, function, argument types), in the order the step kernel reaches them.
PLAN: tuple[tuple[str, str, str], ...] = (
    ("rk", "_rk_stages", "mi i f1 f1 f1 f f2 f1 f1 f1 f1 b b"),
    ("rk", "_build_dense", "mi i f1 f1 f f2 f2 f1 f1 f1 b b"),
    ("rk", "_brent", "mi i f1 i b f f f f f2 f1"),
    ("rk", "_first_dip", "mi i f1 i f f f2 f1 f f"),
    ("model", "guard_gradient", "mi i i f1 f1"),
    ("step", "single_support_force", "mi i f1 f2 f1 f1"),
    ("model", "impact", "mi f1 f1 f2 b"),
    ("model", "energy", "mi f1 f1 f1"),
)


def _types(spec: str, mi: int) -> tuple[Any, ...]:
    """The numba argument types of a PLAN entry: mi (the mass model index as a literal, as the kernels see
    it), i (int64), f (float64), b (bool), f1 / f2 (C-contiguous writable float64 arrays of 1 / 2 dimensions)."""
    from numba.core import types

    table = {
        "i": types.int64,
        "f": types.float64,
        "b": types.boolean,
        "f1": types.Array(types.float64, 1, "C"),
        "f2": types.Array(types.float64, 2, "C"),
    }
    return tuple(types.literal(mi) if tok == "mi" else table[tok] for tok in spec.split())


def dispatcher(module: str, name: str) -> Any:
    """The kernel a PLAN entry names."""
    import importlib

    return getattr(importlib.import_module(f"rimless.sim.fast.{module}"), name)


def compile_entry(module: str, name: str, spec: str, mi: int) -> bool:
    """Compile (or load from numba's cache) one PLAN entry for mass model index ``mi``; False if it fails."""
    try:
        dispatcher(module, name).compile(_types(spec, mi))
    except Exception:  # noqa: BLE001 (a stale entry: the step kernel compiles that function itself)
        return False
    return True


def recorded_phase_call(params: Any) -> tuple[Any, tuple[Any, ...]]:
    """(`rk.RUN_PHASE[mi]` of ``params``' mass model, its arguments for 1 ms of double support recorded with the
    dissipated energy, from Table 1's ER gait): the call that compiles or loads the integrator's entry from
    Python with the argument types of every such call (`rk.phase_call_args`, as `FastIntegrator.run_phase`)."""
    import numpy as np

    from rimless.sim.fast import rk
    from rimless.sim.fast.model import MASS_MODEL_INDEX
    from rimless.sim.model.dynamics import DLSP
    from rimless.sim.model.guards import DIRECTION
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section

    mech = Mechanics.of(params)
    y0 = state_from_section(mech, np.array([-0.465155, 2.604441]))
    return rk.RUN_PHASE[MASS_MODEL_INDEX[params.mass_model]], rk.phase_call_args(
        DLSP, mech.p, y0, 0.0, (1,), (DIRECTION[1],), 1e-3, 1e-10, 1e-12, True, 1e-3, 10_000
    )


def compile_recorder(mi: int, wait_s: float = 120.0) -> bool:
    """Compile (or load) `rk.RUN_PHASE[mi]` (`recorded_phase_call` of Table 1's wheel with mass model index
    ``mi``) once `rk.run_phase` has an entry in numba's cache (waits at most ``wait_s`` s for it: the step kernel
    compiles it); False if the call fails."""
    import time

    from rimless.sim.fast import compiling, rk

    deadline = time.monotonic() + wait_s
    while not compiling.is_cached(rk.run_phase) and time.monotonic() < deadline:
        time.sleep(0.2)
    try:
        from rimless.sim.fast.model import MASS_MODEL_INDEX
        from rimless.sim.model.params import WheelParams

        name = next(n for n, i in MASS_MODEL_INDEX.items() if i == mi)
        entry, args = recorded_phase_call(WheelParams(mass_model=name))
        entry(*args)
    except Exception:  # noqa: BLE001 (the command compiles it itself)
        return False
    return True


#: guide friction (N) of the wheel whose friction Jacobian's entry points `friction_tangent_calls` calls (any
#: F_c > 0: the kernels take it as a run-time value of p)
WARM_FRICTION_N = 0.3


def friction_tangent_calls(params: Any) -> list[tuple[Any, tuple[Any, ...]]]:
    """The exact friction Jacobian's entry points of ``params``' mass model (rimless.sim.fast.friction's
    SECTION, EVENT_TANGENT and TOUCHDOWN_TANGENT), each with arguments of the types
    rimless.sim.step.fast_map.friction_step(jacobian=True) calls it with: Table 1's ER section point, its state in
    the friction phase double support starts in (F_c `WARM_FRICTION_N` where ``params`` has none) as both ends
    of a lift-off, unit tangents. Calling them compiles (or loads) the versions every such step uses; their
    results mean nothing (an event tangent of a phase to itself)."""
    import numpy as np

    from rimless.sim.fast import friction as fj
    from rimless.sim.fast.model import MASS_MODEL_INDEX
    from rimless.sim.model.dynamics import DLSP
    from rimless.sim.model.friction import initial_phase
    from rimless.sim.model.guards import LIFTOFF_A
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section

    if not params.guide_friction_n > 0.0:
        params = params.replace(guide_friction_n=WARM_FRICTION_N)
    mi = MASS_MODEL_INDEX[params.mass_model]
    mech = Mechanics.of(params)
    p = np.asarray(mech.p, dtype=np.float64)
    z = np.array([-0.465155, 2.604441])
    code, y = initial_phase(mech, DLSP, state_from_section(mech, z))
    y = np.asarray(y, dtype=np.float64)
    V = np.ascontiguousarray(np.eye(10)[:, [2, 7]])
    return [
        (fj.SECTION[mi], (z, p)),
        (fj.EVENT_TANGENT[mi], (int(code), int(LIFTOFF_A), y.copy(), int(code), y.copy(), p, V)),
        (fj.TOUCHDOWN_TANGENT[mi], (int(code), y.copy(), p, V)),
    ]


def compile_friction(mi: int) -> bool:
    """Compile (or load) the friction Jacobian's entry points of mass model index ``mi`` (`friction_tangent_calls`
    of Table 1's wheel with that mass model); False if a call fails."""
    try:
        from rimless.sim.fast.model import MASS_MODEL_INDEX
        from rimless.sim.model.params import WheelParams

        name = next(n for n, i in MASS_MODEL_INDEX.items() if i == mi)
        for entry, args in friction_tangent_calls(WheelParams(mass_model=name)):
            entry(*args)
    except Exception:  # noqa: BLE001 (the first friction step compiles them itself)
        return False
    return True


def compile_plan(mi: int) -> None:
    """Compile (or load) every PLAN entry for mass model index ``mi`` into numba's cache, then the recorder
    entry, then the friction Jacobian's entry points (the second process)."""
    for module, name, spec in PLAN:
        compile_entry(module, name, spec, mi)
    compile_recorder(mi)
    compile_friction(mi)


def stale_entries(mi: int) -> list[str]:
    """In a process that has just run the step kernel of ``mi`` and a recorded step: the PLAN entries the kernel
    did not use as written (never called, or called with other argument types, so that compiling the entry adds
    a version), and the recorder entry if the recorded step called it otherwise."""
    stale = []
    for module, name, spec in PLAN:
        disp = dispatcher(module, name)
        before = len(disp.overloads)
        if before == 0 or not compile_entry(module, name, spec, mi) or len(disp.overloads) != before:
            stale.append(f"{module}.{name}")
    from rimless.sim.fast import rk

    recorder = rk.RUN_PHASE[mi]
    before = len(recorder.overloads)
    if before == 0 or not compile_recorder(mi, wait_s=0.0) or len(recorder.overloads) != before:
        stale.append(f"rk.{recorder.py_func.__name__}")
    return stale


def start(mi: int) -> subprocess.Popen[bytes] | None:
    """The second process compiling PLAN for ``mi`` (None: not started). Quiet, deaf to Ctrl-C (the caller
    stops it with `stop`)."""
    if not second_process_allowed():
        return None
    code = f"from rimless.sim.fast import ahead; ahead.compile_plan({int(mi)})"
    import signal

    try:
        return subprocess.Popen(
            [sys.executable, "-c", code],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
        )
    except OSError:
        return None


def stop(proc: subprocess.Popen[bytes] | None) -> None:
    """End the second process if it still runs (its finished cache entries stay)."""
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    except KeyboardInterrupt:  # a second Ctrl-C while it ends: it is killed all the same, then the Ctrl-C goes on
        proc.kill()
        raise


@contextlib.contextmanager
def compiling_ahead(mi: int) -> Iterator[None]:
    """While the block runs, PLAN for ``mi`` compiles in a second process (stopped when the block ends)."""
    proc = start(mi)
    try:  # the stage is reported inside: a Ctrl-C that lands while it is written still stops the second process
        if proc is not None:
            from rimless.progress import stage

            stage("compiling ahead in a second process")
        yield
    finally:
        stop(proc)
