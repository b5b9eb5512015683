"""The size and the cost of the comparison's first-angle offset rule against independent truths (issue 31).

Run from the repository root (not collected by pytest; about 0.5 s of CPU a walk):

    PYTHONPATH=. python tests/analysis/inference/first_angle_study.py --truth uncompressed --draws 30 --seed 7

``--first-impact phase`` measures with the importer as it was before session 21 (every impact at the gait's phase,
the first one too); the default places the first impact at its own touchdown (`steps._first_touchdown`).

``--truth uncompressed``: the tests' compliant truth (`tests.support.analysis_trial_truth`, apart from the comparison's
code) held on uncompressed legs at -alpha/2 and released at 1.8-2.8 rad/s: the comparison's own rigid release, true
offset 0; ``static``: held standing on its compressed trailing leg; ``er_walk``: `floquet_truth.er_walk` released into
its gait at 0.95-1.08 times its speed (a true offset), recorded in a drawn lab (`critical_truth.record`). c 2-20 N s/m,
k 1500-4000 N/m, slopes 1.5-3 deg (er_walk 2-3.5), 10 steps (er_walk 9), imported; the comparison is given the true
slope and wheel. Prints per walk the test (`compare.first_angle_test`, weighted by the importer's per-impact sds as
`compare_trial` runs it; ``--unweighted``: without them; the summary also gives the unweighted test's counts on the
same walks) and the later periods' rms error against the
truth's own when simulated with the rule, with the offset always, with the rigid release matched to the first period,
and with the rigid release fitted on all periods; then how often p fell below 0.01, 0.05, 0.1 and each rms over the
walks. ``--save FILE.npz`` also writes each tested walk's measured and true periods (s, NaN-padded), slope (deg),
k (N/m), c (N s/m) and the rigid release's speed (rad/s), so that other tests of the same walks need no re-import.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
from pathlib import Path

import numpy as np

from rimless.analysis.inference import compare
from rimless.analysis.inference.compare import Simulator, first_angle_test, fit_release_speed
from rimless.analysis.inference.release import map_frequencies
from rimless.analysis.kinematics.build import TrialRefused, import_trial
from rimless.sim.model.params import WheelParams


def _walk(truth: str, i: int, seed: int, folder: Path):
    """(imported trial, true periods s, slope deg, WheelParams) of draw i, or None."""
    from rimless.sim.model.failures import StepFailure

    if truth == "er_walk":
        from rimless.analysis.validation.critical_truth import record
        from rimless.analysis.validation.floquet_truth import er_walk
        from rimless.analysis.validation.importer_coverage import draw_lab

        rng = np.random.default_rng(seed + i)
        k, c, s = rng.uniform(1500, 4000), rng.uniform(2, 20), rng.uniform(2.0, 3.5)
        p = WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c)
        try:
            wk = er_walk(p, s, 0.0, 9, rng, release=float(rng.uniform(0.95, 1.08)))
            tr = import_trial(record(wk, folder / f"t{i}.csv", rng, draw_lab(rng), rest_s=0.0))
        except (StepFailure, TrialRefused):
            return None
        return tr, np.diff(wk.impacts), s, p
    from tests.support import analysis_trial_truth as truth_model

    rng = np.random.default_rng(seed)
    for _ in range(i + 1):  # the draws in order, as the sizes in docs/trials.md were measured
        c, k = rng.uniform(2, 20), rng.uniform(1500, 4000)
        s, w, yaw = rng.uniform(1.5, 3.0), rng.uniform(1.8, 2.8), rng.uniform(0, 360)
    tr = truth_model.simulate_wheel(
        s, w, c_ns_per_m=c, k_n_per_m=k, max_steps=10, ending="caught", seed=seed * 1000 + i, yaw_deg=yaw,
        release_leg=truth,
    )  # fmt: skip
    if tr.steps < 5:
        return None
    try:
        trial = import_trial(truth_model.write_csv(folder / f"t{i}.csv", tr))
    except TrialRefused:
        return None
    return trial, np.diff(tr.impact_time_s), s, WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c)


def no_offset_cases(folder: Path, n: int = 20, seed: int = 7):
    """The first ``n`` walks of the tests' truth released from uncompressed legs (no first-angle offset), imported
    and told their slope: (trial, its periods (s), slope (deg), a Simulator of the truth's wheel, the rigid
    release's speed fitted on the first period (rad/s)) for each walk that imports (the size tests' draws)."""
    for i in range(n):
        got = _walk("uncompressed", i, seed, folder)
        if got is None:
            continue
        trial, _, slope, params = got
        per = np.asarray(trial.step_period_s, float)
        trial = dataclasses.replace(trial, meta=dataclasses.replace(trial.meta, slope_deg=slope))
        sim = Simulator(model="er", params=params)
        w0, _ = fit_release_speed(sim, slope, float(per[0]))
        assert w0 is not None
        yield trial, per, slope, sim, w0


def _later_rms_ms(sim: Simulator, slope: float, w: float, offset: float, true_p: np.ndarray) -> float:
    """The rms over periods 2.. of the simulated (release speed ``w``, first-angle ``offset``) minus ``true_p``, ms."""
    n = true_p.size
    f = map_frequencies(sim.on_slope(slope), "er", w, n, offset, sim.rtol)
    sim_p = np.where(f > 0, 1.0 / np.where(f > 0, f, 1.0), np.nan)
    return float(np.sqrt(np.nanmean((sim_p[1:] - true_p[1:]) ** 2))) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--truth", choices=["uncompressed", "static", "er_walk"], default="uncompressed")
    ap.add_argument("--draws", type=int, default=30)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument(
        "--first-impact",
        choices=["touchdown", "phase"],
        default="touchdown",
        help="the importer's first impact: at its own touchdown (now) or at the gait's phase (before session 21)",
    )
    ap.add_argument(
        "--unweighted",
        action="store_true",
        help="the test without the importer's per-impact sds (as before session 23); default: weighted by them",
    )
    ap.add_argument("--save", type=Path, help="write each tested walk's periods, truth and wheel to this .npz")
    args = ap.parse_args()
    if args.first_impact == "phase":
        from rimless.analysis.kinematics import steps

        steps._first_touchdown = lambda *a: (a[-1], 0.0, math.nan)  # the impacts as the importer placed them before
    ps: list[float] = []
    p_plain: list[float] = []  # the unweighted test's p on the same walks
    weighted = 0
    saved: dict[str, list] = {
        "measured_s": [],
        "true_s": [],
        "slope_deg": [],
        "k_n_per_m": [],
        "c_ns_per_m": [],
        "w0": [],
    }
    rms: dict[str, list[float]] = {"rule": [], "always": [], "rigid, first period": [], "rigid, all periods": []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.draws):
            got = _walk(args.truth, i, args.seed, Path(tmp))
            if got is None:
                continue
            trial, true_p, slope, params = got
            per = np.asarray(trial.step_period_s, float)
            if per.size < 3 or not np.all(np.isfinite(per)):
                continue
            trial = dataclasses.replace(trial, meta=dataclasses.replace(trial.meta, slope_deg=slope))
            sim = Simulator(model="er", params=params)
            w0, _ = fit_release_speed(sim, slope, float(per[0]))
            if w0 is None:
                continue
            sd = None if args.unweighted else compare._consecutive_impact_sd(trial)
            test = first_angle_test(sim, slope, per, w0, sd)
            if not math.isfinite(test.p):
                continue
            ps.append(test.p)
            if sd is not None and test.weighted:
                plain = first_angle_test(sim, slope, per, w0)  # main's test on the same walk
                p_plain.append(plain.p)
                weighted += 1
            else:
                p_plain.append(test.p)
            for key, v in zip(
                saved, (per, true_p[: per.size], slope, params.stiffness_n_per_m, params.damping_ns_per_m, w0)
            ):
                saved[key].append(v)
            level, compare.FIRST_ANGLE_P = compare.FIRST_ANGLE_P, 1.1  # kept whenever the cost falls
            always = first_angle_test(sim, slope, per, w0, sd)
            compare.FIRST_ANGLE_P = level
            for name, (offset, w) in {
                "rule": (test.offset_rad, test.release_theta_dot_rad_s),
                "always": (always.offset_rad, always.release_theta_dot_rad_s),
                "rigid, first period": (0.0, w0),
                "rigid, all periods": (0.0, test.rigid_fit_theta_dot_rad_s),
            }.items():
                rms[name].append(_later_rms_ms(sim, slope, w, offset, true_p[: per.size]))
            print(
                f"{i:3d} p {test.p:.4f} {test.test} {test.statistic:.2f} kept {test.kept}"
                + (f" (unweighted p {p_plain[-1]:.4f})" if sd is not None and test.weighted else "")
                + "; later periods rms (ms) "
                + ", ".join(f"{k} {v[-1]:.3f}" for k, v in rms.items()),
                flush=True,
            )
    if args.save:
        n = max((x.size for x in saved["measured_s"]), default=0)
        pad = {
            k: np.array([np.pad(x, (0, n - x.size), constant_values=np.nan) for x in saved[k]])
            for k in ("measured_s", "true_s")
        }
        np.savez(args.save, **{**{k: np.array(v) for k, v in saved.items() if k not in pad}, **pad})
    p = np.array(ps)
    print(
        f"{args.truth}: {p.size} tested; p < 0.01 {(p < 0.01).sum()}, < 0.05 {(p < 0.05).sum()}, < 0.1 {(p < 0.1).sum()}"
    )
    if p_plain:
        q = np.array(p_plain)
        print(
            f"  weighted by the per-impact sds on {weighted} of them; the unweighted test on all {q.size}: "
            f"p < 0.01 {(q < 0.01).sum()}, < 0.05 {(q < 0.05).sum()}, < 0.1 {(q < 0.1).sum()}"
        )
    for name, v in rms.items():
        print(f"  later periods, {name}: rms over the walks {math.sqrt(np.mean(np.square(v))):.3f} ms")


if __name__ == "__main__":
    main()
