"""Benchmark of `rimless.analysis.inference.calibrate.calibrate`: ``python -m rimless.analysis.bench.calibrate``.

Generates sustained trials of a known ER wheel (default c = 12 N s/m, k = 2200 N/m; Table 1 has 8 and 2500) with
the compiled simulator (CoM height with 0.3 mm noise at 100 Hz, impact times with 0.5 ms noise), then fits
``--fit`` (default c,k) twice in one run, with the same estimator and stopping rules: the reference inner loops
(`rimless.analysis.bench.calibrate_reference`, the previous algorithm frozen: every column of `simulate_steps` recorded in Python, a grid search for each release of the
coarse profile, the full shift grid, bisection, a cubic spline per simulated step, the least squares started at
the coarse profile's best point, the BLAS on all threads) and the fast ones (only the CoM height and its rate
recorded, on whole arrays, and interpolated by cubic Hermite; the profile's releases warm-started from the
nearest point tried; the start refined between the profile's points, with the sigmas and bounds of the coarse
start; one BLAS thread for the SVDs of the least squares), both with the reference's rule for a second start
(from Table 1 only on a ridge or without convergence: ``multi_start="ridge"``; the method's default multistart
and its adequacy and model-choice checks are not part of the comparison, the adequacy figures are computed but
cost one evaluation). ``--series demo`` runs the calibration of `rimless demo` instead (the bundled critical
series, c). Prints, for each, the wall and CPU time, the simulations, whether it converged, each
parameter's estimate, 1-sigma, error and whether its 95 % interval covers the truth; then the ratio of the times
(from CPU time, the wall ratio beside) and the difference of the estimates and interval bounds between the two (in units of the reference's sigma).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from rimless.sim.model.params import WheelParams

SLOPES_DEG = (1.8, 2.2, 2.6, 3.0)
RELEASES_RAD_S = (1.9, 2.4)


def make_trials(truth: WheelParams, rng: np.random.Generator, n_steps: int = 9) -> list[SimpleNamespace]:
    """Trial-like objects of the ER wheel ``truth`` on `SLOPES_DEG` x `RELEASES_RAD_S`: the recording starts
    inside the release step; heights from the impact line."""
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.gait import simulate_steps

    out = []
    for slope in SLOPES_DEG:
        for release in RELEASES_RAD_S:
            p = truth.replace(slope_rad=math.radians(slope))
            g = simulate_steps(
                p, "er", np.array([-math.pi / 8, release]), n_steps, make_integrator("auto", rtol=1e-9), record_dt=1e-3
            )
            ts, order = np.unique(np.asarray(g.table["t_s"]), return_index=True)
            com = np.asarray(g.table["com_height_normal_m"])[order]
            periods = np.array([s.period_s for s in g.steps])
            impacts = np.cumsum(periods)
            t = np.arange(0.5 * periods[0], impacts[-1] + 0.3 * periods[-1], 0.01)
            t = t[t <= ts[-1]]
            y = np.interp(t, ts, com) + rng.normal(0.0, 0.3e-3, t.size) - 0.2
            imp = impacts[:-1] + rng.normal(0.0, 0.5e-3, impacts.size - 1)
            gap = np.zeros(t.size, bool)
            meta = SimpleNamespace(
                slope_deg=slope,
                source_file=f"er_{slope}deg_{release}",
                rate_hz=100.0,
                slope_source="given",
                com_height_reference="impact line",
                step_refused=None,
            )
            out.append(
                SimpleNamespace(
                    time_s=t,
                    impact_time_s=imp,
                    step_period_s=np.diff(imp),
                    meta=meta,
                    series={"com_height": y, "gap": gap, "interpolated": gap},
                )
            )
    return out


def demo_trials() -> tuple[list[Any], list[str]]:
    """The bundled critical series imported as `rimless demo` imports it (the trials with steps), with names."""
    from pathlib import Path

    from rimless.analysis.kinematics.build import DEFAULT_MAX_GAP_S
    from rimless.analysis.kinematics.inputs import load_input

    # the files of `rimless.analysis.examples.critical_series.data_files` (a higher layer: not imported here)
    folder = Path(__file__).resolve().parents[1] / "data" / "critical"
    trials, names = [], []
    for f in sorted(folder.glob("SYNTHETIC_crit_*.csv")):
        row = load_input(f, {"max_gap_s": DEFAULT_MAX_GAP_S})
        if row.trial is not None and row.trial.step_period_s.size:
            trials.append(row.trial)
            names.append(row.file)
    return trials, names


def main(argv: list[str] | None = None) -> None:
    from rimless.analysis.bench.calibrate_reference import calibrate_reference
    from rimless.analysis.inference.calibrate import NoTrialCalibrated, calibrate, parse_fit
    from rimless.sim.model.params import WheelParams

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--c", type=float, default=12.0)
    ap.add_argument("--k", type=float, default=2200.0)
    ap.add_argument("--fit", default="c,k")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--only", choices=("reference", "fast", "both"), default="both")
    ap.add_argument(
        "--series",
        choices=("generated", "demo"),
        default="generated",
        help="generated: trials of the known wheel (--c, --k); demo: the bundled critical series, "
        "imported as `rimless demo` does (its calibration; --fit defaults to c, no truth)",
    )
    a = ap.parse_args(argv)
    wheel = WheelParams(damping_ns_per_m=a.c, stiffness_n_per_m=a.k)
    truth = None if a.series == "demo" else wheel  # the wheel that made the trials (none: the demo's)
    if a.series == "demo":
        trials, names = demo_trials()
        if a.fit == "c,k":
            a.fit = "c"
    else:
        trials = make_trials(wheel, np.random.default_rng(a.seed))
        names = [t.meta.source_file for t in trials]
    fit = parse_fit(a.fit)
    for t, n in zip(trials, names):  # warm the compiled code on the first trial that can be calibrated
        try:
            calibrate([t], [n], ["c"], max_rounds=1, multi_start=False)
            break
        except NoTrialCalibrated:
            continue
    results, times = {}, {}
    for label in ("reference", "fast"):
        if a.only not in (label, "both"):
            continue
        t0, c0 = time.perf_counter(), time.process_time()
        if label == "reference":
            res = calibrate_reference(trials, names, fit)
        else:  # the reference's starts (Table 1 again only on a ridge), not the method's default multistart
            res = calibrate(trials, names, fit, multi_start="ridge")
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        results[label], times[label] = res, (dt, dc)
        print(
            f"{label}: {dt:.1f} s wall, {dc:.1f} s CPU, {res.evaluations} simulations, converged {res.converged} "
            f"({res.optimizer.get('message', '')}; {res.optimizer.get('starts')} start(s), "
            f"{res.optimizer.get('rounds')} round(s))"
        )
        for p in res.params:
            lo, hi = p.ci95
            head = f"  {p.name}: {p.value:.6g} +- {p.se:.3g} (model {p.se_model:.2g}, sandwich {p.se_sandwich:.2g})"
            if truth is None:
                print(
                    f"{head}, 95 % interval [{lo:.6g}, {hi:.6g}]; identifiable {p.identifiable}"
                    f"{' (effective only)' if p.effective_only else ''}"
                )
                continue
            true = float(getattr(truth, p.field))
            print(
                f"{head} truth {true:g}: error {100 * (p.value - true) / true:+.3f} %, 95 % interval [{lo:.6g}, "
                f"{hi:.6g}] {'covers' if lo <= true <= hi else 'MISSES'} it; identifiable {p.identifiable}"
            )
    if len(results) == 2:
        ref, new = results["reference"], results["fast"]
        (tw, tc), (nw, nc) = times["reference"], times["fast"]
        print(
            f"ratio reference/fast: {tc / nc:.2f}x CPU time of the process ({tw / nw:.2f}x wall; load average "
            f"{os.getloadavg()[0]:.1f})"
        )
        for pr, pn in zip(ref.params, new.params):
            (rlo, rhi), (nlo, nhi) = pr.ci95, pn.ci95
            print(
                f"  {pr.name}: estimate differs by {pn.value - pr.value:+.3g} {pr.unit} "
                f"({(pn.value - pr.value) / pr.se:+.3f} sigma), interval bounds by {nlo - rlo:+.3g} / {nhi - rhi:+.3g} "
                f"{pr.unit}, sigma by {100 * (pn.se - pr.se) / pr.se:+.2f} %; identifiable {pr.identifiable} / "
                f"{pn.identifiable}"
            )
        dw = max(abs(new.release_rad_s[k] - ref.release_rad_s[k]) for k in ref.release_rad_s)
        sep = (new.loss_separation or {}).get("damping_identified")
        print(
            f"  releases differ by at most {dw:.2g} rad/s; calibrated cost {ref.cost_calibrated:.6g} / "
            f"{new.cost_calibrated:.6g}; c told from a constant loss (the method's check; the reference has "
            f"none): {sep}"
        )


if __name__ == "__main__":
    main()
