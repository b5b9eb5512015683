"""Sweep of the firmware-in-the-loop gait over sensor rate and clutch delay, against the ideal clutch.

Each grid point (rate_hz, delay_s) is one walk from the ideal-clutch fixed point (firmware_fixed_point);
points are independent, so they run as tasks: in this process (`scheduler="sync"`), on a
dask.distributed LocalCluster (`"local"`, one single-threaded worker process per core) or on a running
cluster (`"tcp://HOST:PORT"`), like rimless.sim.sweep.

Per point: the fixed point and period against the ideal, the mean walking speed (step length / period,
m/s) as a fraction of the ideal's, the stored energy as a fraction of the ideal's, the fitted stability,
and how the walk ended. At one slope the cost of transport of a passive walker is tan(slope) whatever the
clutch, so the clutch's cost shows as a slower gait (and a higher critical slope: see
firmware_critical_slope), which is what `speed_ratio` and `stored_energy_ratio` measure.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.errors import ParameterError


def sweep_point(params_dict: dict[str, Any], rate_hz: float, delay_s: float, steps: int, noise_counts: float,
                seed: int, ideal: dict[str, float]) -> dict[str, Any]:
    """One grid point (runs in a worker)."""
    from rimless.sim.failures import StepFailure
    from rimless.sim.firmware_loop import FirmwareLoopConfig, firmware_fixed_point
    from rimless.sim.params import WheelParams

    params = WheelParams(**params_dict)
    cfg = FirmwareLoopConfig(rate_hz=rate_hz, engage_delay_s=delay_s, release_delay_s=delay_s,
                             noise_counts=noise_counts, seed=seed)
    row: dict[str, Any] = {"rate_hz": rate_hz, "delay_ms": delay_s * 1e3}
    z_ideal = np.array([ideal["theta_plus_rad"], ideal["theta_dot_plus_rad_s"]])
    try:
        fp = firmware_fixed_point(params, cfg, z_ideal, steps=steps, n_average=min(4, steps))
    except StepFailure as err:
        row.update(walks=False, failure=err.reason.value, detail=str(err))
        return row
    step_length = 2.0 * params.leg_length_m * math.sin(math.pi / 8)  # between feet at rest length, m
    speed = step_length / fp.period_s
    eig = np.abs(fp.eigenvalues)
    row.update(
        walks=fp.walk.failure is None,
        failure=None if fp.walk.failure is None else fp.walk.failure.reason.value,
        steps_done=len(fp.walk.steps),
        theta_dot_plus_rad_s=float(fp.z[1]),
        step_period_s=fp.period_s,
        speed_ratio=speed / (step_length / ideal["step_period_s"]),
        stored_energy_ratio=fp.stored_energy_J / ideal["stored_energy_J"],
        max_abs_eigenvalue_fitted=float(np.max(eig)) if np.all(np.isfinite(eig)) else None,
        lock_classes=sorted({s.lock_class for s in fp.walk.steps}),
    )
    return row


def run_firmware_sweep(params: Any, rates_hz: list[float], delays_s: list[float], *, steps: int = 8,
                       noise_counts: float = 1.0, seed: int = 0, scheduler: str = "sync", workers: int | None = None,
                       progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Every (rate, delay) point, rows in grid order, plus the ideal clutch's reference values."""
    from rimless.sim.firmware_cli import ideal_fixed_point

    fp = ideal_fixed_point(params, backend="reference", rtol=1e-9)
    ideal = {"theta_plus_rad": float(fp.z[0]), "theta_dot_plus_rad_s": float(fp.z[1]),
             "step_period_s": float(fp.step.period_s),
             "stored_energy_J": 0.5 * params.k * (params.leg_length_m - float(fp.step.y_minus[3])) ** 2}
    grid = [(r, d) for r in rates_hz for d in delays_s]
    args = [(params.to_dict(), r, d, steps, noise_counts, seed, ideal) for r, d in grid]
    rows: list[dict[str, Any] | None] = [None] * len(grid)
    if scheduler == "sync":
        for i, a in enumerate(args):
            rows[i] = sweep_point(*a)
            if progress:
                progress(i + 1, len(grid))
    else:
        from dask.distributed import Client, LocalCluster, as_completed

        if scheduler == "local":
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=40)
            client = Client(cluster)
        elif scheduler.startswith(("tcp://", "tls://")):
            cluster = None
            client = Client(scheduler, timeout=15)
        else:
            raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
        try:
            futures = {client.submit(sweep_point, *a, pure=False): i for i, a in enumerate(args)}
            for n, fut in enumerate(as_completed(futures), 1):
                rows[futures[fut]] = fut.result()
                if progress:
                    progress(n, len(grid))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    return {"ideal": ideal, "rows": rows, "steps": steps, "noise_counts": noise_counts}



def plot_firmware_sweep(out: dict[str, Any], path: Any) -> Any:
    """Speed and stored energy as fractions of the ideal clutch's, against the clutch delay, one line per rate."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rimless.output import atomic_file

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), sharex=True)
    rates = sorted({r["rate_hz"] for r in out["rows"]})
    for rate in rates:
        rows = sorted((r for r in out["rows"] if r["rate_hz"] == rate and r.get("steps_done")),
                      key=lambda r: r["delay_ms"])
        d = [r["delay_ms"] for r in rows]
        axes[0].plot(d, [r["speed_ratio"] for r in rows], "o-", label=f"{rate:g} Hz")
        axes[1].plot(d, [r["stored_energy_ratio"] for r in rows], "o-", label=f"{rate:g} Hz")
        failed = [r["delay_ms"] for r in out["rows"] if r["rate_hz"] == rate and not r.get("walks")]
        for ax in axes:
            for x in failed:
                ax.axvline(x, color="tab:red", lw=0.8, ls=":")
    axes[0].set_ylabel("walking speed / ideal clutch")
    axes[1].set_ylabel("stored energy / ideal clutch")
    for ax in axes:
        ax.set_xlabel("clutch delay, engage = release (ms)")
        ax.axhline(1.0, color="0.5", lw=0.8)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("ER wheel with the firmware in the loop (dotted red: the walk failed)", fontsize=10)
    fig.tight_layout()
    try:
        with atomic_file(path, option="--plot") as tmp:
            fig.savefig(tmp, dpi=120)
    finally:
        plt.close(fig)
    return path
