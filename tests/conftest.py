"""Fixtures shared across the test folders.

Under pytest-xdist (`-n 2`) session fixtures run once per worker; the expensive ones below are computed once per
test run: the first worker to need one computes it under a file lock in the run's shared temporary root, the
others read what it wrote.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.support import first_use
from tests.support.readme_run import DEMO_COMMAND, DEMO_FOLDER, readme_env


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


def once_per_run(
    tmp_path_factory: pytest.TempPathFactory, name: str, compute: Callable[[Path], dict[str, Any]]
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
    """The README's `rimless demo`, run as written once per test run (in a folder with `.venv` pointing at the
    running environment) for the README's test and the tests that read what it wrote."""

    def run(folder: Path) -> dict[str, Any]:
        (folder / ".venv").symlink_to(Path(sys.prefix))
        res = subprocess.run(
            ["bash", "-c", DEMO_COMMAND],
            cwd=folder,
            env=readme_env(),
            capture_output=True,
            text=True,
            timeout=900,
            stdin=subprocess.DEVNULL,
        )
        return {"stdout": res.stdout, "stderr": res.stderr, "returncode": res.returncode}

    folder, got = once_per_run(tmp_path_factory, "demo", run)
    return DemoRun(out=folder / DEMO_FOLDER, **got)


def pytest_configure(config: pytest.Config) -> None:
    """The run caches bytecode even where the environment says not to (PYTHONDONTWRITEBYTECODE, set on the
    shared VM): every `rimless` subprocess of the tests otherwise compiles the project's modules from source
    again (about 0.1 s each, hundreds of times). `__pycache__/` is ignored by git."""
    if os.environ.pop("PYTHONDONTWRITEBYTECODE", None) is not None:
        sys.dont_write_bytecode = False


_WARM_UP: list[subprocess.Popen[bytes]] = []  # the controller's compiling processes (pytest_sessionstart)
_warm_up_lock = threading.Lock()  # _WARM_UP and _finished change under it
_finished = False  # in the controller: the session ended (no more compiling processes)
_kernels_ready = False  # in a worker: the controller's compile is done

#: the file the controller writes once its compiling processes ended; xdist workers hold every test outside
#: `KERNEL_FREE` until it exists (pytest_runtest_setup)
KERNELS_READY_ENV = "RIMLESS_TEST_KERNELS_READY"

#: tests that never run the simulator's compiled kernels: the firmware's (it cannot import the simulator,
#: docs/architecture.md), which spend much of their time on the fake robot's clock (paced to the wall clock)
KERNEL_FREE = ("tests/firmware/",)


def kernel_free(item: pytest.Item) -> bool:
    return item.nodeid.startswith(KERNEL_FREE)


def pytest_sessionstart(session: pytest.Session) -> None:
    """With `-n N`, compile the simulator's kernels into numba's on-disk cache once, in the controller, while the
    workers start, collect and run the `KERNEL_FREE` tests (ordered first); the other tests wait until it is done
    (pytest_runtest_setup). Otherwise each worker compiles the same kernels at the same time (minutes of CPU each
    on a cold cache). A warm cache makes this a second or two. Without xdist the first test that needs a kernel
    compiles it."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    threading.Thread(target=_say_what_still_runs, args=(config,), daemon=True).start()
    head = "import numpy as np\nfrom rimless.sim import fast\nfrom rimless.sim.model.params import WheelParams\n"
    # first the first-use probe (tests/test_first_use.py): on a cold cache its compile is the one the suite
    # needs anyway, and its output, left for the workers, spares that test a cold compile of its own
    folder = Path(tempfile.mkdtemp(prefix="rimless-first-use-"))
    record = folder / "probe.txt"
    os.environ[first_use.RECORD_ENV] = str(record)  # the workers, started after this hook, inherit it
    ready = folder / "kernels-ready"
    os.environ[KERNELS_READY_ENV] = str(ready)
    codes = [
        first_use.PROBE + head + "fast.warm_up()\n"
        "fast.fast_step(WheelParams(), 've', np.array([-0.465155, 2.604441]), bilateral=True)\n"
    ]
    if full_run(config):
        # the sliding-leg step kernel, which the tests marked `full` in tests/sim/fast use (one mass model per
        # kernel: rimless.sim.fast.step.STEP_MAP_CONTACT); a worker would compile it otherwise
        codes.append(
            head + "try:\n"
            "    fast.fast_step(WheelParams(mass_model='sliding-leg'), 'er', np.array([-0.465155, 2.604441]),"
            " jacobian=True)\n"
            "except Exception:\n"
            "    pass\n"
        )
    say(
        config,
        "rimless: compiling the simulator's kernels for the tests (about a minute on an empty cache, seconds once "
        "cached; longer on a busy machine): the firmware's tests run meanwhile, the others wait for it",
    )
    with open(record, "w") as probe_out:
        # one process each: the workers use the other core (no second process compiling ahead,
        # rimless.sim.fast.ahead)
        env = {**os.environ, "RIMLESS_NO_BACKGROUND": "1"}
        _WARM_UP.extend(
            _start([sys.executable, "-c", code], env, probe_out if i == 0 else subprocess.DEVNULL)
            for i, code in enumerate(codes)
        )
    threading.Thread(target=_mark_ready_after_warm_up, args=(ready, env, record, config), daemon=True).start()


_say_lock = threading.Lock()


def say(config: pytest.Config, line: str) -> None:
    """One line on the terminal through pytest's terminal reporter (flushed at once: under `-q`, with the workers
    waiting, nothing else shows that the run goes on). Also from the controller's compiling thread: the lock
    keeps its lines whole; a progress dot of the main thread may land just before one."""
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is None:
        return
    with _say_lock:
        reporter.write_line(line)
        reporter.flush()


#: while the controller compiles, a line this often says that it still does (seconds)
STILL_COMPILING_EVERY_S = 60.0


#: Compiled after the step kernels, while the kernel-free tests still run: kernels that single tests call
#: directly from Python (the generic dispatches over mass models in tests/sim/fast/test_reduced.py, the friction
#: integrator of tests/sim/fast/test_friction_fast.py's single leg), with the same argument types. Two workers
#: otherwise compiled the first at once (15-18 s each) and the second took 18 s inside one test.
TEST_KERNELS = """
import math
import numpy as np
from rimless.sim.fast import FastIntegrator, model as fm
from rimless.sim.integrate.friction import run_with_friction
from rimless.sim.model.dynamics import SLSP_CLUTCHED
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
mech = Mechanics.of(WheelParams())
mi = fm.MASS_MODEL_INDEX["eight-leg"]
q, qd = np.array([0.1, 0.0, 0.2, 0.22, 0.23]), np.array([0.1, 0.2, 1.0, 0.1, 0.1])
fm.accel_reduced(mi, 0, q, qd, mech.p, np.empty(5), np.zeros(4), np.empty(fm.WORKSPACE_SIZE))
fm.accel_kkt(mi, 0, q, qd, mech.p, np.empty(5), np.zeros(4))
fm.accel_directional(mi, 0, q, qd, mech.p, np.empty(5), np.zeros(4), np.ones((10, 2)), np.empty((5, 2)),
                     np.empty(fm.WORKSPACE_SIZE + 5))
fm.accel_jacobian(mi, 0, q, qd, mech.p, np.empty(5), np.zeros(4), np.empty((5, 10)), np.empty((4, 10)))
p = WheelParams(mass_model="sliding-leg", damping_ns_per_m=0.0, slope_rad=0.0, guide_friction_n=1.0)
mech = Mechanics.of(p)
y0 = np.zeros(10)
y0[3], y0[4] = p.leg_length_m, p.leg_length_m + 0.004
t_end = math.pi * math.sqrt(p.leg_mass_kg / p.k)
run_with_friction(FastIntegrator(rtol=1e-12, atol=1e-14), mech, SLSP_CLUTCHED, y0, 0.0, (), t_end,
                  record_dt=t_end / 20)
"""


def _mark_ready_after_warm_up(ready: Path, env: dict[str, str], record: Path, config: pytest.Config) -> None:
    """In the controller: wait for the compiling processes (at most 30 min each); then compile `TEST_KERNELS`
    and, if the kernels were already cached, run the first-use probe again in an empty cache of its own (its
    output goes to `record`: tests/test_first_use.py needs a cold compile, which otherwise two workers ran at
    once, 37-40 s each); then write `ready`. Says on the terminal every minute that it still compiles, and
    when it is done."""
    t0 = time.monotonic()

    def still(what: str) -> None:
        say(config, f"rimless: still compiling {what} ({(time.monotonic() - t0) / 60:.0f} min so far)")

    for proc in list(_WARM_UP):
        _wait_or_kill(proc, on_every_minute=lambda: still("the simulator's kernels"))
    found = record.read_text().splitlines()[:1] if record.is_file() else []
    more = []
    with _warm_up_lock:  # no process starts after the session's end has killed the others
        if not _finished:
            more.append(_start([sys.executable, "-c", TEST_KERNELS], env, subprocess.DEVNULL))
            if found == ["warm"]:
                cold = {k: v for k, v in env.items() if k != "NUMBA_CACHE_DIR"}
                cold["RIMLESS_CACHE_DIR"] = str(record.parent / "cold-cache")
                with open(record, "w") as probe_out:
                    more.append(_start([sys.executable, "-c", first_use.PROBE], cold, probe_out))
            _WARM_UP.extend(more)
    for proc in more:
        _wait_or_kill(
            proc, on_every_minute=lambda: still("the kernels single tests call (and the first-use test's cold compile)")
        )
    with contextlib.suppress(OSError):  # the session ended first and removed the folder
        ready.touch()
    with _warm_up_lock:
        if not _finished:
            say(
                config,
                f"rimless: the simulator's kernels are compiled ({time.monotonic() - t0:.0f} s): the tests that "
                "need them run now",
            )


def _start(args: list[str], env: dict[str, str], stdout: Any) -> subprocess.Popen[bytes]:
    """A compiling process at the tests' own priority. It ran at nice 15 while the firmware's fakes ran on the
    wall clock; now they run on a virtual clock (firmware/clock.py), and at nice 15 beside two busy loops the
    compile got almost no CPU and the suite never finished."""
    return subprocess.Popen(args, stdout=stdout, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL, env=env)


def _wait_or_kill(
    proc: subprocess.Popen[bytes], timeout_s: float = 1800, on_every_minute: Callable[[], None] | None = None
) -> None:
    """Wait for `proc` (killed after `timeout_s`), calling `on_every_minute()` each STILL_COMPILING_EVERY_S."""
    deadline = time.monotonic() + timeout_s
    while True:
        left = deadline - time.monotonic()
        try:
            proc.wait(timeout=max(0.0, min(left, STILL_COMPILING_EVERY_S)))
            return
        except subprocess.TimeoutExpired:
            if time.monotonic() >= deadline:
                proc.kill()
                proc.wait()
                return
            if on_every_minute is not None:
                with _warm_up_lock:
                    if _finished:
                        continue
                on_every_minute()


#: under xdist, when no test has ended for this long, the controller names the tests still running (seconds)
STILL_RUNNING_EVERY_S = 120.0
_running: dict[str, float] = {}  # in the controller: nodeid -> when its worker started it (monotonic s)
_last_end = [time.monotonic()]  # in the controller: when a test last ended


def pytest_runtest_logstart(nodeid: str, location: Any) -> None:
    """In the controller (xdist relays each worker's start of a test): the test runs from now."""
    with _say_lock:
        _running[nodeid] = time.monotonic()


def pytest_runtest_logfinish(nodeid: str, location: Any) -> None:
    with _say_lock:
        _running.pop(nodeid, None)
        _last_end[0] = time.monotonic()


def _say_what_still_runs(config: pytest.Config) -> None:
    """In the controller: a line naming the running tests and their minutes whenever no test has ended for
    STILL_RUNNING_EVERY_S, so that a long test on a busy machine never looks like a hung run (`-q` prints a
    test's dot only when it ends). Stops with the session."""
    while True:
        time.sleep(STILL_RUNNING_EVERY_S / 4)
        with _warm_up_lock:
            if _finished:
                return
        now = time.monotonic()
        with _say_lock:
            quiet_s = now - _last_end[0]
            running = sorted(_running.items(), key=lambda kv: kv[1])
        if quiet_s < STILL_RUNNING_EVERY_S or not running:
            continue
        names = ", ".join(f"{nodeid} ({(now - t) / 60:.0f} min)" for nodeid, t in running)
        say(config, f"rimless: no test ended for {quiet_s / 60:.0f} min; still running: {names}")
        with _say_lock:
            _last_end[0] = now  # the next line after as long again


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """In an xdist worker: a test that may run a compiled kernel waits until the controller's compile is done
    (pytest_sessionstart), so that the workers never compile the same kernels at once."""
    global _kernels_ready
    if _kernels_ready or kernel_free(item):
        return
    ready = os.environ.get(KERNELS_READY_ENV)
    if not ready or not hasattr(item.config, "workerinput"):
        _kernels_ready = True
        return
    deadline = time.monotonic() + 1800
    while not os.path.exists(ready) and time.monotonic() < deadline:
        time.sleep(0.05)
    _kernels_ready = True  # after 30 min the test compiles what it needs itself


def pytest_sessionfinish(session: pytest.Session) -> None:
    """The controller ends its compiling processes if they still run (see pytest_sessionstart) and removes the
    folder of the first-use probe's output."""
    global _finished
    if hasattr(session.config, "workerinput"):
        return
    with _warm_up_lock:
        _finished = True
        for proc in list(_WARM_UP):
            if proc.poll() is None:
                proc.kill()
            proc.wait()
        _WARM_UP.clear()
    record = os.environ.pop(first_use.RECORD_ENV, None)
    os.environ.pop(KERNELS_READY_ENV, None)
    if record:
        shutil.rmtree(Path(record).parent, ignore_errors=True)


# Under `-n N` xdist hands the tests out in collection order, one scope (a test, or an xdist_group such as the
# demo's readers) at a time to whichever worker is free (`--dist loadgroup --no-loadscope-reorder`, pyproject.toml).
# First the `KERNEL_FREE` tests, which run while the controller compiles the kernels (pytest_sessionstart). Then,
# since a long test picked up near the end keeps one worker busy while the other idles, the known-long tests,
# longest first (seconds measured on the 2-core machine; only their order matters, they are not limits), then the
# other tests marked slow, then the rest in collection order.
LONG_TESTS_S: dict[str, float] = {  # nodeid prefix: seconds (3 workers on 2 cores, empty cache, 2026-11-26)
    "tests/test_readme.py::test_page_commands_run_as_written[docs/simulator.md]": 82.0,  # full
    "tests/test_readme.py::test_page_commands_run_as_written[docs/trials.md]": 51.0,  # full
    "tests/test_readme.py::test_page_commands_run_as_written[README.md]": 46.0,  # runs the demo
    "tests/sim/fast/test_fast.py::test_compiled_map_matches_the_reference_map[active-feet": 30.0,  # full: compiles
    "tests/analysis/inference/test_leg_fit.py::test_intervals_cover_the_truth": 23.0,
    "tests/test_readme.py::test_page_commands_run_as_written[docs/robot.md]": 17.0,  # full
    "tests/sim/in_the_loop/test_loop.py::test_sim_sweep_firmware_orders_the_cost_of_delay_and_caches_points": 16.0,
    "tests/sim/studies/test_paper.py::test_rimless_paper_writes_every_figure_csv_and_headline_row": 15.0,
    "tests/sim/studies/test_stress.py::test_grazing_touchdown_inside_one_step_is_not_missed": 15.0,  # full: compiles
    "tests/sim/fast/test_reduced.py::test_reduced_variational_equations_match_the_full_kkt_derivative": 14.0,
    "tests/analysis/test_readme.py::test_readme_trials_chain_runs_verbatim": 13.5,
    "tests/sim/step/test_poincare.py::test_fixed_point_residual_and_two_jacobian_estimates_agree": 12.5,
    "tests/analysis/inference/test_calibrate_friction.py::test_recovers_friction_and_damping_from_trials": 12.0,
    "tests/analysis/cli/test_tables_at_80_columns.py::test_the_calibration_residuals_name_every_trial": 11.5,
}


def _expected_s(item: pytest.Item) -> float:
    for prefix, seconds in LONG_TESTS_S.items():
        if item.nodeid.startswith(prefix):
            return seconds
    return 1.0 if item.get_closest_marker("slow") else 0.0


#: Set to 1 (as .ci/run does) to run the tests marked `full` too; without it, and without `-m`, they are deselected.
FULL_TESTS_ENV = "RIMLESS_FULL_TESTS"


def full_run(config: pytest.Config) -> bool:
    """Whether this run keeps the tests marked `full`: RIMLESS_FULL_TESTS=1, or a `-m` expression (which then
    decides alone, e.g. `-m full` runs only them)."""
    return os.environ.get(FULL_TESTS_ENV, "") not in ("", "0") or bool(config.getoption("markexpr", ""))


def pytest_report_header(config: pytest.Config) -> str:
    if full_run(config):
        return "rimless: every test (tests marked `full` included)"
    return (
        f"rimless: the default run; the tests marked `full` (more cases of checks this run makes) are "
        f"deselected: {FULL_TESTS_ENV}=1 runs them too, as CI does"
    )


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked `full` out of the default run (see full_run); the kernel-free tests first, then longest first
    (see LONG_TESTS_S); and `xdist_group` working again under pytest 9 with `--dist loadgroup`.

    pytest-xdist 3.8 marks a grouped test by appending `@group` to `item._nodeid`, which pytest 9 no longer
    reads (a node's id lives in `item._id`): groups were silently split across workers. The demo's readers
    (xdist_group "demo") must stay on one worker so the other never waits on the demo's lock."""
    if not full_run(config):
        breadth = [item for item in items if item.get_closest_marker("full")]
        if breadth:
            config.hook.pytest_deselected(items=breadth)
            items[:] = [item for item in items if not item.get_closest_marker("full")]
    # stable: collection order within equal expectations
    items.sort(key=lambda item: (not kernel_free(item), -_expected_s(item)))
    if not hasattr(config, "workerinput") or not config.getvalue("loadgroup"):  # a worker's "dist" reads "no"
        return
    from _pytest.nodeid import NodeId

    for item in items:
        names = sorted(
            {str(m.args[0] if m.args else m.kwargs.get("name", "default")) for m in item.iter_markers("xdist_group")}
        )
        if names and "@" not in item.nodeid:
            item._id = NodeId.parse(f"{item.nodeid}@{'_'.join(names)}")  # type: ignore[attr-defined]
