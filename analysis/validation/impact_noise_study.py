"""The impact times' noise the adequacy check estimates, against the importer's actual impact-time error.

Each series draws an ER wheel away from Table 1 (k, c as `calibrate_coverage`; frictionless), walks it
(`floquet_truth.er_walk`) on ``trials`` slopes of 2-3.5 deg, ``steps`` impacts each, writes each walk as a Vicon
export in a drawn lab whose marker set is chosen (``markers``: a Tracker object or four markers;
`critical_truth.record`, 0.3 mm and 1 mrad of noise, 100 Hz), imports it (`import_trial`, defaults) and compares:

- the truth's scatter: each imported impact minus the true impact nearest it (s), less the trial's mean (a
  constant offset is the calibration's time shift, not noise), pooled over the series (rms with the trial's mean
  counted as a fitted degree of freedom);
- `adequacy.timing_noise_sd` on the imported impact times (what the check compares the periods with);
- the angle's noise over the angular speed at each impact (`steps.noise_sigma` of the imported wheel angle over
  the impact's mean speed, its two periods' mean): the placement's error when the importer puts the impact where
  the wheel reaches its phase, a figure from the recording apart from the periods (reported, not used).

`python -m rimless.analysis.validation.impact_noise_study --series N --seed S [--markers]` prints one JSON
object (docs/trials.md, "The impact times' noise").
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from typing import Any

import numpy as np

__all__ = ["impact_noise_study"]

HOLD_S = 0.4  # `critical_truth.record`'s hold at the release pose before the walk, s


def impact_noise_study(n_series: int, seed: int, markers: bool, *, trials: int = 4, steps: int = 10) -> dict[str, Any]:
    """Per series the truth's pooled impact-time scatter, the adequacy check's estimate and the angle-noise figure
    (ms), and their medians over the series. Deterministic in ``seed``."""
    from dataclasses import replace
    from pathlib import Path

    from rimless.analysis.inference.adequacy import timing_noise_sd
    from rimless.analysis.kinematics.build import import_trial
    from rimless.analysis.kinematics.steps import noise_sigma
    from rimless.analysis.validation.calibrate_coverage import C_RANGE, K_RANGE
    from rimless.analysis.validation.critical_truth import record
    from rimless.analysis.validation.floquet_truth import er_walk
    from rimless.analysis.validation.importer_coverage import draw_lab
    from rimless.errors import RimlessError
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams

    rng = np.random.default_rng([seed, int(markers)])
    cpu = time.process_time()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="rimless-impact-noise-") as tmp:
        for i in range(n_series):
            truth = WheelParams(
                stiffness_n_per_m=float(rng.uniform(*K_RANGE)), damping_ns_per_m=float(rng.uniform(*C_RANGE))
            )
            lab = replace(draw_lab(rng), markers=markers)
            errs: list[np.ndarray] = []
            imported: list[np.ndarray] = []
            angle_se: list[np.ndarray] = []
            refused = 0
            for j, slope in enumerate(np.sort(rng.uniform(2.0, 3.5, trials))):
                try:
                    wk = er_walk(truth, float(slope), 0.0, steps, rng, release=float(rng.uniform(0.95, 1.08)))
                except StepFailure:
                    refused += 1
                    continue
                path = Path(record(wk, Path(tmp) / f"s{i}t{j}.csv", rng, lab, rest_s=0.0))
                try:
                    tr = import_trial(path)
                except RimlessError:
                    refused += 1
                    continue
                imp = np.asarray(tr.impact_time_s, float)
                if imp.size < 3:
                    refused += 1
                    continue
                # the file's clock: the walk starts after `record`'s hold (0.4 s), less the first frame's offset
                # (under a frame: a constant, taken out with the trial's mean)
                true = HOLD_S + np.asarray(wk.impacts, float)
                near = true[np.argmin(np.abs(true[:, None] - imp[None, :]), axis=0)]
                e = imp - near
                errs.append(e - float(np.mean(e)))
                imported.append(imp)
                if "wheel_angle" in tr.series.data:  # the angle in the walk (its noise from third differences)
                    t_s, ang = np.asarray(tr.series.time_s, float), np.asarray(tr.series["wheel_angle"], float)
                    sig_a = noise_sigma(ang[(t_s >= imp[0]) & (t_s <= imp[-1])])
                    w = math.radians(45.0) / np.diff(imp)  # rad/s over each period
                    w_at = np.concatenate([[w[0]], 0.5 * (w[:-1] + w[1:]), [w[-1]]])
                    angle_se.append(sig_a / w_at)
            if not errs:
                rows.append({"series": i, "refused": refused})  # nothing imported
                continue
            n_e = sum(e.size for e in errs)
            scatter = math.sqrt(sum(float(e @ e) for e in errs) / max(n_e - len(errs), 1))
            est, dof = timing_noise_sd(imported)
            row: dict[str, Any] = {"series": i}
            rows.append(
                row
                | {
                    "truth": {"k_n_per_m": truth.stiffness_n_per_m, "c_ns_per_m": truth.damping_ns_per_m},
                    "lab": {"up": lab.up, "heading_deg": lab.heading_deg, "markers": lab.markers},
                    "trials": len(errs),
                    "refused": refused,
                    "truth_scatter_ms": scatter * 1e3,
                    "estimate_ms": est * 1e3 if math.isfinite(est) else None,
                    "estimate_dof": dof,
                    "angle_noise_ms": float(np.sqrt(np.mean(np.concatenate(angle_se) ** 2))) * 1e3
                    if angle_se
                    else None,
                }
            )
    done = [r for r in rows if r.get("estimate_ms") is not None]

    def med(key: str) -> float | None:
        v = [r[key] for r in done if r.get(key) is not None]
        return float(np.median(v)) if v else None

    ratio = [r["estimate_ms"] / r["truth_scatter_ms"] for r in done if r["truth_scatter_ms"] > 0]
    return {
        "markers": markers,
        "series": n_series,
        "seed": seed,
        "trials_per_series": trials,
        "steps": steps,
        "median_truth_scatter_ms": med("truth_scatter_ms"),
        "median_estimate_ms": med("estimate_ms"),
        "median_angle_noise_ms": med("angle_noise_ms"),
        "estimate_over_truth": {
            "median": float(np.median(ratio)) if ratio else None,
            "min": float(np.min(ratio)) if ratio else None,
            "max": float(np.max(ratio)) if ratio else None,
        },
        "cpu_s": time.process_time() - cpu,
        "per_series": rows,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--series", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--markers", action="store_true", help="four markers (default: a Tracker object)")
    a = ap.parse_args(argv)
    if a.series < 1:
        print("error: --series takes 1 or more", file=sys.stderr)
        return 2
    print(json.dumps(impact_noise_study(a.series, a.seed, a.markers), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
