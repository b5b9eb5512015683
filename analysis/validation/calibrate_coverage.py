"""Coverage of `rimless.analysis.calibrate`'s per-parameter intervals through the importer.

Each series draws a compliant ER wheel away from Table 1 (k 1500-4000 N/m, c 2-20 N s/m; Table 1: 2700, 8; the
rest Table 1's), walks it with the simulator's ER model (`floquet_truth.er_walk`, no slope wander) on
``trials`` slopes of 2-3.5 deg, each released at its gait's speed times U(0.95, 1.08), writes each walk as a
Vicon export in a lab drawn per series (`importer_coverage.draw_lab`, `critical_truth.record`), imports it and
fits ``fit`` (default c and k) with the held parameters at the truth's values, exact (``uncertainty`` 0: the
intervals are the data's; the held parameters' part is not exercised here). Reported per parameter: how often
the 95 % interval (``ci95``) holds the truth (Wilson interval), the median relative error, the rms of
(estimate - truth) / se (``rms_z``: 1 for an honest se), the median parts of the se (the data's, the
trial-clustered sandwich's and the measured slopes', `rimless.analysis.inference.trial_slopes`), how often the
parameter was called identifiable (or effective only), the optimiser's end states, and every refused import and
failed fit with its reason.

The truth's dynamics are the calibration's own model (the simulator's ER wheel): this checks the importer,
the fit and its intervals, not the model's adequacy (`critical_truth` does that for the critical slope).
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.validation.coverage import wilson_interval
from rimless.analysis.validation.critical_truth import record
from rimless.analysis.validation.floquet_truth import er_walk
from rimless.analysis.validation.importer_coverage import draw_lab

__all__ = ["K_RANGE", "C_RANGE", "WalkedSeries", "run_calibrate_coverage", "walk_and_import"]

K_RANGE = (1500.0, 4000.0)
C_RANGE = (2.0, 20.0)
FIELDS = {"c": "damping_ns_per_m", "k": "stiffness_n_per_m"}


@dataclass
class WalkedSeries:
    """One series' trials: the exports written (``paths``), the true slope of each by file name (deg), the walks
    that stalled, what was refused (truth walks that failed, imports refused) and the imported trials."""

    paths: list[Path] = field(default_factory=list)
    slopes_deg: dict[str, float] = field(default_factory=dict)
    stalled: int = 0
    refused: list[str] = field(default_factory=list)
    loaded: list[Any] = field(default_factory=list)
    names: list[str] = field(default_factory=list)


def walk_and_import(
    truth: Any,
    lab: Any,
    rng: np.random.Generator,
    folder: Path,
    prefix: str,
    trials: int,
    steps: int,
    *,
    importing: Callable[[], None] | None = None,
) -> WalkedSeries:
    """``trials`` walks of the ER wheel ``truth`` on sorted slopes U(2, 3.5) deg, each released at its gait's
    speed times U(0.95, 1.08) (`floquet_truth.er_walk`), written as Vicon exports ``folder/{prefix}t{j}.csv`` in
    ``lab`` (`critical_truth.record`), then imported (`import_trial`, defaults); ``importing`` is called between."""
    from rimless.analysis.kinematics.build import import_trial
    from rimless.errors import RimlessError
    from rimless.sim.model.failures import StepFailure

    out = WalkedSeries()
    for j, slope in enumerate(np.sort(rng.uniform(2.0, 3.5, trials))):
        try:
            wk = er_walk(truth, float(slope), 0.0, steps, rng, release=float(rng.uniform(0.95, 1.08)))
        except StepFailure as err:
            out.refused.append(f"truth walk failed: {err}")
            continue
        out.stalled += wk.stalled
        out.paths.append(Path(record(wk, folder / f"{prefix}t{j}.csv", rng, lab, rest_s=0.0)))
        out.slopes_deg[out.paths[-1].name] = float(slope)
    if importing:
        importing()
    for p in out.paths:
        try:
            out.loaded.append(import_trial(p))
            out.names.append(p.name)
        except RimlessError as err:
            out.refused.append(str(err).splitlines()[0])
    return out


def run_calibrate_coverage(
    n_series: int,
    seed: int,
    calibrate: Callable[..., Any],
    *,
    fit: Sequence[str] = ("c", "k"),
    trials: int = 4,
    steps: int = 10,
    progress: Callable[[int, str], None] | None = None,
) -> dict[str, Any]:
    """``n_series`` series; ``calibrate(trials, fit=..., wheel=..., names=...)`` is the fit (the public
    `rimless.analysis.calibrate`). Returns the JSON-ready summary with ``per_series``."""
    from rimless.errors import RimlessError
    from rimless.sim import Wheel
    from rimless.sim.model.params import WheelParams
    from rimless.sim.model.uncertain import UNCERTAIN_FIELDS

    bad = [f for f in fit if f not in FIELDS]
    if bad or not fit:
        raise ValueError(f"fit takes {', '.join(FIELDS)}, got {list(fit)}")
    rng = np.random.default_rng(seed)
    cpu, wall = time.process_time(), time.perf_counter()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix=f"rimless-calcov-{os.getpid()}-") as tmp:
        for i in range(n_series):
            truth = WheelParams(
                stiffness_n_per_m=float(rng.uniform(*K_RANGE)), damping_ns_per_m=float(rng.uniform(*C_RANGE))
            )
            lab = draw_lab(rng)
            if progress:
                progress(i, "walking and writing")

            def importing(i: int = i) -> None:
                if progress:
                    progress(i, "importing")

            series = walk_and_import(truth, lab, rng, Path(tmp), f"s{i}_", trials, steps, importing=importing)
            paths, refused, stalled, loaded, names = (
                series.paths,
                series.refused,
                series.stalled,
                series.loaded,
                series.names,
            )
            row: dict[str, Any] = {
                "truth": {n: getattr(truth, FIELDS[n]) for n in fit},
                "lab": {"up": lab.up, "heading_deg": lab.heading_deg, "markers": lab.markers},
                "trials": len(paths),
                "refused": refused,
                "stalled_walks": stalled,
            }
            if progress:
                progress(i, "calibrating")
            exact = Wheel(truth, uncertainty={f: 0.0 for f in UNCERTAIN_FIELDS})
            try:
                if len(loaded) < 2:
                    raise RimlessError(f"{len(loaded)} trial(s) imported")
                res = calibrate(loaded, fit=tuple(fit), wheel=exact, names=names)
            except RimlessError as err:
                row["failed"] = f"{type(err).__name__}: {str(err).splitlines()[0]}"
                rows.append(row)
                continue
            row["converged"] = bool(res.converged)
            row["optimizer"] = {
                k: res.optimizer.get(k)
                for k in ("status", "message", "best_start", "several_minima", "polish", "above_optimum_chi2")
            }
            row["params"] = {}
            for pe in res.params:
                key = next((n for n, f in FIELDS.items() if f == pe.field), pe.name)
                t = row["truth"].get(key)
                if t is None:
                    continue
                lo, hi = pe.ci95
                finite = math.isfinite(pe.se)
                row["params"][key] = {
                    "value": pe.value,
                    "se": pe.se if finite else None,
                    "ci95": [lo, hi] if finite else None,
                    "covered": bool(finite and lo <= t <= hi),
                    "relative_error": pe.value / t - 1.0,
                    "identifiable": bool(pe.identifiable),
                    "effective_only": bool(pe.effective_only),
                    "z": (pe.value - t) / pe.se if finite and pe.se > 0 else None,
                    "se_model": pe.se_model,
                    "se_sandwich": pe.se_sandwich,
                    "se_slope": pe.se_slope,
                }
            rows.append(row)
            if progress:
                progress(i + 1, "done")
    return _summary(rows, tuple(fit), seed, trials, steps, time.process_time() - cpu, time.perf_counter() - wall)


def _rel(got: list[dict[str, Any]], rows: list[dict[str, Any]], name: str, part: str) -> list[float]:
    """Each series' ``part`` of the standard error over its truth (the finite ones)."""
    out = []
    for g, r in zip(got, rows):
        v = g.get(part)
        if v is not None and math.isfinite(v):
            out.append(v / r["truth"][name])
    return out


def _summary(
    rows: list[dict[str, Any]], fit: tuple[str, ...], seed: int, trials: int, steps: int, cpu_s: float, wall_s: float
) -> dict[str, Any]:
    per: dict[str, Any] = {}
    fitted = [r for r in rows if "params" in r]
    for name in fit:
        rows_of = [r for r in fitted if name in r["params"]]
        got = [r["params"][name] for r in rows_of]
        k = sum(g["covered"] for g in got)
        lo, hi = wilson_interval(k, len(got))
        errs = [g["relative_error"] for g in got]
        per[name] = {
            "fitted": len(got),
            "covered": k,
            "coverage": k / len(got) if got else None,
            "coverage_ci95": [lo, hi] if got else None,
            "identifiable": sum(g["identifiable"] for g in got),
            "median_relative_error": float(np.median(errs)) if errs else None,
            "median_abs_relative_error": float(np.median(np.abs(errs))) if errs else None,
            "rms_z": (
                float(np.sqrt(np.mean(np.square(zs))))
                if (zs := [g["z"] for g in got if g.get("z") is not None])
                else None
            ),
            "median_relative_se": {
                part: float(np.median(v)) if (v := _rel(got, rows_of, name, part)) else None
                for part in ("se_model", "se_sandwich", "se_slope")
            },
            "effective_only": sum(bool(g.get("effective_only")) for g in got),
            "median_relative_half_width": (
                float(np.median([(g["ci95"][1] - g["ci95"][0]) / 2 / g["value"] for g in got if g["ci95"]]))
                if any(g["ci95"] for g in got)
                else None
            ),
        }
    statuses: dict[str, int] = {}
    for r in fitted:
        key = str((r.get("optimizer") or {}).get("status"))
        statuses[key] = statuses.get(key, 0) + 1
    failed: dict[str, int] = {}
    for r in rows:
        if "failed" in r:
            failed[r["failed"][:80]] = failed.get(r["failed"][:80], 0) + 1
    return {
        "truth_model": "the simulator's ER wheel (k, c drawn), recorded as Vicon exports in drawn labs and imported",
        "fit": list(fit),
        "series": len(rows),
        "fitted": len(fitted),
        "converged": sum(bool(r.get("converged")) for r in fitted),
        "parameters": per,
        "optimizer_status": statuses,
        "failed": failed,
        "imports": {
            "trials": sum(r["trials"] for r in rows),
            "refused": sum(len(r["refused"]) for r in rows),
        },
        "trials_per_series": trials,
        "steps": steps,
        "seed": seed,
        "cpu_s": cpu_s,
        "wall_s": wall_s,
        "per_series": rows,
    }
