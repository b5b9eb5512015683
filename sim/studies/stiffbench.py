"""Benchmark of near-massless legs: the compiled Rosenbrock single support (rimless.sim.fast.stiff) against
the compiled explicit DOP853 it replaces there, side by side in one run.

The wheel is the one a user describing a rigid-legged wheel writes (`light_wheel`, as
rimless.analysis.validation.critical_truth's `LossyWheel().wheel_params()`: legs of 0.1 g, Table 1's k and c, M = 2.6 kg, I_hub = 0.05 kg m^2,
L = 0.21 m) on a 4 deg slope, ER model, released at theta = -alpha/2 with theta' = 2 rad/s. For each tolerance
rtol (atol = rtol / 100) it walks `n_steps` steps (rimless.sim.step.gait.simulate_steps, no record) with the
FastIntegrator twice: single support by Rosenbrock (`stiff_legs=True`, the default) and by DOP853
(`stiff_legs=False`, what every phase used before). Errors are against DOP853 at rtol 1e-12 (atol 1e-14):
the largest step-period error (s) and the largest error of the post-impact section z = (theta+, theta'+)
(rad, rad/s) over the walk. The compiled step map (`fast_step`, as the trial comparison's scans use it) is
timed on the same steps, its error (largest of period s and z) against the same reference, step by step. Times are CPU time of this thread (time.thread_time), median of `repeats`; every
ratio printed comes from them. Right-hand-side evaluations are counted by the integrators.

Run: ``python -m rimless.sim.studies.stiffbench`` (some 20 s on a loaded 2-core machine, after compiling).
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

import numpy as np

RELEASE_Z = np.array([-math.pi / 8, 2.0])  # theta (rad), theta' (rad/s): the rigid release on two feet
SLOPE_DEG = 4.0
REFERENCE_RTOL = 1e-12


def light_wheel() -> Any:
    """The 0.1 g-leg wheel of the benchmark (WheelParams, slope SLOPE_DEG): what
    rimless.analysis.validation.critical_truth.LossyWheel().wheel_params() writes for its default rigid wheel
    (M = 2.6 kg, I_hub = 0.05 kg m^2, L = 0.21 m; m = 0.1 g, M = m_H + 8 m, I_hub = I_c + 8 m L^2)."""
    from rimless.sim.model.params import WheelParams

    m, mass, inertia, leg = 1e-4, 2.6, 0.05, 0.21
    return WheelParams(
        hub_mass_kg=mass - 8 * m,
        leg_mass_kg=m,
        inertia_kg_m2=inertia - 8 * m * leg**2,
        leg_length_m=leg,
        slope_rad=math.radians(SLOPE_DEG),
    )


def _walk(params: Any, rtol: float, stiff_legs: bool, n_steps: int) -> tuple[Any, int]:
    from rimless.sim.fast import FastIntegrator
    from rimless.sim.step.gait import simulate_steps

    integ = FastIntegrator(rtol=rtol, atol=rtol * 1e-2, stiff_legs=stiff_legs)
    walk = simulate_steps(params, "er", RELEASE_Z, n_steps, integ)
    return walk, sum(int(s.nfev) for s in walk.steps)


def _cpu(fn: Any, repeats: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.thread_time()
        out = fn()
        times.append(time.thread_time() - t0)
    return float(np.median(times)), out


def _errors(walk: Any, ref: Any) -> tuple[float, float]:
    n = min(len(walk.steps), len(ref.steps))
    dp = max(abs(walk.steps[i].period_s - ref.steps[i].period_s) for i in range(n))
    dz = max(float(np.max(np.abs(walk.steps[i].y_plus[[2, 7]] - ref.steps[i].y_plus[[2, 7]]))) for i in range(n))
    return dp, dz


def stiff_bench(rtols: tuple[float, ...] = (1e-8, 1e-10), n_steps: int = 4, repeats: int = 3) -> dict[str, Any]:
    """Rows per rtol: CPU time (s) and evaluations of the walk on each integrator, their ratio, the errors."""
    from rimless.sim.fast import fast_step, stiff

    params = light_wheel()
    load = os.getloadavg()[0]
    _walk(params, 1e-8, True, 1)  # compile (or load) both paths before timing
    _walk(params, 1e-8, False, 1)
    fast_step(params, "er", RELEASE_Z, rtol=1e-8)
    ref, _ = _walk(params, REFERENCE_RTOL, False, n_steps)
    rows = []
    for rtol in rtols:
        t_new, (walk_new, nfev_new) = _cpu(lambda r=rtol: _walk(params, r, True, n_steps), repeats)
        t_old, (walk_old, nfev_old) = _cpu(lambda r=rtol: _walk(params, r, False, n_steps), repeats)

        def maps(r: float = rtol) -> tuple[float, int]:
            z, nfev, err = RELEASE_Z, 0, 0.0
            for ref_step in ref.steps:
                step = fast_step(params, "er", z, rtol=r)
                z, nfev = step.z_next, nfev + step.nfev
                err = max(err, abs(step.period_s - ref_step.period_s), *np.abs(z - ref_step.y_plus[[2, 7]]))
            return err, nfev

        t_map, (err_map, nfev_map) = _cpu(maps, repeats)
        rows.append(
            {
                "rtol": rtol,
                "rosenbrock_cpu_s": t_new,
                "dop853_cpu_s": t_old,
                "cpu_ratio": t_old / t_new,
                "rosenbrock_nfev": nfev_new,
                "dop853_nfev": nfev_old,
                "rosenbrock_errors": _errors(walk_new, ref),
                "dop853_errors": _errors(walk_old, ref),
                "map_cpu_s": t_map,
                "map_nfev": nfev_map,
                "map_error": err_map,
            }
        )
    return {
        "params": params,
        "leg_rate_per_s": float(stiff.leg_rate(np.array(params.as_vector()))),
        "n_steps": n_steps,
        "load_before": load,
        "load_after": os.getloadavg()[0],
        "rows": rows,
    }


def format_table(out: dict[str, Any]) -> str:
    p = out["params"]
    lines = [
        f"ER walk of {out['n_steps']} steps, legs {p.leg_mass_kg * 1e3:g} g (k {p.stiffness_n_per_m:g} N/m, "
        f"c {p.damping_ns_per_m:g} N s/m: fastest leg root {out['leg_rate_per_s']:.3g} 1/s), slope {SLOPE_DEG:g} deg,"
        f" release z = ({RELEASE_Z[0]:.4f} rad, {RELEASE_Z[1]:g} rad/s); errors against DOP853 at rtol {REFERENCE_RTOL:g}",
        f"{'rtol':>7} {'Rosenbrock s':>12} {'DOP853 s':>9} {'ratio':>6} {'nfev R':>8} {'nfev D':>8} "
        f"{'period err R':>12} {'period err D':>12} {'z err R':>9} {'z err D':>9} {'map s':>7} {'map nfev':>8} {'map err':>8}",
    ]
    for r in out["rows"]:
        (pr, zr), (pd, zd) = r["rosenbrock_errors"], r["dop853_errors"]
        lines.append(
            f"{r['rtol']:7.0e} {r['rosenbrock_cpu_s']:12.4f} {r['dop853_cpu_s']:9.4f} {r['cpu_ratio']:6.1f} "
            f"{r['rosenbrock_nfev']:8d} {r['dop853_nfev']:8d} {pr:12.2e} {pd:12.2e} {zr:9.2e} {zd:9.2e} "
            f"{r['map_cpu_s']:7.4f} {r['map_nfev']:8d} {r['map_error']:8.1e}"
        )
    lines.append(
        f"CPU time of this thread, median of repeats; load average {out['load_before']:.1f} before, "
        f"{out['load_after']:.1f} after"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    print(format_table(stiff_bench()))
