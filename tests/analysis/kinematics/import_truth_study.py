"""The import's slope interval coverage and impact-time errors against the independent truths (issue 31).

Run from the repository root (not collected by pytest; minutes of CPU):

    PYTHONPATH=. python tests/analysis/kinematics/import_truth_study.py slope --draws 40 --seed 5 [--wheel-given]
        [--release-leg uncompressed]
    PYTHONPATH=. python tests/analysis/kinematics/import_truth_study.py impacts --draws 24

``slope``: marker-only walks of the compliant ER truth (`tests.support.analysis_trial_truth`) with c 2-20 N s/m,
k 1500-4000 N/m, slope 1.2-2.5 deg, release 2-3 rad/s, any heading, Y-up or Z-up lab, even or uneven 4-marker
sets, 60 % of them with the middle of most stances occluded (two kept); prints each draw and how often the 95 %
interval held the truth, and the rms of (estimate - truth) / (half width / 1.96). ``--release-leg uncompressed``:
the truth held on uncompressed legs before its release, as it was until session 18 (`analysis_trial_truth.RELEASE_LEG`). ``impacts``: the rigid truth (`rigid_walk`, 3-6 deg) and the ER truth (1.7-2.6 deg),
8 steps each, recorded as Tracker objects; prints the impact-time errors (ms) against the truth's own times.
"""

from __future__ import annotations

import argparse
import math
import re
import tempfile
from pathlib import Path

import numpy as np

from rimless.analysis.kinematics.build import TrialRefused, import_trial
from tests.support import analysis_trial_truth as truth
from tests.support.analysis_truth_wheel import EVEN_MARKERS, UNEVEN_MARKERS


def slope_study(draws: int, seed: int, folder: Path, wheel_given: bool = False, release_leg: str = "static") -> None:
    """``wheel_given``: each import is told the wheel (its c and k, k with Table 1's stated 10 %), as a user who
    knows it would (`import_trial(wheel=...)`); else the importer bounds the legs' drift."""
    from rimless.sim import Wheel

    rng = np.random.default_rng(seed)
    covered = within = n = 0
    z2: list[float] = []
    for i in range(draws):
        c, k = rng.uniform(2, 20), rng.uniform(1500, 4000)
        s, w, yaw = rng.uniform(1.2, 2.5), rng.uniform(2.0, 3.0), rng.uniform(0, 360)
        kw = dict(
            c_ns_per_m=c, k_n_per_m=k, max_steps=11, ending="walked", seed=i, yaw_deg=yaw, release_leg=release_leg
        )
        tr = truth.simulate_wheel(s, w, **kw)
        gaps: tuple = ()
        if rng.random() < 0.6 and tr.impact_time_s.size > 1:
            keep = tuple(int(j) for j in rng.choice(tr.impact_time_s.size, size=2, replace=False))
            gaps = truth.mid_stance_gaps(tr, keep, 2 * rng.uniform(0.1, 0.3))
            tr = truth.simulate_wheel(s, w, gaps=gaps, **kw)
        y_up = rng.random() < 0.5
        lab = truth.in_lab(tr, truth.Y_UP_FROM_Z_UP) if y_up else tr
        body = UNEVEN_MARKERS if i % 2 else EVEN_MARKERS
        try:
            wheel = Wheel(stiffness_n_per_m=k, damping_ns_per_m=c) if wheel_given else None
            m = import_trial(truth.write_markers_csv(folder / "m.csv", lab, body, seed=i), wheel=wheel).meta
        except TrialRefused as err:
            print(i, "refused", str(err)[:120])
            continue
        lo, hi = (math.degrees(v) for v in m.slope_ci_rad)
        hit = lo <= s <= hi
        near = abs(m.slope_deg - s) <= 0.1
        z2.append(((m.slope_deg - s) / max((hi - lo) / 2 / 1.959964, 1e-12)) ** 2)
        n += 1
        covered += hit
        within += hit or near
        how = re.sub(r"\s+", " ", m.slope_method)[:70]
        print(
            f"{i:3d} c {c:5.1f} k {k:5.0f} truth {s:.3f} gaps {len(gaps)} {'Y' if y_up else 'Z'}-up steps "
            f"{tr.steps:2d}: {m.slope_deg:.3f} [{lo:.3f}, {hi:.3f}] {'ok' if hit else 'near' if near else 'MISS'} "
            f"({how})",
            flush=True,
        )
    rms = math.sqrt(sum(z2) / len(z2)) if z2 else float("nan")
    print(f"coverage {covered}/{n}; within 0.1 deg or covered {within}/{n}; rms z {rms:.3f}")


def _errors_ms(tr, path: Path) -> np.ndarray:
    t = import_trial(truth.write_csv(path, tr))
    got = t.impact_time_s + tr.time_s[0]  # the recording's time 0 is its first frame
    if got.size == 0:
        return np.zeros(0)
    e = got[:, None] - tr.impact_time_s[None]
    return 1e3 * e[np.arange(got.size), np.argmin(np.abs(e), axis=1)]


def impact_study(draws: int, seed: int, folder: Path) -> None:
    rng = np.random.default_rng(seed)
    errs: dict[str, list[float]] = {"rigid": [], "er": []}
    for i in range(draws):
        rigid = truth.rigid_walk(rng.uniform(3.0, 6.0), rng.uniform(1.0, 2.5), seed=i, ramp_steps=8)
        er = truth.simulate(rng.uniform(1.7, 2.6), rng.uniform(2.0, 2.8), max_steps=8, ending="walked", seed=i)
        for name, tr in (("rigid", rigid), ("er", er)):
            e = _errors_ms(tr, folder / f"{name}.csv")
            errs[name] += e.tolist()
            print(name, i, f"{tr.slope_deg:.2f} deg", tr.steps, "impacts, errors ms", np.round(e, 1), flush=True)
    for name, v in errs.items():
        a = np.asarray(v)
        if a.size:
            print(
                f"{name}: {a.size} impacts, median {np.median(a):+.2f} ms, median |error| {np.median(np.abs(a)):.2f} ms, "
                f"range {a.min():+.2f} to {a.max():+.2f} ms"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", choices=["slope", "impacts"])
    ap.add_argument("--draws", type=int, default=40)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--wheel-given", action="store_true", help="slope: tell the importer the wheel's c and k")
    ap.add_argument(
        "--release-leg",
        choices=["static", "uncompressed"],
        default="static",
        help="slope: the truth stands on its legs before the release (static) or is held on uncompressed legs",
    )
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if a.study == "slope":
            slope_study(a.draws, a.seed, Path(tmp), a.wheel_given, a.release_leg)
        else:
            impact_study(a.draws, a.seed, Path(tmp))


if __name__ == "__main__":
    main()
