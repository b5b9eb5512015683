"""Benchmark of the sweep and of the branch-end location, fast path and reference side by side in one run.

- Sweep: the same grid (no cache) on 1 worker, 2 workers (LocalCluster) and in-process; CPU times (of this
  thread in-process; of each worker process, time.process_time read on the workers before and after the sweep, so their loading of the compiled kernels
  and Dask's own work on them are included) and wall
  times; the speed-up from 1 to 2 workers from CPU time: the 1-worker run's CPU over the busiest worker's CPU in
  the 2-worker run (what two free cores would give: it measures the split of the work and the overhead of a
  second worker, not the load), with the wall-time speed-up beside (which other processes on the machine
  shrink); and the largest difference in the numbers between the runs.
- Branch end: the ER and VE (medium) critical slope at Table 1 by pseudo-arclength continuation (special
  point located to 1e-9 rad) against Algorithm 1 refined by bisection (bracket 1e-8 rad): time, map
  evaluations and the difference of the located slopes; both at the maps' default rtol (1e-10), and the
  pseudo-arclength run again at rtol 1e-8 (whose map error, about 1e-10 per `rimless bench`, is still below
  the 1e-9 target) with its difference from the default-rtol slope. Each is the least CPU time (and, beside,
  the least wall time) of three runs after a warm-up run; the ratio bisection / pseudo-arclength is in CPU time.
"""

from __future__ import annotations

import functools
import math
import time
from typing import Any

from rimless.sim.model.params import WheelParams

COMPARED = ("critical_slope_rad", "max_abs_eigenvalue", "step_period_s", "energy_ratio")


def _max_difference(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> float:
    worst = 0.0
    if len(a) != len(b):
        return math.inf
    for ra, rb in zip(a, b):
        for key in COMPARED:
            va, vb = ra.get(key), rb.get(key)
            if isinstance(va, float) and isinstance(vb, float) and va == va and vb == vb:
                worst = max(worst, abs(va - vb))
            elif (va == va) != (vb == vb):
                return math.inf
    return worst


def sweep_bench(points: list[dict[str, Any]], options: Any) -> dict[str, Any]:
    import os

    from rimless.sim.studies.sweep import run_sweep

    out: dict[str, Any] = {
        "grid_points": len(points),
        "cores": os.cpu_count(),
        "load_average_before": os.getloadavg()[0],
    }
    from rimless.sim.studies.bench import time_once
    from rimless.sim.studies.sweep import dask_client

    runs = {}
    t0 = time.perf_counter()
    res, t = time_once(lambda: run_sweep(points, options, scheduler="sync"))
    runs["sync"] = res
    out["sync"] = {"seconds": t.wall_s, "cpu_s": t.cpu_s, "setup_s": res.setup_s, "rows": len(res.rows)}
    for label, workers in (("1 worker", 1), ("2 workers", 2)):
        t0 = time.perf_counter()
        with dask_client("local", workers) as client:
            before = client.run(time.process_time)
            res = run_sweep(points, options, scheduler="local", client=client)
            after = client.run(time.process_time)
        cpu = [after[w] - before[w] for w in after if w in before]
        runs[label] = res
        out[label] = {
            "seconds": time.perf_counter() - t0,
            "cpu_s": sum(cpu),
            "busiest_worker_cpu_s": max(cpu),
            "worker_cpu_s": sorted(cpu),
            "setup_s": res.setup_s,
            "rows": len(res.rows),
        }
    out["load_average_after"] = os.getloadavg()[0]
    out["speedup_1_to_2_workers"] = out["1 worker"]["cpu_s"] / out["2 workers"]["busiest_worker_cpu_s"]
    out["speedup_1_to_2_workers_wall"] = out["1 worker"]["seconds"] / out["2 workers"]["seconds"]
    out["max_difference_between_schedulers"] = max(
        _max_difference(runs["sync"].rows, runs[k].rows) for k in ("1 worker", "2 workers")
    )
    return out


def branch_end_bench(params: WheelParams = WheelParams(), repeats: int = 3) -> dict[str, Any]:  # noqa: B008
    from rimless.sim.continuation.algorithm1 import critical_slope
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import default_guess
    from rimless.sim.studies.bench import time_once

    def run(model: str, method: str, rtol: float, **kw: Any) -> dict[str, Any]:
        best = best_cpu = math.inf
        cs = None
        for _ in range(repeats):
            pmap = make_map(params, model, backend="fast", rtol=rtol)
            cs, t = time_once(
                functools.partial(
                    critical_slope,
                    pmap,
                    default_guess(params, model),
                    jacobian_factory=lambda m: m.jacobian,
                    method=method,
                    **kw,
                )
            )
            best, best_cpu = min(best, t.wall_s), min(best_cpu, t.cpu_s)
        assert cs is not None
        return {
            "seconds": best,
            "cpu_s": best_cpu,
            "critical_slope_rad": cs.critical_slope_rad,
            "reason": cs.reason,
            "map_evaluations": cs.map_evaluations,
            "rtol": rtol,
        }

    out: dict[str, Any] = {}
    for model in ("er", "ve"):
        run(model, "arclength", 1e-10)  # warm-up
        entry: dict[str, Any] = {
            "arclength": run(model, "arclength", 1e-10),
            "bisection": run(model, "bisection", 1e-10, refine_tol_rad=1e-8),
            "arclength_rtol_1e-8": run(model, "arclength", 1e-8),
        }
        entry["difference_rad"] = abs(
            entry["arclength"]["critical_slope_rad"] - entry["bisection"]["critical_slope_rad"]
        )
        entry["bisection_over_arclength_cpu"] = entry["bisection"]["cpu_s"] / entry["arclength"]["cpu_s"]
        entry["bisection_over_arclength_wall"] = entry["bisection"]["seconds"] / entry["arclength"]["seconds"]
        entry["rtol_1e-8_difference_rad"] = abs(
            entry["arclength_rtol_1e-8"]["critical_slope_rad"] - entry["arclength"]["critical_slope_rad"]
        )
        out[model] = entry
    return out


def bench_sweep(
    params: WheelParams, *, models: list[str], grid: dict[str, list[float]], mass_models: list[str], options: Any
) -> dict[str, Any]:
    """`rimless sim sweep --bench`: the grid (no cache) on each scheduler, then the branch-end location at
    `params` by pseudo-arclength against bisection. An empty grid sweeps the wheel's own k."""
    from rimless.sim.studies.sweep import grid_points

    points = grid_points(params, models, grid or {"k": [params.k]}, mass_models)
    return {"sweep": sweep_bench(points, options), "branch_end": branch_end_bench(params)}


def format_bench(result: dict[str, Any]) -> str:
    """The text of `rimless sim sweep --bench`: every ratio from CPU time, wall time beside."""
    lines = []
    s = result.get("sweep")
    if s:
        lines.append(
            f"sweep of {s['grid_points']} grid points (no cache) on {s['cores']} cores, load average "
            f"{s['load_average_before']:.1f} before, {s['load_average_after']:.1f} after (a busy machine "
            "stretches the wall times, not the CPU times):"
        )
        for k in ("sync", "1 worker", "2 workers"):
            cpu = s[k].get("cpu_s")
            per = (
                ""
                if "worker_cpu_s" not in s[k]
                else " (workers " + ", ".join(f"{c:.1f}" for c in s[k]["worker_cpu_s"]) + ")"
            )
            lines.append(
                f"  {k:10s} CPU {'-' if cpu is None else f'{cpu:7.1f}'} s{per}, wall {s[k]['seconds']:7.1f} s "
                f"(worker set-up {s[k]['setup_s']:.1f} s)"
            )
        wall = s.get("speedup_1_to_2_workers_wall")
        lines.append(
            f"  speed-up 1 -> 2 workers: {s['speedup_1_to_2_workers']:.2f}x from CPU time (1 worker's CPU / the "
            f"busiest of 2){'' if wall is None else f', {wall:.2f}x wall'}; largest difference between "
            f"schedulers {s['max_difference_between_schedulers']:.3g}"
        )
    for model, e in result.get("branch_end", {}).items():
        a, b = e["arclength"], e["bisection"]
        ratio = e.get("bisection_over_arclength_cpu")
        lines.append(
            f"{model} branch end: pseudo-arclength {a.get('cpu_s', math.nan):.2f} s CPU ({a['seconds']:.2f} s wall), "
            f"{a['map_evaluations']} maps -> {a['critical_slope_rad']:.9f} rad ({a['reason']}); bisection "
            f"{b.get('cpu_s', math.nan):.2f} s CPU ({b['seconds']:.2f} s wall), {b['map_evaluations']} maps -> "
            f"{b['critical_slope_rad']:.9f} rad ({b['reason']}); difference {e['difference_rad']:.2g} rad"
            + (
                ""
                if ratio is None
                else f"; bisection / pseudo-arclength {ratio:.2f}x CPU ({e['bisection_over_arclength_wall']:.2f}x wall)"
            )
        )
        if "arclength_rtol_1e-8" in e:
            c = e["arclength_rtol_1e-8"]
            lines.append(
                f"  pseudo-arclength at rtol 1e-8: {c.get('cpu_s', math.nan):.2f} s CPU ({c['seconds']:.2f} s wall), "
                f"{c['map_evaluations']} maps -> {c['critical_slope_rad']:.9f} rad ({c['reason']}); "
                f"{e['rtol_1e-8_difference_rad']:.2g} rad from rtol 1e-10"
            )
    return "\n".join(lines)
