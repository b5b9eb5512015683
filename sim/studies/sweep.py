"""Parameter sweeps of the gait branches: a grid of wheels, each point's branches traced, on Dask.

A grid point is one (model, parameter set). Its work (rimless.sim.continuation.branches.trace_gait_branches: every gait at
the start slope, each followed down in slope) is independent of every other point, so points run as tasks:
- `scheduler="sync"`: one process, in order (no Dask needed);
- `scheduler="local"`: a dask.distributed LocalCluster with one single-threaded worker process per core
  (or `workers`), created and closed here; its processes write their own messages to
  $RIMLESS_CACHE_DIR/dask-workers.log (else ~/.cache/rimless/), not to the terminal, and leave Ctrl-C to the
  command;
- `scheduler="tcp://HOST:8786"`: a cluster a lab already runs.
Every worker loads the compiled kernels once (numba's on-disk cache, rimless.sim.fast.warm_up) before the
first task, not per task. Results are cached on disk (under $RIMLESS_CACHE_DIR/sweep, else
~/.cache/rimless/sweep), one JSON file per grid point named by the hash of everything that determines it: its
parameters, model and options, and the source of the code that computes it (the simulator's model, generated
kernels, integrators, step and continuation, the computing module and, for the firmware in the loop, the
firmware's control path; `code_fingerprint`), so a re-run or an extended grid recomputes nothing already done
and no edit to that code can return a stale row.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rimless.errors import ParameterError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

CACHE_VERSION = 4  # the layout of a cached file; the code is keyed by code_fingerprint
# the packages every grid point's result depends on (source files hashed into the cache key)
CODE_PACKAGES = (
    "rimless.sim.model",
    "rimless.sim.integrate",
    "rimless.sim.fast",
    "rimless.sim.step",
    "rimless.sim.continuation",
)
# what a computation in the firmware-in-the-loop package depends on besides
LOOP_PACKAGES = ("rimless.sim.in_the_loop", "rimless.firmware")
# sweepable parameters: option name -> (WheelParams field, unit)
GRID_PARAMETERS: dict[str, tuple[str, str]] = {
    "k": ("stiffness_n_per_m", "N/m"),
    "c": ("damping_ns_per_m", "N s/m"),
    "hub_mass_kg": ("hub_mass_kg", "kg"),
    "leg_mass_kg": ("leg_mass_kg", "kg"),
    "inertia_kg_m2": ("inertia_kg_m2", "kg m^2"),
}


def cache_root() -> Path:
    """Where the project keeps its caches: $RIMLESS_CACHE_DIR, else $XDG_CACHE_HOME/rimless, else ~/.cache/rimless."""
    own = os.environ.get("RIMLESS_CACHE_DIR")
    if own:
        return Path(own).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "rimless"


def default_cache_dir() -> Path:
    """The sweep result cache: cache_root()/sweep."""
    return cache_root() / "sweep"


def _package_files(name: str) -> list[Path]:
    """The source files of the package or module `name` (found without importing it)."""
    import importlib.util

    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        return []
    origin = Path(spec.origin)
    if spec.submodule_search_locations:
        return sorted(p for loc in spec.submodule_search_locations for p in Path(loc).rglob("*.py"))
    return [origin]


@functools.cache
def code_fingerprint(module: str = "") -> str:
    """sha256 of the source of CODE_PACKAGES and of `module` (the computing function's module; its package's
    LOOP_PACKAGES too when it belongs to the firmware in the loop), with the versions of numpy, scipy and numba:
    the part of a grid point's cache key that changes with any edit to the code that computes the point."""
    import importlib.metadata as md

    names = list(CODE_PACKAGES) + ([module] if module else [])
    if module.startswith("rimless.sim.in_the_loop"):
        names += LOOP_PACKAGES
    h = hashlib.sha256()
    for name in names:
        for path in _package_files(name):
            h.update(f"{name}:{path.name}\0".encode())
            h.update(path.read_bytes())
    for dist in ("numpy", "scipy", "numba"):
        try:
            h.update(f"{dist}={md.version(dist)}".encode())
        except md.PackageNotFoundError:
            h.update(f"{dist}=none".encode())
    return h.hexdigest()


@dataclass(frozen=True)
class SweepOptions:
    """What every grid point is computed with (part of the cache key)."""

    backend: str = "auto"
    rtol: float = 1e-10
    start_slope_rad: float = 0.05
    n_guesses: int = 14
    to_end: bool = False
    # further slopes (rad) at which gaits are searched (rimless.sim.continuation.branches.search_slopes)
    search_slopes_rad: tuple[float, ...] = ()
    search_guesses: int = 20  # theta'+ guesses at each search slope (branches.SEARCH_THETA_DOT_RAD_S)
    # each critical slope also re-located at rtol x 10 (critical_slope_rtol_shift_rad, critical_slope_tol_rad)
    locate_tolerance: bool = False


def grid_points(
    base: Any, models: Iterable[str], grid: dict[str, list[float]], mass_models: Iterable[str]
) -> list[dict[str, Any]]:
    """Every combination as a plain dict {model, params (WheelParams.to_dict())} (the task's input)."""
    import itertools

    names = list(grid)
    out = []
    for mass_model in mass_models:
        for model in models:
            for combo in itertools.product(*(grid[n] for n in names)):
                changes = {GRID_PARAMETERS[n][0]: float(v) for n, v in zip(names, combo)}
                params = base.replace(mass_model=mass_model, **changes)
                out.append({"model": model, "params": params.to_dict()})
    return out


def point_key(point: dict[str, Any], options: Any, compute: Callable[..., Any] | None = None) -> str:
    """The cache key of a grid point: sha256 of its parameters, model, options, CACHE_VERSION and the
    fingerprint of the code that computes it (`compute`, default compute_point)."""
    fn = compute or compute_point
    payload = json.dumps(
        {
            "v": CACHE_VERSION,
            "point": point,
            "options": options.__dict__,
            "compute": f"{fn.__module__}.{fn.__qualname__}",
            "code": code_fingerprint(fn.__module__),
        },
        sort_keys=True,
    )
    return hashlib.sha256(payload.encode()).hexdigest()[:32]


def compute_point(point: dict[str, Any], options: SweepOptions) -> dict[str, Any]:
    """Trace every branch of one grid point; returns {"rows": [...], "points": [...], "seconds": s}.
    Runs in a worker: imports inside, plain data in and out."""
    from rimless.sim.continuation.branches import trace_gait_branches
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams

    t0 = time.perf_counter()
    params = WheelParams(**point["params"])
    try:
        branches = trace_gait_branches(
            params,
            point["model"],
            backend=options.backend,
            rtol=options.rtol,
            start_slope_rad=options.start_slope_rad,
            n_guesses=options.n_guesses,
            to_end=options.to_end,
            search_slopes_rad=tuple(getattr(options, "search_slopes_rad", ())),
            search_guesses=int(getattr(options, "search_guesses", 20)),
        )
    except StepFailure as err:  # no gait could even be searched for: one row saying so
        branches = []
        error = str(err)
    else:
        error = ""
    rows = [b.row() for b in branches]
    if getattr(options, "locate_tolerance", False):
        for b, r in zip(branches, rows):
            r.update(b.location_tolerance(options.backend, options.rtol))
    if not rows:
        p = params.replace(slope_rad=options.start_slope_rad)
        rows = [
            {
                "model": point["model"].upper(),
                "k": p.k,
                "c": p.c,
                "mass_model": p.mass_model,
                "hub_mass_kg": p.hub_mass_kg,
                "leg_mass_kg": p.leg_mass_kg,
                "start_slope_rad": p.slope_rad,
                "branch": "",
                "branch_label": "",
                "reason": "no-gait",
                "detail": error or "no period-1 gait found at the start slope",
                "critical_slope_rad": math.nan,
                "critical_slope_deg": math.nan,
                "cot": math.nan,
                "stable_at_start": False,
                "contact_valid_at_start": False,
            }
        ]
    pts = [r for b in branches for r in b.point_rows()]
    return {"rows": rows, "points": pts, "seconds": time.perf_counter() - t0}


def _worker_setup() -> float:
    """Load the compiled kernels in this worker (from numba's on-disk cache); seconds taken."""
    try:
        from rimless.sim import fast
    except ImportError:
        return 0.0
    return float(fast.warm_up())


def _read_cached(
    cache_dir: str | None, point: dict[str, Any], options: Any, compute: Callable[..., Any] | None = None
) -> dict[str, Any] | None:
    """The cached result of `point` (marked ``cached``), or None when there is none or it cannot be read."""
    if not cache_dir:
        return None
    path = Path(cache_dir) / f"{point_key(point, options, compute)}.json"
    if not path.exists():
        return None
    try:
        out = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    out["cached"] = True
    return out


def _cached_compute(
    point: dict[str, Any],
    options: Any,
    cache_dir: str | None,
    compute: Callable[[dict[str, Any], Any], dict[str, Any]] | None = None,
) -> dict[str, Any]:
    hit = _read_cached(cache_dir, point, options, compute)
    if hit is not None:
        return hit
    out = (compute or compute_point)(point, options)
    if cache_dir:
        _write_json_atomic(Path(cache_dir) / f"{point_key(point, options, compute)}.json", out)
    out["cached"] = False
    return out


def _write_json_atomic(path: Path, obj: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(obj, allow_nan=True))
    tmp.replace(path)


@dataclass
class SweepResult:
    rows: list[dict[str, Any]]
    points: list[dict[str, Any]]
    seconds: float
    computed: int
    cached: int
    scheduler: str
    workers: int
    setup_s: float


def _ignoring_ctrl_c(creator_pid: int) -> Any:
    """Unpickling the plugin of _ctrl_c_is_the_commands in a process other than the one that made it (a local
    worker process, which multiprocessing's spawn starts by unpickling the worker's options, before the
    worker's asyncio loop or any of its code runs): ignore SIGINT from here on (Python and asyncio then install
    no handler of their own)."""
    import signal
    import threading

    if os.getpid() != creator_pid and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return _ctrl_c_is_the_commands(creator_pid)


def _ctrl_c_is_the_commands(creator_pid: int | None = None) -> Any:
    """A Dask worker plugin that does nothing but, unpickled in a worker process, make it ignore SIGINT: a
    Ctrl-C to the process group is the command's, which then kills its workers (dask_client)."""
    from distributed import WorkerPlugin

    class CtrlCIsTheCommands(WorkerPlugin):
        def __init__(self, pid: int) -> None:
            self.creator_pid = pid

        def __reduce__(self) -> tuple[Any, tuple[int]]:
            return _ignoring_ctrl_c, (self.creator_pid,)

    return CtrlCIsTheCommands(os.getpid() if creator_pid is None else creator_pid)


def workers_log() -> Path:
    """Where the processes of the last local Dask cluster wrote their own messages (stderr): not the terminal."""
    return cache_root() / "dask-workers.log"


@contextlib.contextmanager
def _children_write_to(path: Path) -> Iterator[None]:
    """Point this process's stderr (file descriptor 2) at `path` while the local cluster starts its worker
    processes (and multiprocessing's resource tracker), which inherit it: whatever they print, also a Ctrl-C
    landing while one of them is still starting Python, goes to that file, never after `interrupted`. Then
    stderr is the terminal again. Without a writable cache folder, nothing changes."""
    import sys

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        log = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)  # the last cluster's only
    except OSError:
        log = -1
    if log < 0:
        yield
        return
    with contextlib.suppress(OSError, ValueError):
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing reaches a terminal anyway
        os.close(log)
        yield
        return
    os.dup2(log, 2)
    try:
        yield
    finally:
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
        os.close(log)


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int | None = None) -> Iterator[Any]:
    """A dask.distributed Client on a LocalCluster of `workers` single-threaded processes (scheduler "local")
    or on a running scheduler ("tcp://HOST:PORT"), closed on the way out.

    Ctrl-C is the main process's alone: the local workers of the `rimless` command ignore SIGINT (so a Ctrl-C
    sent to the process group does not print a traceback in every worker), and on an interrupt the workers
    are killed and the cluster closed at once, its shutdown logs silenced, before the KeyboardInterrupt goes on.
    An unreachable scheduler raises ConnectionError."""
    import logging
    import signal
    import threading

    from dask.distributed import Client, LocalCluster

    cluster = client = None
    main = threading.current_thread() is threading.main_thread()
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if main else None
    try:
        try:
            if scheduler == "local":
                _quiet_resource_tracker()
                # created with SIGINT blocked: a Ctrl-C meanwhile waits for the unblock below. The worker
                # processes write to workers_log(), not to the terminal, and ignore SIGINT once started
                # (_ctrl_c_is_the_commands), so a Ctrl-C to the process group is the command's alone, which
                # kills its workers
                from rimless.progress import stage

                stage("sweep: starting a local Dask cluster")
                try:
                    with _children_write_to(workers_log()):
                        cluster = LocalCluster(
                            n_workers=workers or os.cpu_count() or 1,
                            threads_per_worker=1,
                            processes=True,
                            dashboard_address=":0",
                            silence_logs=logging.ERROR,
                            plugins=(_ctrl_c_is_the_commands(),),
                        )
                except Exception as err:  # noqa: BLE001 - Dask wraps what went wrong (a worker died, no port, ...)
                    from rimless.errors import RunFailure

                    cause = err.__cause__ or err
                    raise RunFailure(
                        f"cannot start a local Dask cluster: {type(cause).__name__}: "
                        f"{str(cause).splitlines()[0] if str(cause) else err}"
                    ) from None
                client = Client(cluster)
                _no_gc_callback()
            else:
                try:
                    client = Client(scheduler, timeout=15)
                except (OSError, TimeoutError) as err:
                    raise ConnectionError(f"cannot reach the Dask scheduler {scheduler}: {err}") from None
        finally:
            if old_mask is not None:
                signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        yield client
        if client is not None:  # a Ctrl-C while closing goes to the except below, as one during the work
            client.close()
        if cluster is not None:
            cluster.close()
    except BaseException as err:
        from rimless.errors import interrupted_by_user

        _close_at_once(client, cluster, interrupted=interrupted_by_user(err))
        raise


def _no_gc_callback() -> None:
    """Remove the garbage-collection callback that the in-process Dask scheduler installs (it only logs long
    collections). Python swallows an exception raised inside a gc callback ("Exception ignored in ..."), so a
    Ctrl-C whose KeyboardInterrupt was raised there was lost: `rimless paper` then ran on to the end and exited
    0 (4 of 4 runs with the Ctrl-C 2 s after its workers started)."""
    from distributed.gc import disable_gc_diagnosis

    disable_gc_diagnosis(force=True)


def _quiet_resource_tracker() -> None:
    """multiprocessing's resource tracker (a process of its own, started with the first worker, writing to our
    stderr) warns at its exit about semaphores of workers that were killed (after a Ctrl-C) and unlinks them:
    it is started with that warning ignored (it takes the interpreter's -W options from sys.warnoptions), so
    nothing is printed after `interrupted`; the semaphores are still cleaned up."""
    import sys

    quiet = "ignore:resource_tracker:UserWarning"
    if quiet not in sys.warnoptions:
        sys.warnoptions.append(quiet)


def _close_at_once(client: Any, cluster: Any, *, interrupted: bool = False) -> None:
    """After an interrupt or an error: kill the local workers, close client and cluster without waiting for
    them, and keep Dask's shutdown messages (lost workers, cancelled tasks) off the terminal. After an
    interrupt the process is about to print `interrupted` and exit: nothing else of this process may print
    (logging, the threads' and finalizers' tracebacks are silenced for good)."""
    import logging
    import sys
    import threading

    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    if interrupted:
        logging.disable(logging.CRITICAL)
        threading.excepthook = lambda args: None  # a Dask thread dying in the shutdown says nothing
        sys.unraisablehook = lambda unraisable: None
    if cluster is not None:
        try:
            from multiprocessing import resource_tracker

            import psutil

            keep = {getattr(resource_tracker._resource_tracker, "_pid", None)}
            for child in psutil.Process().children(recursive=True):
                try:  # one child gone or unreadable does not spare the others
                    if child.pid not in keep and "resource_tracker" not in " ".join(child.cmdline()):
                        child.kill()
                except Exception:  # noqa: BLE001 - gone already
                    continue
        except Exception:  # noqa: BLE001 - best effort; close() below ends them anyway
            pass
    for obj in (client, cluster):
        if obj is None:
            continue
        with contextlib.suppress(BaseException):
            obj.close(timeout=0.5)


def worker_failure(err: BaseException, scheduler: str) -> None:
    """Raise a one-line UserError when `err`, raised by a task or set-up on a Dask worker, says the worker
    cannot import rimless (the package is not installed where the worker runs)."""
    from rimless.errors import RimlessError, UserError

    if isinstance(err, RimlessError):  # already classified
        return
    text = f"{type(err).__name__}: {err}"
    if isinstance(err, ImportError) or "No module named 'rimless" in text:
        missing = getattr(err, "name", None) or "rimless"
        raise UserError(
            f"--scheduler {scheduler}: a Dask worker cannot import {missing} ({text.splitlines()[0]}); "
            'install rimless (pip install -e ".[pc]") in the environment every worker runs in'
        ) from None


def run_sweep(
    points: list[dict[str, Any]],
    options: DataclassInstance = SweepOptions(),
    *,
    scheduler: str = "local",
    workers: int | None = None,
    cache_dir: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    client: Any = None,
    compute: Callable[[dict[str, Any], Any], dict[str, Any]] | None = None,
    setup: Callable[[], float] | None = None,
) -> SweepResult:
    """Compute every grid point (see module docstring); rows come back in the order of `points`.

    `compute(point, options)` replaces `compute_point` for another kind of grid (a module-level function
    returning {"rows", "points", "seconds"}; `options` a dataclass, part of the cache key with the point);
    `setup()` replaces the per-worker kernel warm-up."""
    setup = setup or _worker_setup
    t0 = time.perf_counter()
    cache = str(cache_dir) if cache_dir else None
    results: list[dict[str, Any] | None] = [None] * len(points)
    todo = []
    for i, pt in enumerate(points):  # cache hits never reach a worker
        results[i] = _read_cached(cache, pt, options, compute)
        if results[i] is None:
            todo.append(i)
    done = len(points) - len(todo)
    if progress:
        progress(done, len(points))
    setup_s = 0.0
    n_workers = 1
    if todo and scheduler == "sync":
        setup_s = setup()
        for i in todo:
            results[i] = _cached_compute(points[i], options, cache, compute)
            done += 1
            if progress:
                progress(done, len(points))
    elif todo:
        from dask.distributed import as_completed

        if client is None and not (scheduler == "local" or scheduler.startswith(("tcp://", "tls://"))):
            raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
        with contextlib.ExitStack() as stack:
            if client is None:
                client = stack.enter_context(dask_client(scheduler, workers))
            try:
                t_setup = time.perf_counter()
                client.run(setup)  # once per worker, before any task
                setup_s = time.perf_counter() - t_setup
                n_workers = len(client.scheduler_info().get("workers", {})) or 1
                futures = {
                    client.submit(_cached_compute, points[i], options, cache, compute, pure=False): i for i in todo
                }
                from rimless.progress import stage

                stage(f"sweep: {len(todo)} grid points submitted to {n_workers} worker(s)")
                for fut in as_completed(futures):
                    results[futures[fut]] = fut.result()
                    done += 1
                    if progress:
                        progress(done, len(points))
            except Exception as err:
                worker_failure(err, scheduler)
                raise
    rows = [r for res in results if res is not None for r in res["rows"]]
    pts = [r for res in results if res is not None for r in res["points"]]
    computed = sum(1 for res in results if res is not None and not res.get("cached"))
    return SweepResult(
        rows, pts, time.perf_counter() - t0, computed, len(points) - computed, scheduler, n_workers, setup_s
    )


def write_table(rows: list[dict[str, Any]], path_stem: Path, metadata: dict[str, Any]) -> list[Path]:
    """Write rows as Parquet (metadata under b"rimless") and CSV, each to a temporary name then renamed."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    frame = pd.DataFrame(rows)
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    pq_path = path_stem.with_suffix(".parquet")
    csv_path = path_stem.with_suffix(".csv")
    table = pa.Table.from_pandas(frame, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[b"rimless"] = json.dumps(metadata, default=str).encode()
    table = table.replace_schema_metadata(meta)
    tmp = pq_path.with_name(f".{pq_path.name}.tmp")
    pq.write_table(table, tmp)
    tmp.replace(pq_path)
    tmp = csv_path.with_name(f".{csv_path.name}.tmp")
    frame.to_csv(tmp, index=False)
    tmp.replace(csv_path)
    return [pq_path, csv_path]


def parse_grid(params: Any, texts: dict[str, str | None]) -> dict[str, list[float]]:
    """The sweep's grid from the options' text (name of GRID_PARAMETERS -> `START:STOP:STEP` or `a,b`, None
    when not given), each value checked against `params` (WheelParams.replace); errors name the option."""
    from rimless.values import parse_range

    grid: dict[str, list[float]] = {}
    for name, text in texts.items():
        if text is None:
            continue
        option = "--" + name.replace("_", "-")
        grid[name] = parse_range(text, option)
        field_name = GRID_PARAMETERS[name][0]
        for v in grid[name]:
            try:
                params.replace(**{field_name: v})
            except ParameterError as err:
                raise ParameterError(f"{option} {v:g}: {err}") from None
    return grid


def _no_gait_anywhere(rows: list[dict[str, Any]], options: SweepOptions) -> str:
    """The one-line reason of a sweep in which no grid point has a gait (every row is a `no-gait` row)."""
    details = list(dict.fromkeys(str(r.get("detail") or "no period-1 gait found") for r in rows))
    more = f" (and {len(details) - 2} other reasons)" if len(details) > 2 else ""
    n = len(rows)
    return (
        f"no period-1 gait at any of the {n} grid point{'s' if n != 1 else ''} at the start slope "
        f"{math.degrees(options.start_slope_rad):.4f} deg ({options.start_slope_rad:g} rad, "
        f"{options.n_guesses} guesses): {'; '.join(details[:2])}{more}"
    )


def branch_sweep(
    params: Any,
    *,
    models: list[str],
    grid: dict[str, list[float]],
    mass_models: list[str],
    options: SweepOptions,
    out: Path,
    scheduler: str = "local",
    workers: int | None = None,
    cache_dir: Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    power: Any = None,
) -> dict[str, Any]:
    """`rimless sim sweep`: every grid point's branches (run_sweep), written as `out`.parquet/.csv and
    `out`-points.parquet/.csv; returns the command's JSON object. An empty grid sweeps the wheel's own k.
    A grid on which no point has a gait is a RunFailure (no file written); points without one, among points
    with gaits, are `no-gait` rows."""
    from rimless.errors import RunFailure
    from rimless.output import check_output_folder, writable_dir

    grid = grid or {"k": [params.k]}
    points = grid_points(params, models, grid, mass_models)
    check_output_folder(out.parent if str(out.parent) else ".", option="--out")  # before minutes of work
    if cache_dir is not None:
        writable_dir(cache_dir, option="--cache-dir")
    try:
        res = run_sweep(points, options, scheduler=scheduler, workers=workers, cache_dir=cache_dir, progress=progress)
    except ConnectionError as err:
        raise ParameterError(f"--scheduler: {err}") from None
    meta = {
        "grid": grid,
        "models": models,
        "mass_models": mass_models,
        "options": options.__dict__,
        "base_params": params.to_dict(),
        "scheduler": scheduler,
    }
    if not res.rows:
        raise RunFailure("the sweep produced no rows")
    if all(r.get("reason") == "no-gait" for r in res.rows):  # nothing to tabulate: no table is written
        raise RunFailure(_no_gait_anywhere(res.rows, options))
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.studies.system_cot import sweep_system_cot

    power = power or ClutchPower()
    res.rows = sweep_system_cot(res.rows, res.points, power, backend=options.backend, rtol=options.rtol)
    meta["electrical_power"] = power.as_dict()
    paths = write_table(res.rows, out, meta)
    if res.points:
        paths += write_table(res.points, out.with_name(out.name + "-points"), meta)
    return {
        "rows": res.rows,
        "files": [str(p) for p in paths],
        "seconds": res.seconds,
        "computed": res.computed,
        "cached": res.cached,
        "scheduler": scheduler,
        "workers": res.workers,
        "grid": grid,
    }
