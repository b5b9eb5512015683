"""Benchmark of the step map's Jacobian with guide friction: the exact one (rimless.sim.step.fast_map.
friction_step(jacobian=True): variational equations through the stick/slip sub-phases, saltation at their
events) against central differences of the same compiled map (what FastPoincareMap.jacobian took before, step
1e-5, four map calls), side by side in one run.

Each row is one (model, F_c, wheel, section point z, rtol): Table 1 and a wheel away from it (`AWAY`: m_H 2.3 kg,
m 0.05 kg, I_c 0.06 kg m^2, k 1800 N/m, c 4 N s/m; the rest Table 1's), F_c 0.1-0.6 N, z = (theta+ rad,
theta'+ rad/s). Both Jacobians are taken at each rtol of RTOLS (atol = rtol / 100) and compared with a truth:
central differences of the compiled map at rtol 1e-12 with step 1e-6 (their own error some 1e-7 relative at most:
the map's error over the step, the step's truncation; 7e-8 on the sharply bending case, whose differences at step
1e-5 are off by 8e-6). Errors: the largest |J - J_truth| relative to the largest
|J_truth| entry. Times: CPU time of this thread (time.thread_time), median of `repeats`; the ratio printed is
central differences' CPU over the exact Jacobian's. `events`: the guards the tangents went through (a
"slip-end" is a leg that sticks or reverses, a "stick-end" a stuck leg that slips again).

The 2e-7 against the reference path (session 22: "one case 2e-7, not investigated"; tests/sim/fast/
test_friction_jacobian.py, the slow reference-path test): ER, F_c 0.3 N, Table 1, z = Z_SLOW, entry
dtheta'+/dtheta+ (2.6e-7 of -1.294; the events lift-off, two slip ends, the clutch's lock, a stick's end). It is
the reference path's own tolerance, not the tangents nor an event located differently (session 23, load 16-19):
- the compiled exact Jacobian is converged: at rtol 1e-10, 1e-11, 1e-12 it is within 7e-11 of itself at 1e-13,
  and within 8.8e-9 of central differences of the compiled map (rtol 1e-12, step 1e-5);
- central differences of the reference map (scipy DOP853, Python right-hand side, step 1e-5) approach it as the
  reference's rtol tightens: 9.9e-7 at rtol 1e-10, 1.6e-6 at 1e-11, 2.0e-7 at 1e-12, 4.9e-9 at 1e-13;
- at rtol 1e-12 the gap does not depend on the step (1.4e-7, 2.0e-7, 2.1e-7 at steps 1e-4, 1e-5, 1e-6): not
  rounding noise over the step (that would grow tenfold per decade) but the slope of the reference map's global
  integration error, smooth in z (the two maps' z_next differ by 2.3e-12 there).
On the VE case of that test (F_c 0.1 N, the wheel away, no clutch lock) the two agree within 6e-9 at rtol 1e-12.

Run: ``python -m rimless.sim.studies.fricjacbench`` (about 5 s of CPU once compiled).
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

AWAY: dict[str, Any] = {
    "hub_mass_kg": 2.3,
    "leg_mass_kg": 0.05,
    "inertia_kg_m2": 0.06,
    "stiffness_n_per_m": 1800.0,
    "damping_ns_per_m": 4.0,
}
Z_TABLE1 = (-0.465155, 2.604441)  # near Table 1's ER fixed point
Z_SLOW = (-0.42, 2.3)
# (model, F_c N, wheel, z): tests/sim/fast/test_friction_jacobian.py's cases and one where the map bends sharply
CASES: tuple[tuple[str, float, str, tuple[float, float]], ...] = (
    ("er", 0.1, "away", Z_TABLE1),
    ("er", 0.3, "table1", Z_SLOW),
    ("er", 0.3, "away", Z_SLOW),
    ("er", 0.6, "away", Z_SLOW),
    ("ve", 0.1, "away", Z_SLOW),
    ("ve", 0.3, "table1", Z_SLOW),
    ("ve", 0.6, "away", Z_TABLE1),
)
RTOLS = (1e-8, 1e-10)
TRUTH_RTOL = 1e-12
FD_STEP = 1e-5
TRUTH_STEP = 1e-6  # the truth's step: 1e-5 leaves 8e-6 of truncation on the sharply bending case


def _central(params: Any, model: str, z: np.ndarray, rtol: float, h: float) -> np.ndarray:
    from rimless.sim.step.fast_map import friction_step

    J = np.empty((2, 2))
    for i in range(2):
        dz = np.zeros(2)
        dz[i] = h
        J[:, i] = (
            friction_step(params, model, z + dz, rtol=rtol).z_next
            - friction_step(params, model, z - dz, rtol=rtol).z_next
        ) / (2 * h)
    return J


def _cpu(fn: Any, repeats: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.thread_time()
        out = fn()
        times.append(time.thread_time() - t0)
    return float(np.median(times)), out


def friction_jacobian_bench(
    rtols: tuple[float, ...] = RTOLS,
    repeats: int = 3,
    cases: tuple[tuple[str, float, str, tuple[float, float]], ...] = CASES,
) -> dict[str, Any]:
    """Rows per case and rtol: CPU s of the exact Jacobian and of central differences, their ratio, each one's
    error against the truth (module docstring), the events crossed."""
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.fast_map import friction_step

    load = os.getloadavg()[0]
    rows = []
    for model, friction_n, wheel, z0 in cases:
        params = WheelParams(guide_friction_n=friction_n, **(AWAY if wheel == "away" else {}))
        z = np.array(z0)
        friction_step(params, model, z, rtol=1e-10, jacobian=True)  # compile (or load) before timing
        truth = _central(params, model, z, TRUTH_RTOL, TRUTH_STEP)
        scale = float(np.max(np.abs(truth)))
        for rtol in rtols:
            t_exact, exact = _cpu(
                lambda p=params, m=model, zz=z, r=rtol: friction_step(p, m, zz, rtol=r, jacobian=True), repeats
            )
            t_fd, fd = _cpu(lambda p=params, m=model, zz=z, r=rtol: _central(p, m, zz, r, FD_STEP), repeats)
            rows.append(
                {
                    "model": model,
                    "friction_n": friction_n,
                    "wheel": wheel,
                    "z": z0,
                    "rtol": rtol,
                    "exact_cpu_s": t_exact,
                    "central_cpu_s": t_fd,
                    "cpu_ratio": t_fd / t_exact,
                    "exact_error": float(np.max(np.abs(exact.jacobian - truth))) / scale,
                    "central_error": float(np.max(np.abs(fd - truth))) / scale,
                    "events": exact.events,
                }
            )
    return {"rows": rows, "load_before": load, "load_after": os.getloadavg()[0]}


def _events(events: tuple[str, ...]) -> str:
    counts: dict[str, int] = {}
    for e in events:
        counts[e] = counts.get(e, 0) + 1
    return " ".join(f"{k}x{v}" if v > 1 else k for k, v in counts.items())


def format_table(out: dict[str, Any]) -> str:
    lines = [
        "Step-map Jacobian with guide friction: exact (variational + saltation) against central differences of the "
        f"compiled map (step {FD_STEP:g}), each at rtol; errors against central differences at rtol {TRUTH_RTOL:g} "
        f"(step {TRUTH_STEP:g}), relative to the largest entry",
        f"{'model':>5} {'F_c N':>5} {'wheel':>6} {'theta+':>9} {'theta+dot':>9} {'rtol':>6} {'exact ms':>8} "
        f"{'central ms':>10} {'ratio':>5} {'exact err':>9} {'central err':>11}  events",
    ]
    for r in out["rows"]:
        lines.append(
            f"{r['model']:>5} {r['friction_n']:5.1f} {r['wheel']:>6} {r['z'][0]:9.6f} {r['z'][1]:9.6f} "
            f"{r['rtol']:6.0e} {r['exact_cpu_s'] * 1e3:8.2f} {r['central_cpu_s'] * 1e3:10.2f} {r['cpu_ratio']:5.1f} "
            f"{r['exact_error']:9.1e} {r['central_error']:11.1e}  {_events(r['events'])}"
        )
    lines.append(
        f"CPU time of this thread, median of repeats; load average {out['load_before']:.1f} before, "
        f"{out['load_after']:.1f} after"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    print(format_table(friction_jacobian_bench()))
