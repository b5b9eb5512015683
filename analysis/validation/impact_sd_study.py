"""The importer's per-impact time sd (``impact_sd_ms``) against its actual impact-time error on truth walks.

Each walk draws an ER wheel away from Table 1 (k, c as `calibrate_coverage`; frictionless) and a slope of 2-3.5 deg,
walks it (`floquet_truth.er_walk`, released at 0.95-1.08 times its gait's speed, ``steps`` impacts), writes it as
a Vicon export in a drawn lab (Y-up or Z-up, any heading; ``markers``: four markers, else a Tracker object;
`critical_truth.record`, ``noise_mm`` of marker noise, 1 mrad of object angle noise, 100 Hz), imports it
(`import_trial`, defaults) and sets each imported impact against the truth's (the walk's impact times in the
file's clock: `record`'s hold, less its first frame's offset, read from the same draw).

The sd is of each impact's own error, apart from a shift common to the trial's impacts (the phase the importer
takes from all of them: it moves no period), so the common shift is taken out: the mean of the later impacts'
errors weighted by their inverse variance. Per impact position (the first impact, the second, ..., the last) the
rms of z = (error - common shift) / sd, with the later impacts' z scaled by sqrt(n / (n - 1)) for the fitted
shift and the first impact's by the shift's own variance added to its sd's; goal 0.8-1.25 at each position.

`python -m rimless.analysis.validation.impact_sd_study --walks N --seed S [--markers] [--noise-mm MM]` prints one
JSON object (docs/trials.md, "Each impact's time sd").
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import tempfile
import time
from typing import Any

import numpy as np

__all__ = ["impact_sd_study", "impact_z"]

HOLD_S = 0.4  # `critical_truth.record`'s hold at the release pose before the walk, s


def impact_z(error_s: np.ndarray, sd_s: np.ndarray) -> np.ndarray | None:
    """Per impact (error - common shift) / sd, the common shift the inverse-variance mean of the later impacts'
    errors (see the module doc); ``error_s`` and ``sd_s`` (s) in impact order. None when an sd is not finite or
    fewer than three impacts."""
    e, sd = np.asarray(error_s, float), np.asarray(sd_s, float)
    if e.size < 3 or not np.all(np.isfinite(sd)) or not np.all(sd > 0):
        return None
    w = 1.0 / sd[1:] ** 2
    shift = float(np.sum(w * e[1:]) / np.sum(w))
    var_shift = 1.0 / float(np.sum(w))
    z = np.empty(e.size)
    n = e.size - 1
    z[1:] = (e[1:] - shift) / sd[1:] * math.sqrt(n / (n - 1))
    z[0] = (e[0] - shift) / math.sqrt(sd[0] ** 2 + var_shift)
    return z


def impact_sd_study(
    n_walks: int, seed: int, markers: bool, *, steps: int = 10, noise_mm: float = 0.35
) -> dict[str, Any]:
    """Per impact position the rms z and the median sd (ms), over ``n_walks`` drawn walks (those imported with at
    least three impacts and every sd stated). Deterministic in ``seed``."""
    from dataclasses import replace
    from pathlib import Path

    from rimless.analysis.kinematics.build import import_trial
    from rimless.analysis.validation.calibrate_coverage import C_RANGE, K_RANGE
    from rimless.analysis.validation.critical_truth import record
    from rimless.analysis.validation.floquet_truth import er_walk
    from rimless.analysis.validation.importer_coverage import draw_lab
    from rimless.errors import RimlessError
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams

    rng = np.random.default_rng([seed, int(markers), 23])
    cpu = time.process_time()
    zs: list[np.ndarray] = []
    sds: list[np.ndarray] = []
    errs: list[np.ndarray] = []
    refused = no_sd = 0
    with tempfile.TemporaryDirectory(prefix="rimless-impact-sd-") as tmp:
        for i in range(n_walks):
            truth = WheelParams(
                stiffness_n_per_m=float(rng.uniform(*K_RANGE)), damping_ns_per_m=float(rng.uniform(*C_RANGE))
            )
            lab = replace(draw_lab(rng), markers=markers, noise_m=noise_mm * 1e-3)
            slope = float(rng.uniform(2.0, 3.5))
            try:
                wk = er_walk(truth, slope, 0.0, steps, rng, release=float(rng.uniform(0.95, 1.08)))
            except StepFailure:
                refused += 1
                continue
            offset_s = float(copy.deepcopy(rng).uniform(0, 1.0 / lab.rate_hz))  # `record`'s first draw
            path = Path(record(wk, Path(tmp) / f"w{i}.csv", rng, lab, rest_s=0.0))
            try:
                tr = import_trial(path)
            except RimlessError:
                refused += 1
                continue
            imp, sd = np.asarray(tr.impact_time_s, float), np.asarray(tr.impact_sd_s, float)
            if imp.size < 3:
                refused += 1
                continue
            true = HOLD_S - offset_s + np.asarray(wk.impacts, float)
            near = true[np.argmin(np.abs(true[:, None] - imp[None, :]), axis=0)]
            z = impact_z(imp - near, sd)
            if z is None:
                no_sd += 1
                continue
            zs.append(z)
            sds.append(sd)
            errs.append(imp - near)
    n_pos = max((z.size for z in zs), default=0)
    positions = []
    for k in range(n_pos):
        zk = np.array([z[k] for z in zs if z.size > k])
        sk = np.array([s[k] for s in sds if s.size > k])
        positions.append(
            {
                "impact": k + 1,
                "walks": int(zk.size),
                "rms_z": float(np.sqrt(np.mean(zk**2))),
                "median_sd_ms": float(np.median(sk)) * 1e3,
                "within_2_sd": float(np.mean(np.abs(zk) <= 2.0)),
            }
        )
    later = np.concatenate([z[1:] for z in zs]) if zs else np.zeros(0)
    first = np.array([z[0] for z in zs])
    return {
        "markers": markers,
        "walks": n_walks,
        "seed": seed,
        "steps": steps,
        "noise_mm": noise_mm,
        "used": len(zs),
        "refused": refused,
        "no_sd": no_sd,
        "rms_z_first": float(np.sqrt(np.mean(first**2))) if first.size else None,
        "rms_z_later": float(np.sqrt(np.mean(later**2))) if later.size else None,
        "max_abs_error_ms": float(max(np.max(np.abs(e - np.mean(e[1:]))) for e in errs)) * 1e3 if errs else None,
        "per_position": positions,
        "cpu_s": time.process_time() - cpu,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walks", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--markers", action="store_true", help="four markers (default: a Tracker object)")
    ap.add_argument("--noise-mm", type=float, default=0.35, help="marker (or object origin) noise, mm")
    ap.add_argument("--steps", type=int, default=10)
    a = ap.parse_args(argv)
    if a.walks < 1:
        print("error: --walks takes 1 or more", file=sys.stderr)
        return 2
    if not a.noise_mm >= 0:
        print("error: --noise-mm takes 0 or more", file=sys.stderr)
        return 2
    print(json.dumps(impact_sd_study(a.walks, a.seed, a.markers, steps=a.steps, noise_mm=a.noise_mm), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
