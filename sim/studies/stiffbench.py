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
timed on the same steps, its error (largest of period s and z) against the same reference, step by step; and
with its exact Jacobian (`fast_step(jacobian=True)`, "map+J": the variational equations through the Rosenbrock
single support), its Jacobian's largest difference from central differences of the map at rtol 1e-12 (dz 1e-6,
relative to the largest entry; their own error is some 1e-8 / 1e-6). Times are CPU time of this thread (time.thread_time), median of `repeats`; every
ratio printed comes from them. Right-hand-side evaluations are counted by the integrators.

With guide friction (`FRICTION_N`, 0.3 N, the audit's truth): the same wheel and walk with its stick/slip phases
(rimless.sim.integrate.friction), single support by Rosenbrock and by DOP853 side by side, errors against DOP853 at
rtol 1e-12 with the same friction, and the largest difference of the steps' friction work (J) and stuck time (s)
from the reference's; no map column (the one-call compiled map has no guide friction).

Legs of 1 mg (`ONE_MG`, m_H / m ~ 2.6e6; the same wheel otherwise): double support, whose field now comes from
the pivoted KKT solve (rimless.sim.fast.model.kkt_in_double_support), is timed on the compiled DOP853
(FastIntegrator) and on scipy's DOP853 with the reference model's Python right-hand side (LAPACK's KKT solve),
side by side at each rtol, with the errors of the lift-off time (s) and state against scipy's DOP853 at rtol
1e-12; and the compiled step map from the release (which failed in double support before), its error against the
light-leg limit line through the maps of 0.1 g and 0.01 g legs at rtol 1e-12 (the map is smooth in m: first
order), its Jacobian against central differences of the map at rtol 1e-12 (dz 1e-6). No explicit reference of the
whole step exists there: DOP853 stops with "step size too small" in single support at rtol 1e-10 and 1e-12, and
scipy's BDF on the Python right-hand side ran over 3.7 min of CPU at rtol 1e-10 without ending.

Run: ``python -m rimless.sim.studies.stiffbench`` (25 s of CPU after compiling; 2 min wall at load 7 on 2 cores).
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
FRICTION_N = 0.3  # N: the audit's independent truth (rimless.analysis.validation), F_c of the friction table


def light_wheel(friction_n: float = 0.0) -> Any:
    """The 0.1 g-leg wheel of the benchmark (WheelParams, slope SLOPE_DEG): what
    rimless.analysis.validation.critical_truth.LossyWheel().wheel_params() writes for its default rigid wheel
    (M = 2.6 kg, I_hub = 0.05 kg m^2, L = 0.21 m; m = 0.1 g, M = m_H + 8 m, I_hub = I_c + 8 m L^2)."""
    return light_wheel_of(1e-4, friction_n)


def light_wheel_of(leg_mass_kg: float, friction_n: float = 0.0) -> Any:
    """`light_wheel` with legs of leg_mass_kg (kg), M and I_hub kept, guide friction friction_n (N)."""
    from rimless.sim.model.params import WheelParams

    m, mass, inertia, leg = leg_mass_kg, 2.6, 0.05, 0.21
    return WheelParams(
        hub_mass_kg=mass - 8 * m,
        leg_mass_kg=m,
        inertia_kg_m2=inertia - 8 * m * leg**2,
        leg_length_m=leg,
        slope_rad=math.radians(SLOPE_DEG),
        guide_friction_n=friction_n,
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


def _walk_row(params: Any, rtol: float, n_steps: int, repeats: int, ref: Any) -> tuple[dict[str, Any], Any, Any]:
    """The walk columns of a row (CPU s, evaluations and errors against ref on each integrator) and the walks."""
    t_new, (walk_new, nfev_new) = _cpu(lambda: _walk(params, rtol, True, n_steps), repeats)
    t_old, (walk_old, nfev_old) = _cpu(lambda: _walk(params, rtol, False, n_steps), repeats)
    row = {
        "rtol": rtol,
        "rosenbrock_cpu_s": t_new,
        "dop853_cpu_s": t_old,
        "cpu_ratio": t_old / t_new,
        "rosenbrock_nfev": nfev_new,
        "dop853_nfev": nfev_old,
        "rosenbrock_errors": _errors(walk_new, ref),
        "dop853_errors": _errors(walk_old, ref),
    }
    return row, walk_new, walk_old


def _friction_errors(walk: Any, ref: Any) -> tuple[float, float]:
    """The largest differences of the steps' friction work (J) and stuck time (s, either leg) from ref's."""
    n = min(len(walk.steps), len(ref.steps))
    dw = max(abs(walk.steps[i].friction_work_J - ref.steps[i].friction_work_J) for i in range(n))
    ds = max(float(np.max(np.abs(np.subtract(walk.steps[i].stick_s, ref.steps[i].stick_s)))) for i in range(n))
    return dw, ds


def friction_rows(rtols: tuple[float, ...], n_steps: int, repeats: int) -> list[dict[str, Any]]:
    """Rows per rtol for the light wheel with guide friction FRICTION_N: as stiff_bench's walk columns, plus the
    friction work and stuck time differences (J, s) of each integrator from the reference."""
    params = light_wheel(FRICTION_N)
    _walk(params, 1e-8, True, 1)  # compile (or load) the friction phases on both paths before timing
    _walk(params, 1e-8, False, 1)
    ref, _ = _walk(params, REFERENCE_RTOL, False, n_steps)
    rows = []
    for rtol in rtols:
        row, walk_new, walk_old = _walk_row(params, rtol, n_steps, repeats, ref)
        rows.append(
            row
            | {
                "rosenbrock_friction_errors": _friction_errors(walk_new, ref),
                "dop853_friction_errors": _friction_errors(walk_old, ref),
                "steps": (len(walk_new.steps), len(walk_old.steps), len(ref.steps)),
                "friction_work_J": float(sum(s.friction_work_J for s in ref.steps)),
            }
        )
    return rows


ONE_MG = 1e-6  # kg: the leg mass of the double-support rows


def double_support_rows(rtols: tuple[float, ...], repeats: int) -> list[dict[str, Any]]:
    """Rows per rtol for 1 mg legs: the double-support phase from the release on the compiled DOP853 and on scipy's
    DOP853 with the reference model (CPU s, evaluations, their ratio, each one's largest error of the lift-off
    time s and state against scipy's DOP853 at rtol 1e-12); the compiled map from the release (CPU s a step,
    evaluations, error against the light-leg limit line, s and rad or rad/s) and with its Jacobian (CPU s, its
    largest difference from central differences relative to the largest entry)."""
    from rimless.sim.fast import FastIntegrator, fast_step
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.dynamics import DLSP
    from rimless.sim.model.guards import LIFTOFF_A, STALL, TOUCHDOWN
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section

    params = light_wheel_of(ONE_MG)
    mech = Mechanics.of(params)
    y0 = state_from_section(mech, RELEASE_Z)
    guards = (LIFTOFF_A, STALL, TOUCHDOWN)

    def scipy_phase(r: float) -> Any:
        return ScipyIntegrator("DOP853", rtol=r, atol=r * 1e-2).run_phase(mech, DLSP, y0, 0.0, guards, 5.0)

    def fast_phase(r: float) -> Any:
        return FastIntegrator(rtol=r, atol=r * 1e-2).run_phase(mech, DLSP, y0, 0.0, guards, 5.0)

    fast_step(params, "er", RELEASE_Z, rtol=1e-8, jacobian=True)  # compile (or load) before timing
    fast_phase(1e-8)
    ref = scipy_phase(REFERENCE_RTOL)
    ref_maps = {m: fast_step(light_wheel_of(m), "er", RELEASE_Z, rtol=REFERENCE_RTOL) for m in (1e-4, 1e-5)}
    slope = (ONE_MG - 1e-5) / (1e-5 - 1e-4)
    lim_t = ref_maps[1e-5].period_s + (ref_maps[1e-5].period_s - ref_maps[1e-4].period_s) * slope
    lim_z = ref_maps[1e-5].z_next + (ref_maps[1e-5].z_next - ref_maps[1e-4].z_next) * slope
    fd = np.column_stack(
        [
            (
                fast_step(params, "er", RELEASE_Z + dz, rtol=REFERENCE_RTOL).z_next
                - fast_step(params, "er", RELEASE_Z - dz, rtol=REFERENCE_RTOL).z_next
            )
            / 2e-6
            for dz in (np.array([1e-6, 0.0]), np.array([0.0, 1e-6]))
        ]
    )
    rows = []
    for rtol in rtols:
        t_fast, run_fast = _cpu(lambda r=rtol: fast_phase(r), repeats)
        t_scipy, run_scipy = _cpu(lambda r=rtol: scipy_phase(r), repeats)
        t_map, step = _cpu(lambda r=rtol: fast_step(params, "er", RELEASE_Z, rtol=r), repeats)
        t_jac, with_j = _cpu(lambda r=rtol: fast_step(params, "er", RELEASE_Z, rtol=r, jacobian=True), repeats)

        def err(run: Any) -> tuple[float, float]:
            return abs(run.t_end - ref.t_end), float(np.max(np.abs(run.y_end - ref.y_end)))

        rows.append(
            {
                "rtol": rtol,
                "fast_cpu_s": t_fast,
                "scipy_cpu_s": t_scipy,
                "cpu_ratio": t_scipy / t_fast,
                "fast_nfev": run_fast.nfev,
                "scipy_nfev": run_scipy.nfev,
                "fast_errors": err(run_fast),
                "scipy_errors": err(run_scipy),
                "map_cpu_s": t_map,
                "map_nfev": step.nfev,
                "map_limit_error": max(abs(step.period_s - lim_t), *np.abs(step.z_next - lim_z)),
                "map_jacobian_cpu_s": t_jac,
                "map_jacobian_error": float(np.max(np.abs(with_j.jacobian - fd)) / np.max(np.abs(fd))),
            }
        )
    return rows


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
        row, _, _ = _walk_row(params, rtol, n_steps, repeats, ref)

        def maps(r: float = rtol) -> tuple[float, int]:
            z, nfev, err = RELEASE_Z, 0, 0.0
            for ref_step in ref.steps:
                step = fast_step(params, "er", z, rtol=r)
                z, nfev = step.z_next, nfev + step.nfev
                err = max(err, abs(step.period_s - ref_step.period_s), *np.abs(z - ref_step.y_plus[[2, 7]]))
            return err, nfev

        t_map, (err_map, nfev_map) = _cpu(maps, repeats)

        def jacobians(r: float = rtol) -> tuple[float, int]:
            """The map with its exact Jacobian on the reference's steps: its largest difference (relative to the
            largest entry) from central differences of the map at rtol 1e-12 (dz 1e-6), the evaluations."""
            nfev, err = 0, 0.0
            for z in [RELEASE_Z] + [s.y_plus[[2, 7]] for s in ref.steps[:-1]]:
                step = fast_step(params, "er", z, rtol=r, jacobian=True)
                nfev += step.nfev
                fd = np.column_stack(
                    [
                        (
                            fast_step(params, "er", z + dz, rtol=1e-12).z_next
                            - fast_step(params, "er", z - dz, rtol=1e-12).z_next
                        )
                        / 2e-6
                        for dz in (np.array([1e-6, 0.0]), np.array([0.0, 1e-6]))
                    ]
                )
                err = max(err, float(np.max(np.abs(step.jacobian - fd)) / np.max(np.abs(fd))))
            return err, nfev

        def jacobians_timed(r: float = rtol) -> int:
            z, nfev = RELEASE_Z, 0
            for ref_step in ref.steps:
                nfev += fast_step(params, "er", z, rtol=r, jacobian=True).nfev
                z = ref_step.y_plus[[2, 7]]
            return nfev

        t_jac, nfev_jac = _cpu(jacobians_timed, repeats)
        err_jac, _ = jacobians()
        rows.append(
            row
            | {
                "map_cpu_s": t_map,
                "map_nfev": nfev_map,
                "map_error": err_map,
                "map_jacobian_cpu_s": t_jac,
                "map_jacobian_nfev": nfev_jac,
                "map_jacobian_error": err_jac,
            }
        )
    fric = friction_rows(rtols, n_steps, repeats)
    dlsp = double_support_rows(rtols, repeats)
    return {
        "double_support_rows": dlsp,
        "params": params,
        "friction_rows": fric,
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
        f"{'period err R':>12} {'period err D':>12} {'z err R':>9} {'z err D':>9} {'map s':>7} {'map nfev':>8} {'map err':>8} "
        f"{'map+J s':>8} {'J nfev':>7} {'J err':>8}",
    ]
    for r in out["rows"]:
        (pr, zr), (pd, zd) = r["rosenbrock_errors"], r["dop853_errors"]
        lines.append(
            f"{r['rtol']:7.0e} {r['rosenbrock_cpu_s']:12.4f} {r['dop853_cpu_s']:9.4f} {r['cpu_ratio']:6.1f} "
            f"{r['rosenbrock_nfev']:8d} {r['dop853_nfev']:8d} {pr:12.2e} {pd:12.2e} {zr:9.2e} {zd:9.2e} "
            f"{r['map_cpu_s']:7.4f} {r['map_nfev']:8d} {r['map_error']:8.1e} "
            f"{r['map_jacobian_cpu_s']:8.4f} {r['map_jacobian_nfev']:7d} {r['map_jacobian_error']:8.1e}"
        )
    lines.append(f"The same walk with guide friction F_c = {FRICTION_N:g} N (stick/slip phases), reference with it:")
    lines.append(
        f"{'rtol':>7} {'Rosenbrock s':>12} {'DOP853 s':>9} {'ratio':>6} {'nfev R':>8} {'nfev D':>8} "
        f"{'period err R':>12} {'period err D':>12} {'z err R':>9} {'z err D':>9} {'W_f err R':>9} {'W_f err D':>9} "
        f"{'stuck err R':>11} {'stuck err D':>11}"
    )
    for r in out["friction_rows"]:
        (pr, zr), (pd, zd) = r["rosenbrock_errors"], r["dop853_errors"]
        (wr, sr), (wd, sd) = r["rosenbrock_friction_errors"], r["dop853_friction_errors"]
        lines.append(
            f"{r['rtol']:7.0e} {r['rosenbrock_cpu_s']:12.4f} {r['dop853_cpu_s']:9.4f} {r['cpu_ratio']:6.1f} "
            f"{r['rosenbrock_nfev']:8d} {r['dop853_nfev']:8d} {pr:12.2e} {pd:12.2e} {zr:9.2e} {zd:9.2e} "
            f"{wr:9.1e} {wd:9.1e} {sr:11.1e} {sd:11.1e}"
        )
    if out["friction_rows"]:
        r = out["friction_rows"][0]
        lines.append(
            f"(steps walked R/D/reference: {'/'.join(str(n) for n in r['steps'])}; the reference's friction work over "
            f"the walk {r['friction_work_J']:.4g} J)"
        )
    lines.append(
        f"Legs of {ONE_MG * 1e3:g} g: double support from the release, compiled DOP853 (F) and scipy's DOP853 on the "
        f"reference model (S) side by side, errors (lift-off time s, state) against S at rtol {REFERENCE_RTOL:g}; the "
        "compiled map, its error against the light-leg limit (maps of 0.1 g and 0.01 g legs), its Jacobian's against "
        "central differences:"
    )
    lines.append(
        f"{'rtol':>7} {'F s':>8} {'S s':>8} {'ratio':>6} {'nfev F':>6} {'nfev S':>6} {'t err F':>8} {'t err S':>8} "
        f"{'y err F':>8} {'y err S':>8} {'map s':>8} {'map nfev':>8} {'map err':>8} {'map+J s':>8} {'J err':>8}"
    )
    for r in out.get("double_support_rows", []):
        (tf, yf), (ts, ys) = r["fast_errors"], r["scipy_errors"]
        lines.append(
            f"{r['rtol']:7.0e} {r['fast_cpu_s']:8.5f} {r['scipy_cpu_s']:8.5f} {r['cpu_ratio']:6.1f} "
            f"{r['fast_nfev']:6d} {r['scipy_nfev']:6d} {tf:8.1e} {ts:8.1e} {yf:8.1e} {ys:8.1e} "
            f"{r['map_cpu_s']:8.5f} {r['map_nfev']:8d} {r['map_limit_error']:8.1e} {r['map_jacobian_cpu_s']:8.5f} "
            f"{r['map_jacobian_error']:8.1e}"
        )
    lines.append(
        f"CPU time of this thread, median of repeats; load average {out['load_before']:.1f} before, "
        f"{out['load_after']:.1f} after"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    print(format_table(stiff_bench()))
