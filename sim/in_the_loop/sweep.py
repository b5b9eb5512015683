"""Sweep of the firmware-in-the-loop gait over sensor rate and clutch delay, against the ideal clutch.

Each grid point (rate_hz, delay) is one walk from the ideal-clutch fixed point (firmware_fixed_point) and,
with `critical_slope`, the critical slope under the firmware (firmware_boundaries). Points are independent
and run through rimless.sim.studies.sweep.run_sweep (`compute=compute_firmware_point`): in this process
(`scheduler="sync"`), on a dask.distributed LocalCluster (`"local"`) or a running cluster
(`"tcp://HOST:PORT"`), each point cached on disk by the hash of its parameters and options, so a re-run
or an extended grid recomputes nothing already done.

Per point: the fixed point and period against the ideal clutch, the mean walking speed (step length /
period) and the stored energy as fractions of the ideal's, the fitted stability beside the ideal's, and
how the walk ended. At one slope the cost of transport of a passive walker is tan(slope) whatever the
clutch, so the clutch's cost shows as a slower gait and a higher critical slope; with `critical_slope`
the CoT = tan(phi_c) is compared with the ideal ER and the VE wheels' (two reference grid points, the
continuation of `rimless sim critical-slope`), as the share of the ER advantage over VE that remains:
(CoT_VE - CoT_firmware) / (CoT_VE - CoT_ER ideal).
"""

from __future__ import annotations

import functools
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

STEP_LENGTH_FACTOR = 2.0 * math.sin(math.pi / 8)  # step length between feet at rest length / L0


@dataclass(frozen=True)
class FirmwareSweepOptions:
    """What every firmware grid point is computed with (part of the cache key with the point)."""

    kind: str = "firmware-clutch"  # keeps these cache entries apart from the branch sweep's
    version: int = 1  # bump when what a point computes changes (the cache key holds it)
    steps: int = 8
    noise_counts: float = 1.0
    jitter_ms: float = 0.05
    holding_force_N: float = 100.0
    seed: int = 0
    critical_slope: bool = False
    critical_low_deg: float = 0.5
    critical_tol_deg: float = 0.05
    ve_branch: str = "fast"  # the VE gait the ER advantage is measured against (the paper's: fast)


def firmware_grid_points(
    params: Any, rates_hz: list[float], delays_ms: list[float], *, references: bool = False
) -> list[dict[str, Any]]:
    """Every (rate, delay) as a plain dict (the task's input), rates outer; with `references`, the
    ideal-ER and VE critical-slope reference points first."""
    base = params.to_dict()
    refs = [{"clutch": "ideal", "model": m, "params": base} for m in ("er", "ve")] if references else []
    return refs + [
        {"clutch": "firmware", "params": base, "rate_hz": float(r), "delay_ms": float(d)}
        for r in rates_hz
        for d in delays_ms
    ]


@functools.lru_cache(maxsize=8)
def _ideal_reference(params_json: str) -> dict[str, float]:
    """The ideal-clutch ER fixed point at these parameters (per worker process, computed once)."""
    from rimless.sim.in_the_loop.ideal import ideal_fixed_point
    from rimless.sim.model.params import WheelParams

    params = WheelParams(**json.loads(params_json))
    fp = ideal_fixed_point(params, backend="reference", rtol=1e-9)
    return {
        "theta_plus_rad": float(fp.z[0]),
        "theta_dot_plus_rad_s": float(fp.z[1]),
        "step_period_s": float(fp.step.period_s),
        "stored_energy_J": 0.5 * params.k * (params.leg_length_m - float(fp.step.y_minus[3])) ** 2,
        "max_abs_eigenvalue": float(np.max(np.abs(fp.eigenvalues))),
    }


def ideal_reference(params: Any) -> dict[str, float]:
    """The ideal-clutch ER fixed point's values the firmware rows are compared with."""
    return dict(_ideal_reference(json.dumps(params.to_dict(), sort_keys=True)))


def compute_firmware_point(point: dict[str, Any], options: FirmwareSweepOptions) -> dict[str, Any]:
    """One grid point (runs in a worker; plain data in and out): {"rows": [row], "points": [], "seconds"}."""
    t0 = time.perf_counter()
    row = _reference_row(point, options) if point["clutch"] == "ideal" else _firmware_row(point, options)
    return {"rows": [row], "points": [], "seconds": time.perf_counter() - t0}


def _reference_row(point: dict[str, Any], options: FirmwareSweepOptions) -> dict[str, Any]:
    """Critical slope and CoT of the ideal-clutch ER wheel or of the VE wheel's `options.ve_branch` gait (the
    paper compares with the fast one): every gait at 0.05 rad followed down in slope, as `rimless sim gaits`
    and the branch sweep do (rimless.sim.continuation.branches.trace_gait_branches)."""
    from rimless.sim.continuation.branches import trace_gait_branches
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams

    params = WheelParams(**point["params"])
    model = point["model"]
    want = "er" if model == "er" else options.ve_branch
    row: dict[str, Any] = {"clutch": "ideal" if model == "er" else "none (VE)", "model": model, "branch_label": want}
    try:
        branches = [b.row() for b in trace_gait_branches(params, model, backend="auto", rtol=1e-10)]
    except StepFailure as err:
        branches, why = [], str(err)
    else:
        why = f"no {want} gait at 0.05 rad (gaits: {', '.join(b['branch_label'] for b in branches) or 'none'})"
    usable = [b for b in branches if math.isfinite(b["critical_slope_rad"]) and b["stable_at_start"]]
    found = [b for b in usable if b["branch_label"] == want]
    note = ""
    if not found and model == "ve" and usable:  # e.g. Table 1's k: the fast gait is unstable, compare with the best
        found = [min(usable, key=lambda r: r["critical_slope_rad"])]
        note = f"{why}; compared with the VE gait of lowest critical slope instead. "
    if not found:
        row.update(critical_slope_deg=None, cot=None, limited_by="no gait", detail=why)
        return row
    b = min(found, key=lambda r: r["critical_slope_rad"])
    row.update(
        branch_label=b["branch_label"],
        critical_slope_deg=b["critical_slope_deg"],
        cot=b["cot"],
        limited_by="mechanics",
        detail=f"{note}{b['reason']}: {b['detail']}",
        step_period_s=b["step_period_s"],
    )
    return row


def _firmware_row(point: dict[str, Any], options: FirmwareSweepOptions) -> dict[str, Any]:
    from rimless.sim.in_the_loop.loop import FirmwareLoopConfig
    from rimless.sim.in_the_loop.studies import firmware_boundaries, firmware_fixed_point
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams

    params = WheelParams(**point["params"])
    rate_hz, delay_s = point["rate_hz"], point["delay_ms"] * 1e-3
    cfg = FirmwareLoopConfig(
        rate_hz=rate_hz,
        engage_delay_s=delay_s,
        release_delay_s=delay_s,
        noise_counts=options.noise_counts,
        jitter_s=options.jitter_ms * 1e-3,
        holding_force_N=options.holding_force_N,
        seed=options.seed,
    )
    ideal = ideal_reference(params)
    row: dict[str, Any] = {
        "clutch": "firmware",
        "model": "er",
        "rate_hz": rate_hz,
        "delay_ms": point["delay_ms"],
        "noise_counts": options.noise_counts,
        "slope_deg": params.slope_deg,
    }
    z_ideal = np.array([ideal["theta_plus_rad"], ideal["theta_dot_plus_rad_s"]])
    try:
        fp = firmware_fixed_point(params, cfg, z_ideal, steps=options.steps, n_average=min(4, options.steps))
    except StepFailure as err:
        row.update(walks=False, failure=err.reason.value, detail=str(err), steps_done=0)
    else:
        walk = fp.walk
        eig = np.abs(fp.eigenvalues)
        faults = [f["fault"] for _, name, f in walk.events if name == "fault"]
        row.update(
            walks=walk.failure is None and not faults,
            failure=(
                walk.failure.reason.value
                if walk.failure is not None
                else f"firmware fault: {', '.join(faults)}"
                if faults
                else None
            ),
            detail=str(walk.failure) if walk.failure is not None else "",
            steps_done=len(walk.steps),
            theta_plus_rad=float(fp.z[0]),
            theta_dot_plus_rad_s=float(fp.z[1]),
            step_period_s=fp.period_s,
            speed_ratio=ideal["step_period_s"] / fp.period_s,  # same step length: speed ratio = period ratio^-1
            stored_energy_J=fp.stored_energy_J,
            stored_energy_ratio=fp.stored_energy_J / ideal["stored_energy_J"],
            max_abs_eigenvalue_fitted=float(np.max(eig)) if np.all(np.isfinite(eig)) else None,
            max_abs_eigenvalue_ideal=ideal["max_abs_eigenvalue"],
            stable_fitted=fp.stable,
            lock_classes=",".join(sorted({s.lock_class for s in walk.steps})),
            energy_residual_max_J=max((abs(s.energy_residual_J) for s in walk.steps), default=None),
        )
    if options.critical_slope:
        try:
            b = firmware_boundaries(
                params,
                cfg,
                low_rad=math.radians(options.critical_low_deg),
                steps=options.steps,
                tol_rad=math.radians(options.critical_tol_deg),
            )
        except ValueError as err:
            row.update(
                critical_slope_deg=None,
                cot=None,
                limited_by="not bracketed",
                critical_detail=str(err),
                mechanical_critical_slope_deg=None,
            )
        else:
            phi = b.firmware.critical_slope_rad
            mech = b.mechanical_slope_rad
            row.update(
                critical_slope_deg=math.degrees(phi),
                cot=math.tan(phi),
                limited_by=b.limited_by,
                firmware_fault_below=b.firmware.limited_by == "firmware",
                critical_detail=b.detail,
                mechanical_critical_slope_deg=math.degrees(mech) if math.isfinite(mech) else None,
            )
    return row


def _no_setup() -> float:
    """The firmware walks run on the reference path: no compiled kernels to load."""
    return 0.0


def add_advantage(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Fill `er_advantage_remaining` (share of the ideal ER's CoT saving over VE kept under the firmware)
    in the firmware rows from the two reference rows; returns {"er_ideal": row, "ve": row} (or {})."""
    refs = {r["model"]: r for r in rows if r.get("clutch") != "firmware"}
    er, ve = refs.get("er"), refs.get("ve")
    if not (er and ve and er.get("cot") is not None and ve.get("cot") is not None):
        return {}
    saving = ve["cot"] - er["cot"]
    if not saving > 1e-3 * ve["cot"]:  # no ER advantage over this VE gait to keep a share of
        er["cot_saving_vs_ve"] = saving / ve["cot"]
        return {"er_ideal": er, "ve": ve}
    er["cot_saving_vs_ve"] = saving / ve["cot"]
    for r in rows:
        if r.get("clutch") == "firmware" and r.get("cot") is not None:
            r["cot_saving_vs_ve"] = (ve["cot"] - r["cot"]) / ve["cot"]
            r["er_advantage_remaining"] = (ve["cot"] - r["cot"]) / saving if saving > 0 else None
    return {"er_ideal": er, "ve": ve}


def run_firmware_grid(
    params: Any,
    rates_hz: list[float],
    delays_ms: list[float],
    options: FirmwareSweepOptions,
    *,
    scheduler: str = "local",
    workers: int | None = None,
    cache_dir: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Every (rate, delay) point through rimless.sim.studies.sweep.run_sweep (Dask, on-disk cache); rows in grid
    order (references first when `options.critical_slope`), the ideal clutch's values, the run's counts."""
    from rimless.sim.studies.sweep import run_sweep

    points = firmware_grid_points(params, rates_hz, delays_ms, references=options.critical_slope)
    needs_kernels = options.critical_slope  # the reference continuations use the compiled path
    res = run_sweep(
        points,
        options,
        scheduler=scheduler,
        workers=workers,
        cache_dir=cache_dir,
        progress=progress,
        compute=compute_firmware_point,
        setup=None if needs_kernels else _no_setup,
    )
    refs = add_advantage(res.rows)
    return {
        "ideal": ideal_reference(params),
        "references": refs,
        "rows": res.rows,
        "steps": options.steps,
        "noise_counts": options.noise_counts,
        "seconds": res.seconds,
        "computed": res.computed,
        "cached": res.cached,
        "workers": res.workers,
    }


def run_firmware_sweep(
    params: Any,
    rates_hz: list[float],
    delays_s: list[float],
    *,
    steps: int = 8,
    noise_counts: float = 1.0,
    seed: int = 0,
    scheduler: str = "sync",
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    cache_dir: str | Path | None = None,
) -> dict[str, Any]:
    """Every (rate, delay s) point, rows in grid order, plus the ideal clutch's reference values
    (`rimless sim firmware-sweep`; no critical slopes; no cache unless `cache_dir`)."""
    opts = FirmwareSweepOptions(steps=steps, noise_counts=noise_counts, seed=seed)
    return run_firmware_grid(
        params,
        rates_hz,
        [d * 1e3 for d in delays_s],
        opts,
        scheduler=scheduler,
        workers=workers,
        cache_dir=cache_dir,
        progress=progress,
    )


def plot_firmware_sweep(out: dict[str, Any], path: Any) -> Any:
    """The designer's figure: how much of the ER wheel's advantage remains against clutch delay, one line
    per sensor rate, the ideal clutch as the reference line (1, or its eigenvalue).

    Panels: the share of the ideal ER's CoT saving over VE that remains (with critical slopes; otherwise
    the walking speed relative to the ideal clutch), the stored energy relative to the ideal clutch's,
    and max |eigenvalue| of the map fitted to the walk beside the ideal clutch's (below 1: stable).
    Open markers: the boundary is set by a firmware fault, not by the mechanics; red dotted: the walk failed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rimless.sim.studies.figures import save_figure

    fw_rows = [r for r in out["rows"] if r.get("clutch", "firmware") == "firmware"]
    with_cot = any(r.get("er_advantage_remaining") is not None for r in fw_rows)
    first = (
        ("er_advantage_remaining", "ER advantage kept\n(CoT saving vs VE / ideal's)")
        if with_cot
        else ("speed_ratio", "walking speed / ideal clutch")
    )
    panels = [
        first,
        ("stored_energy_ratio", "stored energy / ideal clutch"),
        ("max_abs_eigenvalue_fitted", "max |eigenvalue| (fitted)"),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), sharex=True)
    rates = sorted({r["rate_hz"] for r in fw_rows})
    for rate in rates:
        rows = sorted((r for r in fw_rows if r["rate_hz"] == rate), key=lambda r: r["delay_ms"])
        for ax, (key, _) in zip(axes, panels):
            pts = [(r["delay_ms"], r.get(key), r.get("limited_by")) for r in rows if r.get(key) is not None]
            (line,) = ax.plot([d for d, _, _ in pts], [v for _, v, _ in pts], "o-", label=f"{rate:g} Hz")
            if key == "er_advantage_remaining":
                lim = [(d, v) for d, v, by in pts if by == "firmware"]
                ax.plot([d for d, _ in lim], [v for _, v in lim], "o", mfc="white", color=line.get_color())
        for ax in axes:
            for r in rows:
                if not r.get("walks"):
                    ax.axvline(r["delay_ms"], color="tab:red", lw=0.8, ls=":")
    ideal_eig = out.get("ideal", {}).get("max_abs_eigenvalue")
    for ax, (key, label) in zip(axes, panels):
        ax.set_ylabel(label)
        ax.set_xlabel("clutch delay, engage = release (ms)")
        ax.grid(alpha=0.3)
        if key == "max_abs_eigenvalue_fitted":
            if ideal_eig is not None:
                ax.axhline(ideal_eig, color="0.3", lw=1.2, label="ideal clutch")
            ax.axhline(1.0, color="tab:red", lw=0.8, ls="--", label="stability limit")
        else:
            ax.axhline(1.0, color="0.3", lw=1.2, label="ideal clutch")
            if key == "er_advantage_remaining":
                ax.axhline(0.0, color="tab:red", lw=0.8, ls="--", label="no better than VE")
    axes[0].legend(fontsize=8)
    axes[2].legend(fontsize=8)
    fig.suptitle(
        "ER wheel with the firmware in the loop against the ideal clutch (open: firmware-limited "
        "boundary; red dotted: the walk failed)",
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(fig, path, dpi=120, option="--plot")


def firmware_sweep_table(
    params: Any,
    *,
    rate_hz: str | None,
    clutch_delay_ms: str | None,
    noise_counts: float | None,
    steps: int,
    seed: int,
    critical_slope: bool,
    critical_low_deg: float,
    out: Path,
    scheduler: str,
    workers: int | None,
    cache_dir: Any,
    plot: Any,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """`rimless sim sweep --clutch firmware`: the grid of `rate_hz` x `clutch_delay_ms` (the options' text,
    Hz and ms) on Dask with the sweep's cache, written as `out`.parquet/.csv, with the figure at `plot`.
    Errors name the option. Returns the command's JSON object."""
    from rimless.errors import ParameterError
    from rimless.output import check_output_folder, writable_dir
    from rimless.sim.studies.sweep import write_table
    from rimless.values import parse_range

    rates = parse_range(rate_hz or "300,1000", "--rate-hz")
    delays = parse_range(clutch_delay_ms or "0:10:2.5", "--clutch-delay-ms")
    if any(not 1.0 <= r <= 1e6 for r in rates):
        raise ParameterError(f"--rate-hz must be rates in [1, 1e6] Hz, got {rate_hz!r}")
    if any(not 0.0 <= d <= 1000.0 for d in delays):
        raise ParameterError(f"--clutch-delay-ms must be delays in [0, 1000] ms, got {clutch_delay_ms!r}")
    noise = 1.0 if noise_counts is None else noise_counts
    if not (noise == noise and 0.0 <= noise <= 1000.0):
        raise ParameterError(f"--noise-counts must be a noise level in [0, 1000] counts, got {noise}")
    if not (math.isfinite(critical_low_deg) and 0.0 <= critical_low_deg < params.slope_deg):
        raise ParameterError(
            f"--critical-low-deg must be in [0, the slope {params.slope_deg:g} deg), got {critical_low_deg}"
        )
    check_output_folder(out.parent if str(out.parent) else ".", option="--out")
    if cache_dir is not None:
        writable_dir(cache_dir, option="--cache-dir")
    options = FirmwareSweepOptions(
        steps=steps, noise_counts=noise, seed=seed, critical_slope=critical_slope, critical_low_deg=critical_low_deg
    )
    try:
        res = run_firmware_grid(
            params, rates, delays, options, scheduler=scheduler, workers=workers, cache_dir=cache_dir, progress=progress
        )
    except ConnectionError as err:
        raise ParameterError(f"--scheduler: {err}") from None
    meta = {
        "clutch": "firmware",
        "grid": {"rate_hz": rates, "delay_ms": delays},
        "options": options.__dict__,
        "base_params": params.to_dict(),
        "scheduler": scheduler,
        "ideal": res["ideal"],
    }
    paths = write_table(res["rows"], out, meta)
    res["plot"] = str(plot_firmware_sweep(res, plot)) if plot is not None else None
    return {
        "clutch": "firmware",
        "rows": res["rows"],
        "ideal": res["ideal"],
        "references": res["references"],
        "files": [str(p) for p in paths],
        "plot": res["plot"],
        "seconds": res["seconds"],
        "computed": res["computed"],
        "cached": res["cached"],
        "scheduler": scheduler,
        "workers": res["workers"],
        "grid": meta["grid"],
    }


def firmware_sweep_figure(
    params: Any, rates_hz: list[float], delays_s: list[float], *, plot: Any = None, **options: Any
) -> dict[str, Any]:
    """`rimless sim firmware-sweep`: `run_firmware_sweep` and, with `plot`, its figure (key `plot`: its path)."""
    out = run_firmware_sweep(params, rates_hz, delays_s, **options)
    out["plot"] = str(plot_firmware_sweep(out, plot)) if plot is not None else None
    return out
