"""Parameter sweeps of the gait branches: a grid of wheels, each point's branches traced, on Dask.

A grid point is one (model, parameter set). Its work (rimless.sim.continuation.branches.trace_gait_branches: every gait at
the start slope, each followed down in slope) is independent of every other point, so points run as tasks:
- `scheduler="sync"`: one process, in order (no Dask needed);
- `scheduler="local"`: a dask.distributed LocalCluster with one single-threaded worker process per core
  (or `workers`), created and closed here;
- `scheduler="tcp://HOST:8786"`: a cluster a lab already runs.
Every worker loads the compiled kernels once (numba's on-disk cache, rimless.sim.fast.warm_up) before the
first task, not per task. Results are cached on disk, one JSON file per grid point named by the hash of
everything that determines it (parameters, model, options, CACHE_VERSION), so a re-run or an extended grid
recomputes nothing already done.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rimless.errors import ParameterError

CACHE_VERSION = 3
# sweepable parameters: option name -> (WheelParams field, unit)
GRID_PARAMETERS: dict[str, tuple[str, str]] = {
    "k": ("stiffness_n_per_m", "N/m"),
    "c": ("damping_ns_per_m", "N s/m"),
    "hub_mass_kg": ("hub_mass_kg", "kg"),
    "leg_mass_kg": ("leg_mass_kg", "kg"),
    "inertia_kg_m2": ("inertia_kg_m2", "kg m^2"),
}


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "rimless" / "sweep"


@dataclass(frozen=True)
class SweepOptions:
    """What every grid point is computed with (part of the cache key)."""

    backend: str = "auto"
    rtol: float = 1e-10
    start_slope_rad: float = 0.05
    n_guesses: int = 14
    to_end: bool = False


def grid_points(base: Any, models: Iterable[str], grid: dict[str, list[float]], mass_models: Iterable[str]) -> list[dict[str, Any]]:
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


def point_key(point: dict[str, Any], options: SweepOptions) -> str:
    """The cache key of a grid point: sha256 of its parameters, model, options and CACHE_VERSION."""
    payload = json.dumps({"v": CACHE_VERSION, "point": point, "options": options.__dict__}, sort_keys=True)
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
        branches = trace_gait_branches(params, point["model"], backend=options.backend, rtol=options.rtol,
                                       start_slope_rad=options.start_slope_rad, n_guesses=options.n_guesses,
                                       to_end=options.to_end)
    except StepFailure as err:  # no gait could even be searched for: one row saying so
        branches = []
        error = str(err)
    else:
        error = ""
    rows = [b.row() for b in branches]
    if not rows:
        p = params.replace(slope_rad=options.start_slope_rad)
        rows = [{"model": point["model"].upper(), "k": p.k, "c": p.c, "mass_model": p.mass_model,
                 "hub_mass_kg": p.hub_mass_kg, "leg_mass_kg": p.leg_mass_kg, "start_slope_rad": p.slope_rad,
                 "branch": "", "branch_label": "", "reason": "no-gait",
                 "detail": error or "no period-1 gait found at the start slope",
                 "critical_slope_rad": math.nan, "critical_slope_deg": math.nan, "cot": math.nan,
                 "stable_at_start": False, "contact_valid_at_start": False}]
    pts = [r for b in branches for r in b.point_rows()]
    return {"rows": rows, "points": pts, "seconds": time.perf_counter() - t0}


def _worker_setup() -> float:
    """Load the compiled kernels in this worker (from numba's on-disk cache); seconds taken."""
    try:
        from rimless.sim import fast
    except ImportError:
        return 0.0
    return float(fast.warm_up())


def _read_cached(cache_dir: str | None, point: dict[str, Any], options: SweepOptions) -> dict[str, Any] | None:
    """The cached result of `point` (marked ``cached``), or None when there is none or it cannot be read."""
    if not cache_dir:
        return None
    path = Path(cache_dir) / f"{point_key(point, options)}.json"
    if not path.exists():
        return None
    try:
        out = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    out["cached"] = True
    return out


def _cached_compute(point: dict[str, Any], options: Any, cache_dir: str | None,
                    compute: Callable[[dict[str, Any], Any], dict[str, Any]] | None = None) -> dict[str, Any]:
    hit = _read_cached(cache_dir, point, options)
    if hit is not None:
        return hit
    out = (compute or compute_point)(point, options)
    if cache_dir:
        _write_json_atomic(Path(cache_dir) / f"{point_key(point, options)}.json", out)
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


def run_sweep(
    points: list[dict[str, Any]],
    options: SweepOptions = SweepOptions(),
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
        results[i] = _read_cached(cache, pt, options)
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
        from dask.distributed import Client, LocalCluster, as_completed

        own_cluster = None
        own_client = client is None
        if client is None:
            if scheduler == "local":
                n = workers or os.cpu_count() or 1
                own_cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                           silence_logs=40)
                client = Client(own_cluster)
            elif scheduler.startswith("tcp://") or scheduler.startswith("tls://"):
                try:
                    client = Client(scheduler, timeout=15)
                except (OSError, TimeoutError) as err:
                    raise ConnectionError(f"cannot reach the Dask scheduler {scheduler}: {err}") from None
            else:
                raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
        try:
            t_setup = time.perf_counter()
            client.run(setup)  # once per worker, before any task
            setup_s = time.perf_counter() - t_setup
            n_workers = len(client.scheduler_info().get("workers", {})) or 1
            futures = {client.submit(_cached_compute, points[i], options, cache, compute, pure=False): i for i in todo}
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
                done += 1
                if progress:
                    progress(done, len(points))
        finally:
            if own_client:
                client.close()
            if own_cluster is not None:
                own_cluster.close()
    rows = [r for res in results if res is not None for r in res["rows"]]
    pts = [r for res in results if res is not None for r in res["points"]]
    computed = sum(1 for res in results if res is not None and not res.get("cached"))
    return SweepResult(rows, pts, time.perf_counter() - t0, computed, len(points) - computed,
                       scheduler, n_workers, setup_s)


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


def branch_sweep(params: Any, *, models: list[str], grid: dict[str, list[float]], mass_models: list[str],
                 options: SweepOptions, out: Path, scheduler: str = "local", workers: int | None = None,
                 cache_dir: Path | None = None, progress: Callable[[int, int], None] | None = None,
                 power: Any = None) -> dict[str, Any]:
    """`rimless sim sweep`: every grid point's branches (run_sweep), written as `out`.parquet/.csv and
    `out`-points.parquet/.csv; returns the command's JSON object. An empty grid sweeps the wheel's own k."""
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
    meta = {"grid": grid, "models": models, "mass_models": mass_models, "options": options.__dict__,
            "base_params": params.to_dict(), "scheduler": scheduler}
    if not res.rows:
        raise RunFailure("the sweep produced no rows")
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.studies.system_cot import sweep_system_cot

    power = power or ClutchPower()
    res.rows = sweep_system_cot(res.rows, res.points, power, backend=options.backend, rtol=options.rtol)
    meta["electrical_power"] = power.as_dict()
    paths = write_table(res.rows, out, meta)
    if res.points:
        paths += write_table(res.points, out.with_name(out.name + "-points"), meta)
    return {"rows": res.rows, "files": [str(p) for p in paths], "seconds": res.seconds, "computed": res.computed,
            "cached": res.cached, "scheduler": scheduler, "workers": res.workers, "grid": grid}
