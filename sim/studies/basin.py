"""The basin of attraction of a period-1 gait (`rimless sim basin`; Schwab and Wisse 2001).

Every point of an N x N grid over a box of the section (theta+ rad, theta'+ rad/s) is iterated under the
Poincaré map for up to `steps` steps and given a fate (rimless.sim.studies.section_map.FATES):

- "gait": it comes within `tol` (scaled metric below) of the gait's fixed point z*;
- "other-gait": after `steps` steps it repeats itself (period 1 to 4, within `tol`) away from z*;
- "undecided": neither within `steps` steps;
- a failure class of rimless.sim.model.failures.FailureReason ("stall" = falls back, "stance-lift-off" = loses
  contact, ...): the step that failed and why.

Grid points are cell centres, so the basin's area is (number of "gait" points) x (cell area), in rad * rad/s,
and the fraction of the box is that number over N^2. Scaled metric (distances from z*):
d = sqrt((dtheta / (alpha/2))^2 + (dtheta' / theta'*)^2), alpha/2 = pi/8 the half spoke angle and theta'* the
gait's theta'+. `nearest_failure_distance` is the smallest d of a point whose fate is a failure class (known to
within the half diagonal of a cell, `resolution_scaled`); with no failing point in the box it is the distance
to the box's nearest edge, a lower bound (`nearest_failure_is_lower_bound`).

Where the rows run (`scheduler`): the grid's rows of constant theta'+ are the tasks of
rimless.sim.studies.sweep.run_sweep, so a big grid spreads over the same Dask schedulers as `rimless sim sweep`
("sync": this process; "local": a LocalCluster of single-threaded worker processes; "tcp://HOST:PORT": a
running scheduler; "auto": local for grids of at least DASK_MIN_POINTS points when a second core is there,
else sync). Each row is computed by the same function on every scheduler and the rows are put back in grid
order, so the fates do not depend on the scheduler.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rimless.errors import ParameterError
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import SPOKE_ANGLE_RAD
from rimless.sim.studies.section_map import FATES, GAIT, OTHER_GAIT, UNDECIDED, StepMap, apply, failure_fate

NOT_FAILURES = (GAIT, OTHER_GAIT, UNDECIDED)
DASK_MIN_POINTS = 64 * 64  # "auto" puts grids of this many points and more on a local Dask cluster
DEFAULT_THETA_HALF_WIDTH_RAD = 0.15
DEFAULT_THETA_DOT_RANGE = (0.02, 2.5)  # times the gait's theta'+


def default_box(z_star: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """theta+ in z*_0 +- 0.15 rad, theta'+ in [0.02, 2.5] x theta'*."""
    th, w = float(z_star[0]), float(z_star[1])
    return (
        (th - DEFAULT_THETA_HALF_WIDTH_RAD, th + DEFAULT_THETA_HALF_WIDTH_RAD),
        (DEFAULT_THETA_DOT_RANGE[0] * w, DEFAULT_THETA_DOT_RANGE[1] * w),
    )


def check_box(box: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    """((theta lo, hi) rad, (theta' lo, hi) rad/s), finite and lo < hi; ParameterError otherwise."""
    try:
        (a, b), (c, d) = box
        out = ((float(a), float(b)), (float(c), float(d)))
    except (TypeError, ValueError):
        raise ParameterError(f"box must be ((theta_lo, theta_hi), (theta_dot_lo, theta_dot_hi)), got {box!r}") from None
    for (lo, hi), name in zip(out, ("theta+", "theta'+"), strict=True):
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ParameterError(f"box: the {name} range must be finite with low < high, got [{lo:g}, {hi:g}]")
    return out


def scaled_distance(z: np.ndarray, z_star: np.ndarray) -> float:
    """sqrt((dtheta / (alpha/2))^2 + (dtheta' / theta'*)^2)."""
    return float(math.hypot((z[0] - z_star[0]) / (SPOKE_ANGLE_RAD / 2), (z[1] - z_star[1]) / z_star[1]))


def point_fate(
    step_map: StepMap, slope_rad: float, z0: np.ndarray, z_star: np.ndarray, steps: int, tol: float
) -> tuple[str, int, np.ndarray]:
    """(fate, steps taken, last section point) of one start point."""
    z = np.asarray(z0, dtype=float)
    history = [z]
    for k in range(1, steps + 1):
        try:
            z = apply(step_map, z, slope_rad)
        except StepFailure as err:
            return failure_fate(err), k, history[-1]
        if scaled_distance(z, z_star) < tol:
            return GAIT, k, z
        history.append(z)
    for period in range(1, 5):
        if len(history) > period and scaled_distance(history[-1], history[-1 - period]) < tol:
            return OTHER_GAIT, steps, z
    return UNDECIDED, steps, z


@dataclass(frozen=True)
class BasinRows:
    """What every row task needs (sent to the Dask workers: `step_map` must pickle)."""

    step_map: StepMap
    slope_rad: float
    z_star: tuple[float, float]
    thetas: tuple[float, ...]
    steps: int
    tol: float


def basin_row(point: dict[str, Any], task: BasinRows) -> dict[str, Any]:
    """The fates of one grid row (theta'+ = point["theta_dot_plus_rad_s"], every theta+ of the grid), as a
    run_sweep task: {"rows": [{fate, steps, theta_end_rad, theta_dot_end_rad_s}, ...], "points": [], "seconds"}."""
    t0 = time.perf_counter()
    zs = np.array(task.z_star)
    w = float(point["theta_dot_plus_rad_s"])
    rows = []
    for th in task.thetas:
        fate, k, z_end = point_fate(task.step_map, task.slope_rad, np.array([th, w]), zs, task.steps, task.tol)
        rows.append(
            {"fate": fate, "steps": int(k), "theta_end_rad": float(z_end[0]), "theta_dot_end_rad_s": float(z_end[1])}
        )
    return {"rows": rows, "points": [], "seconds": time.perf_counter() - t0}


def resolve_scheduler(scheduler: str, points: int) -> str:
    """ "auto": "local" for at least DASK_MIN_POINTS points when a second process is allowed, else "sync"; any
    other value as given (checked by run_sweep)."""
    if scheduler != "auto":
        return scheduler
    from rimless.second_process import second_process_allowed

    return "local" if points >= DASK_MIN_POINTS and second_process_allowed() else "sync"


def basin_of_attraction(
    step_map: StepMap,
    slope_rad: float,
    z_star: Any,
    *,
    box: Any = None,
    grid: int = 50,
    steps: int = 100,
    tol: float = 1e-4,
    progress: Callable[[int, int], None] | None = None,
    scheduler: str = "sync",
    workers: int | None = None,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The basin of the gait z* of `step_map(z, slope_rad)`: (the JSON object, the per-point arrays).

    scheduler: where the grid's rows run (module doc; with Dask, `step_map` must pickle); workers: the size
    of a local cluster (default one per core). progress(i, n): points done.

    The arrays (one entry per grid point, theta+ varying fastest): theta_plus_rad, theta_dot_plus_rad_s, fate
    (strings), steps (map steps taken), distance_scaled (from z* at the start)."""
    if not (isinstance(grid, int) and 2 <= grid <= 1000):
        raise ParameterError(f"grid must be an integer in [2, 1000], got {grid!r}")
    if not (isinstance(steps, int) and 1 <= steps <= 100_000):
        raise ParameterError(f"steps must be an integer in [1, 100000], got {steps!r}")
    if not (math.isfinite(tol) and 0 < tol < 1):
        raise ParameterError(f"tol must be in (0, 1), got {tol!r}")
    zs = np.asarray(z_star, dtype=float)
    if zs.shape != (2,) or not np.all(np.isfinite(zs)) or zs[1] <= 0:
        raise ParameterError(f"z_star must be a finite section point with theta'+ > 0, got {z_star!r}")
    (t_lo, t_hi), (w_lo, w_hi) = check_box(default_box(zs) if box is None else box)
    dt, dw = (t_hi - t_lo) / grid, (w_hi - w_lo) / grid
    thetas = t_lo + (np.arange(grid) + 0.5) * dt
    omegas = w_lo + (np.arange(grid) + 0.5) * dw
    n = grid * grid
    th_pts = np.tile(thetas, grid)
    w_pts = np.repeat(omegas, grid)
    from rimless.sim.studies.sweep import run_sweep

    where = resolve_scheduler(scheduler, n)
    task = BasinRows(
        step_map, float(slope_rad), (float(zs[0]), float(zs[1])), tuple(float(t) for t in thetas), steps, tol
    )
    row_points = [{"theta_dot_plus_rad_s": float(w)} for w in omegas]
    run = run_sweep(
        row_points,
        task,  # a frozen dataclass: run_sweep's options
        scheduler=where,
        workers=workers if where == "local" else None,
        compute=basin_row,
        setup=_no_setup if where == "sync" else None,
        progress=None if progress is None else (lambda done, total: progress(done * grid, total * grid)),
    )
    fates: list[str] = []
    taken = np.zeros(n, dtype=np.int64)
    dist = np.zeros(n)
    other: list[list[float]] = []
    for i, r in enumerate(run.rows):  # grid order: rows of constant theta'+, theta+ fastest
        fates.append(r["fate"])
        taken[i] = r["steps"]
        dist[i] = scaled_distance(np.array([th_pts[i], w_pts[i]]), zs)
        z_end = np.array([r["theta_end_rad"], r["theta_dot_end_rad_s"]])
        if r["fate"] == OTHER_GAIT and all(scaled_distance(z_end, np.array(o)) > 1e3 * tol for o in other):
            other.append([float(z_end[0]), float(z_end[1])])
    evaluations = int(taken.sum())
    fate_arr = np.array(fates)
    counts = {f: int(np.sum(fate_arr == f)) for f in FATES}
    failing = ~np.isin(fate_arr, NOT_FAILURES)
    non_gait = fate_arr != GAIT
    cell = dt * dw
    edge = min(
        (zs[0] - t_lo) / (SPOKE_ANGLE_RAD / 2),
        (t_hi - zs[0]) / (SPOKE_ANGLE_RAD / 2),
        (zs[1] - w_lo) / zs[1],
        (w_hi - zs[1]) / zs[1],
    )

    def nearest(mask: np.ndarray) -> tuple[float, bool, dict[str, Any] | None]:
        if not mask.any():
            return float(max(edge, 0.0)), True, None
        j = int(np.argmin(np.where(mask, dist, np.inf)))
        return float(dist[j]), False, {"theta_plus_rad": th_pts[j], "theta_dot_plus_rad_s": w_pts[j], "fate": fates[j]}

    nf, nf_bound, nf_point = nearest(failing)
    ng, ng_bound, ng_point = nearest(non_gait)
    out: dict[str, Any] = {
        "slope_rad": float(slope_rad),
        "fixed_point": {"theta_plus_rad": float(zs[0]), "theta_dot_plus_rad_s": float(zs[1])},
        "box": {"theta_plus_rad": [t_lo, t_hi], "theta_dot_plus_rad_s": [w_lo, w_hi]},
        "box_area_rad2_per_s": (t_hi - t_lo) * (w_hi - w_lo),
        "grid": grid,
        "points": n,
        "steps": steps,
        "convergence_tol_scaled": tol,
        "cell_area_rad2_per_s": cell,
        "basin_area_rad2_per_s": counts[GAIT] * cell,
        "basin_area_fraction": counts[GAIT] / n,
        "fate_counts": counts,
        "fates": list(FATES),
        "metric": (
            "scaled distance d = sqrt((dtheta+ / (alpha/2))^2 + (dtheta'+ / theta'*)^2), alpha/2 = pi/8 rad, "
            "theta'* = the gait's theta'+"
        ),
        "metric_scales": {"theta_plus_rad": SPOKE_ANGLE_RAD / 2, "theta_dot_plus_rad_s": float(zs[1])},
        "resolution_scaled": 0.5 * math.hypot(dt / (SPOKE_ANGLE_RAD / 2), dw / zs[1]),
        "nearest_failure_distance": nf,
        "nearest_failure_is_lower_bound": nf_bound,
        "nearest_failure_point": nf_point,
        "nearest_non_gait_distance": ng,
        "nearest_non_gait_is_lower_bound": ng_bound,
        "nearest_non_gait_point": ng_point,
        "other_gaits": [{"theta_plus_rad": o[0], "theta_dot_plus_rad_s": o[1]} for o in other],
        "map_evaluations": evaluations,
        "scheduler": where,
        "workers": run.workers,
    }
    points = {
        "theta_plus_rad": th_pts,
        "theta_dot_plus_rad_s": w_pts,
        "fate": fate_arr,
        "steps": taken,
        "distance_scaled": dist,
    }
    return out, points


def _no_setup() -> float:
    """In this process the map compiles on first use: no worker warm-up."""
    return 0.0


class WheelSlopeMap:
    """SlopeMap(params, model, backend, rtol) built on first use; it pickles as its recipe (for Dask workers),
    never as the compiled map."""

    def __init__(self, params: Any, model: str, backend: str, rtol: float) -> None:
        self.recipe = (params, model, backend, float(rtol))
        self._map: Any = None

    def __call__(self, z: np.ndarray, slope_rad: float) -> np.ndarray:
        if self._map is None:
            from rimless.sim.studies.section_map import SlopeMap

            params, model, backend, rtol = self.recipe
            self._map = SlopeMap(params, model, backend=backend, rtol=rtol)
        return self._map(z, slope_rad)

    def __getstate__(self) -> dict[str, Any]:
        return {"recipe": self.recipe, "_map": None}


def basin_study(
    params: Any,
    model: str,
    *,
    grid: int = 50,
    steps: int = 100,
    box: Any = None,
    tol: float = 1e-4,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: Callable[[int, int], None] | None = None,
    scheduler: str = "auto",
    workers: int | None = None,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The basin of the wheel's period-1 gait (found as `rimless sim fixed-point` finds it); scheduler and
    workers: where the grid's rows run (module doc)."""
    from rimless.sim.studies.gaits import fixed_point_study

    if box is not None:
        check_box(box)
    if not (isinstance(grid, int) and 2 <= grid <= 1000):  # before the fixed point, not after
        raise ParameterError(f"grid must be an integer in [2, 1000], got {grid!r}")
    fp = fixed_point_study(params, model, backend=backend, rtol=rtol)
    z_star = np.array([fp["theta_plus_rad"], fp["theta_dot_plus_rad_s"]])
    smap = WheelSlopeMap(params, model, backend, rtol)
    out, points = basin_of_attraction(
        smap,
        params.slope_rad,
        z_star,
        box=box,
        grid=grid,
        steps=steps,
        tol=tol,
        progress=progress,
        scheduler=scheduler,
        workers=workers,
    )
    out = {"model": model, "slope_deg": params.slope_deg, **out}
    out["fixed_point"].update(
        {
            "step_period_s": fp["step_period_s"],
            "max_abs_eigenvalue": fp["max_abs_eigenvalue"],
            "stable": fp["stable"],
        }
    )
    return out, points


FATE_COLOURS = {
    "gait": "#2ca02c",
    "other-gait": "#1f77b4",
    "undecided": "#bcbd22",
    "stall": "#d62728",
    "stance-lift-off": "#9467bd",
}


def write_basin(out: dict[str, Any], points: dict[str, np.ndarray], folder: str | Path) -> dict[str, str]:
    """basin.png (the fates over the box, the gait marked) and basin.csv (every point) in `folder`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from rimless.output import atomic_file, writable_dir
    from rimless.sim.studies.figures import save_figure

    folder = writable_dir(folder, option="--out")
    csv = folder / "basin.csv"
    with atomic_file(csv, option="--out") as tmp:
        pd.DataFrame(points).to_csv(tmp, index=False)
    n = out["grid"]
    present = [f for f in FATES if out["fate_counts"][f] > 0]
    code = {f: i for i, f in enumerate(present)}
    img = np.array([code[f] for f in points["fate"]]).reshape(n, n)
    grey = plt.get_cmap("tab10")
    colours = [FATE_COLOURS.get(f, grey(i % 10)) for i, f in enumerate(present)]
    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    (t_lo, t_hi), (w_lo, w_hi) = out["box"]["theta_plus_rad"], out["box"]["theta_dot_plus_rad_s"]
    ax.imshow(
        img,
        origin="lower",
        extent=(t_lo, t_hi, w_lo, w_hi),
        aspect="auto",
        cmap=ListedColormap(colours),
        vmin=-0.5,
        vmax=len(present) - 0.5,
        interpolation="nearest",
    )
    fpd = out["fixed_point"]
    ax.plot(fpd["theta_plus_rad"], fpd["theta_dot_plus_rad_s"], "k*", ms=12)
    ax.set_xlabel("theta+ (rad)")
    ax.set_ylabel("theta'+ (rad/s)")
    ax.set_title(
        f"basin of attraction, {out.get('model', '')} wheel at {math.degrees(out['slope_rad']):.3f} deg: "
        f"{100 * out['basin_area_fraction']:.1f} % of the box"
    )
    ax.legend(
        handles=[Patch(color=c, label=f"{f} ({out['fate_counts'][f]})") for f, c in zip(present, colours, strict=True)],
        loc="upper left",
        fontsize=8,
    )
    png = save_figure(fig, folder / "basin.png", option="--out")
    return {"figure": str(png), "csv": str(csv)}
