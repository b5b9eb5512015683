"""Work-precision benchmark of the Poincaré map: the compiled fast path against scipy's RK45 and DOP853
solvers (Python right-hand side, rimless.sim.integrate.reference.ScipyIntegrator), in one run, side by side.

For the ER and VE wheels at Table 1 (eight-leg), at the fixed points z*, and each tolerance rtol
(atol = rtol / 100), every backend gives P(z*), the step period and max |eigenvalue| of dP/dz
(fast path: exact variational Jacobian; scipy backends: PoincareMap.jacobian, central differences with
its default step). Errors are against a tight reference: scipy DOP853 at rtol 1e-13 (atol 1e-15), its
eigenvalues from central differences with h = 1e-5 (accurate to about 1e-8). Time per map is
the time of P alone (no Jacobian), median over repetitions. Units: errors in rad, rad/s (inf-norm over z),
s (period); times in s. Every time is measured twice: CPU time of the thread that ran it (time.thread_time)
and wall time (time.perf_counter); every ratio printed comes from CPU time, so other processes on the machine
do not change it (they stretch the wall time of a compiled and a Python path differently: 405x at load 4 and
4578x at load 22 from wall medians), and the wall figures are printed beside. Steps and right-hand-side evaluations per map are reported for the fast path, in
total and per phase. The speed-up at error <= 1e-9 compares, per backend, the loosest rtol at which that
rtol and every tighter one run meet the target (the grids include half decades, so neither backend is held
to a decade step). A compiled third-party integrator (numbakit-ode's DOP853, if installed) runs beside the
fast path's integrator on one phase (without --quick). Guide friction (F_c = 0.5 N): one step map on the
compiled path (stick/slip phase by phase) and on the reference path side by side, ratio and errors.

The load average is recorded before and after the run: on a busy machine the wall times are marked and
followed by a warning (the CPU-time ratios stand; a loaded core's shared caches still move them a little).
"""

from __future__ import annotations

import functools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from rimless.sim.model.params import WheelParams

Z_STAR = {"er": np.array([-0.465155, 2.604441]), "ve": np.array([-0.434780, 2.289290])}
REFERENCE_RTOL = 1e-13
T = TypeVar("T")
TARGET_ERROR = 1e-9


@dataclass(frozen=True)
class Clocks:
    """The two clocks of every timing (a seam: tests put fakes here). cpu: CPU time of the calling thread (s);
    wall: a monotonic wall clock (s)."""

    cpu: Callable[[], float] = time.thread_time
    wall: Callable[[], float] = time.perf_counter


CLOCKS = Clocks()


@dataclass(frozen=True)
class Timing:
    """CPU and wall seconds of one piece of work (medians where it was repeated)."""

    cpu_s: float
    wall_s: float


def time_once(fn: Callable[[], T]) -> tuple[T, Timing]:
    """fn()'s result and its CPU and wall time."""
    c0, w0 = CLOCKS.cpu(), CLOCKS.wall()
    out = fn()
    return out, Timing(CLOCKS.cpu() - c0, CLOCKS.wall() - w0)


def _time_per_call(fn: Callable[[], Any], budget_s: float, max_reps: int) -> Timing:
    """Median CPU and wall time of fn() over repetitions filling about budget_s of CPU time (at least 1, at most
    max_reps): the number of repetitions does not depend on the machine's load either."""
    cpu: list[float] = []
    wall: list[float] = []
    while len(cpu) < max_reps:
        _, t = time_once(fn)
        cpu.append(t.cpu_s)
        wall.append(t.wall_s)
        if sum(cpu) > budget_s:
            break
    return Timing(float(np.median(cpu)), float(np.median(wall)))


def cpu_ratio(slow_cpu_s: float | None, fast_cpu_s: float | None) -> float | None:
    """slow / fast in CPU time; None when either is missing or the fast one took no measurable CPU time."""
    if slow_cpu_s is None or fast_cpu_s is None or not fast_cpu_s > 0:
        return None
    return slow_cpu_s / fast_cpu_s


def load_average() -> list[float] | None:
    """The 1, 5 and 15 minute load averages (None where the platform has none)."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def machine_load(before: list[float] | None, after: list[float] | None) -> dict[str, Any]:
    """Load averages around a run and whether the machine was busy with other work.

    Busy: the 1-minute load before the run, or after it less the benchmark's own process, exceeds a quarter
    of the cores: then timings (and more so ratios between a compiled and a Python path, which load slows
    differently) are not representative."""
    cpus = os.cpu_count() or 1
    busy = None
    if before is not None and after is not None:
        others = max(before[0], after[0] - 1.0)
        busy = bool(others > 0.25 * cpus)
    return {"before": before, "after": after, "cpus": cpus, "busy": busy}


def _compile_cost(quick: bool) -> dict[str, Any]:
    """First-call cost of the compiled kernels in a fresh process: cold (empty numba cache) and warm."""
    code = (
        "import time; c=time.process_time(); t=time.perf_counter(); from rimless.sim import fast; "
        "t1=time.perf_counter(); c1=time.process_time(); fast.warm_up(); "
        "print(t1-t, time.perf_counter()-t1, c1-c, time.process_time()-c1)"
    )
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as cache_dir:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
        runs = ["warm"] if quick else ["cold", "warm"]
        if quick:
            env = dict(os.environ)  # the project's own cache, as a user would have it after a first run
        for label in runs:
            try:
                res = subprocess.run(
                    [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600, check=True
                )
                imp, first, imp_cpu, first_cpu = (float(v) for v in res.stdout.split())
                out[label] = {
                    "import_s": imp,
                    "first_calls_s": first,
                    "import_cpu_s": imp_cpu,
                    "first_calls_cpu_s": first_cpu,
                }
            except (subprocess.SubprocessError, ValueError) as err:
                out[label] = {"error": str(err)}
    if quick:
        out["note"] = "quick: warm cache only (a cold compile takes tens of seconds; run without --quick)"
    return out


def loosest_meeting(
    rows: list[dict[str, Any]], model: str, backend: str, target: float = TARGET_ERROR
) -> dict[str, Any] | None:
    """The row of the loosest rtol whose error, and that of every tighter rtol run, is <= target (a loose
    rtol that meets it by chance, above a tighter one that does not, does not count); None if none."""
    mine = sorted((r for r in rows if r["model"] == model and r["backend"] == backend), key=lambda r: r["rtol"])
    best = None
    for r in mine:
        if r["error"] > target:
            break
        best = r
    return best


def speedups_at_target(rows: list[dict[str, Any]], target: float = TARGET_ERROR) -> dict[str, dict[str, Any]]:
    """Per model: the fast path's and scipy DOP853's loosest rtol meeting `target` (loosest_meeting), their CPU
    and wall seconds per map, and the speed-up DOP853 / fast in CPU time (`speedup`; `speedup_wall` beside)."""
    out: dict[str, dict[str, Any]] = {}
    for model in sorted({r["model"] for r in rows}):
        f = loosest_meeting(rows, model, "fast-dop853", target)
        d = loosest_meeting(rows, model, "scipy-DOP853", target)
        out[model] = {
            "fast_rtol": f and f["rtol"],
            "fast_seconds_per_map": f and f["seconds_per_map"],
            "fast_cpu_seconds_per_map": f and f["cpu_seconds_per_map"],
            "dop853_rtol": d and d["rtol"],
            "dop853_seconds_per_map": d and d["seconds_per_map"],
            "dop853_cpu_seconds_per_map": d and d["cpu_seconds_per_map"],
            "speedup": cpu_ratio(d["cpu_seconds_per_map"], f["cpu_seconds_per_map"]) if (f and d) else None,
            "speedup_wall": (d["seconds_per_map"] / f["seconds_per_map"]) if (f and d) else None,
        }
    return out


PEER_PHASE_S = 0.2  # the peer comparison integrates clutched single support for this long (s)


def _peer_bench(params: WheelParams, quick: bool) -> dict[str, Any]:
    """A compiled third-party integrator beside ours on the same phase and right-hand side: numbakit-ode's
    DOP853 (nbkode, numba; optional, not a dependency) against rimless.sim.fast.rk.run_phase, clutched single
    support of the ER wheel for PEER_PHASE_S from the state at clutch lock (no guards), at several rtol
    (atol = rtol / 100). Both call the same compiled generated equations; the error is the inf-norm of the
    end state against scipy DOP853 at rtol 1e-13 on that right-hand side. Skipped with --quick: nbkode
    compiles its solver for minutes in every new process."""
    if quick:
        return {"skipped": "--quick (nbkode compiles for minutes in each process)"}
    try:
        import nbkode  # type: ignore[import-not-found]
        import numba
    except ImportError:
        return {"skipped": "not installed (pip install numbakit-ode)"}
    from scipy.integrate import solve_ivp

    from rimless.sim.fast import mass_model_index, param_vector, rk
    from rimless.sim.fast import model as fm
    from rimless.sim.fast import step as fs

    mi = mass_model_index(params)
    p = param_vector(params)
    phase = fm.SLSP_CLUTCHED

    @numba.njit
    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        out = np.empty(10)
        qdd = np.empty(5)
        lam = np.zeros(4)
        fm.accel_reduced(mi, phase, y[:5], y[5:], p, qdd, lam, np.empty(0))
        out[:5] = y[5:]
        out[5:] = qdd
        return out

    y0, _ = fm.state_from_section(mi, Z_STAR["er"], p)
    none = np.zeros(0, dtype=np.int64)
    r0 = rk.run_phase(
        mi,
        fm.DLSP,
        p,
        y0,
        0.0,
        fs.PHASE_DLSP_CODES,
        fs.PHASE_DLSP_DIRS,
        5.0,
        1e-13,
        1e-15,
        10,
        False,
        False,
        -1.0,
        10**6,
    )
    r1 = rk.run_phase(
        mi,
        fm.SLSP_FREE,
        p,
        r0[2],
        r0[1],
        fs.PHASE_FREE_ER_CODES,
        fs.PHASE_FREE_ER_DIRS,
        5.0,
        1e-13,
        1e-15,
        10,
        False,
        False,
        -1.0,
        10**6,
    )
    ys = np.array(r1[2], dtype=float)
    ys[8] = 0.0
    t0 = float(r1[1])
    ref = solve_ivp(rhs, (t0, t0 + PEER_PHASE_S), ys, method="DOP853", rtol=1e-13, atol=1e-15).y[:, -1]
    import warnings

    warnings.filterwarnings("ignore", module="nbkode")  # its numba performance / experimental-feature notes
    warnings.filterwarnings("ignore", category=numba.NumbaWarning)
    try:
        _, first_call = time_once(
            lambda: nbkode.DOP853(rhs, t0, ys, rtol=1e-6, atol=1e-8, first_step=1e-3).run(t0 + PEER_PHASE_S)
        )
        compile_s = first_call.wall_s
    except Exception as err:  # noqa: BLE001 (a third-party failure is reported, not raised)
        return {"skipped": f"nbkode failed: {type(err).__name__}: {err}"}
    rows = []
    for rtol in (1e-6, 1e-8, 1e-10):

        def ours(rtol: float = rtol) -> np.ndarray:
            return rk.run_phase(
                mi, phase, p, ys, t0, none, none, PEER_PHASE_S, rtol, rtol * 1e-2, 10, False, False, -1.0, 10**6
            )[2]

        def peer(rtol: float = rtol) -> np.ndarray:
            # first_step given: nbkode 0.5's own initial-step choice calls scipy's select_initial_step with
            # an older signature and fails on current scipy
            _, y = nbkode.DOP853(rhs, t0, ys, rtol=rtol, atol=rtol * 1e-2, first_step=1e-3).run(t0 + PEER_PHASE_S)
            return np.asarray(y).reshape(-1)[:10]

        for name, fn in (("fast-dop853", ours), ("nbkode-DOP853", peer)):
            t = _time_per_call(fn, 0.3, 200)
            rows.append(
                {
                    "backend": name,
                    "rtol": rtol,
                    "error": float(np.max(np.abs(fn() - ref))),
                    "seconds": t.wall_s,
                    "cpu_seconds": t.cpu_s,
                }
            )
    return {
        "phase": "ER clutched single support",
        "duration_s": PEER_PHASE_S,
        "peer_first_call_s": compile_s,
        "rows": rows,
    }


def _timed_fixed_point(pmap: Any, guess: np.ndarray, reps: int, *, record: bool = True) -> tuple[Any, Timing]:
    """The fixed point from `guess` with the exact Jacobian, and its median CPU and wall time (s) over `reps`
    runs after one warm-up run."""
    from rimless.sim.step.poincare import solve_fixed_point

    solve_fixed_point(pmap, guess, record=record)  # warm
    found: list[Any] = []

    def solve() -> None:
        found.append(solve_fixed_point(pmap, guess, jacobian=pmap.variational_jacobian, record=record))

    t = _time_per_call(solve, math.inf, reps)
    return found[-1], t


FRICTION_N = 0.5  # guide friction of the friction rows, N


def friction_bench(quick: bool, say: Callable[[str], None]) -> dict[str, Any]:
    """Guide friction (F_c = FRICTION_N) side by side: one step map from z* on the compiled path (each stick/slip
    phase compiled, rimless.sim.step.fast_map.friction_step) and on the reference path (scipy DOP853), both at
    rtol 1e-10, each against a tight reference (scipy DOP853 rtol REFERENCE_RTOL): error in z (inf-norm), friction
    work error (J), CPU and wall seconds per map (median) and their ratio (CPU; `ratio_wall` beside)."""
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import section_from_state, state_from_section
    from rimless.sim.step.fast_map import friction_step
    from rimless.sim.step.hybrid import simulate_step

    params = WheelParams(guide_friction_n=FRICTION_N)
    mech = Mechanics.of(params)
    rtol = 1e-10
    out: dict[str, Any] = {"guide_friction_n": FRICTION_N, "rtol": rtol, "rows": []}
    for model in ("er", "ve"):
        z = Z_STAR[model]
        y0 = state_from_section(mech, z)
        say(f"{model}: guide friction {FRICTION_N:g} N, tight reference")
        tight = simulate_step(
            mech, model, y0, ScipyIntegrator("DOP853", rtol=REFERENCE_RTOL, atol=REFERENCE_RTOL * 1e-2)
        )
        z_ref = section_from_state(tight.y_plus)
        say(f"{model}: guide friction, compiled and reference paths")
        fast_r = friction_step(params, model, z, rtol=rtol)
        ref_integ = ScipyIntegrator("DOP853", rtol=rtol, atol=rtol * 1e-2)
        ref_r = simulate_step(mech, model, y0, ref_integ)
        fast_t = _time_per_call(lambda: friction_step(params, model, z, rtol=rtol), 0.1 if quick else 0.5, 200)
        ref_t = _time_per_call(
            lambda: simulate_step(mech, model, y0, ref_integ),
            0.05 if quick else 0.5,
            3 if quick else 20,
        )
        out["rows"].append(
            {
                "model": model,
                "fast_seconds_per_map": fast_t.wall_s,
                "reference_seconds_per_map": ref_t.wall_s,
                "fast_cpu_seconds_per_map": fast_t.cpu_s,
                "reference_cpu_seconds_per_map": ref_t.cpu_s,
                "ratio": cpu_ratio(ref_t.cpu_s, fast_t.cpu_s),
                "ratio_wall": ref_t.wall_s / fast_t.wall_s,
                "fast_error": float(np.max(np.abs(fast_r.z_next - z_ref))),
                "reference_error": float(np.max(np.abs(section_from_state(ref_r.y_plus) - z_ref))),
                "fast_vs_reference": float(np.max(np.abs(fast_r.z_next - section_from_state(ref_r.y_plus)))),
                "friction_work_J": tight.friction_work_J,
                "fast_friction_work_error_J": abs(fast_r.friction_work_J - tight.friction_work_J),
                "reference_friction_work_error_J": abs(ref_r.friction_work_J - tight.friction_work_J),
                "stick_s": list(tight.stick_s),
            }
        )
    return out


def run_bench(quick: bool, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run the benchmark; returns the JSON-ready result (see the module docstring).

    quick: fewer tolerances, fewer repetitions, no cold-compile measurement (well under a minute with a
    warm numba cache).
    """
    from rimless.sim import fast
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.step.fast_map import FastPoincareMap
    from rimless.sim.step.poincare import PoincareMap, solve_fixed_point

    say = progress or (lambda _msg: None)
    params = WheelParams()
    load_before = load_average()
    t0, c0 = time.perf_counter(), CLOCKS.cpu()
    say("compiling / loading the fast kernels")
    warm_s = fast.warm_up()
    if quick:
        tols = {
            "fast": [1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 1e-7, 1e-8, 1e-10],
            "DOP853": [1e-6, 1e-7, 1e-8, 1e-9, 1e-10],
            "RK45": [1e-4, 1e-6],
        }
        budget, fast_budget = 0.2, 0.1
    else:
        full = sorted([10.0**-e for e in range(4, 13)] + [3 * 10.0**-e for e in range(5, 10)], reverse=True)
        tols = {"fast": full, "DOP853": full, "RK45": [10.0**-e for e in range(4, 10)]}
        budget, fast_budget = 0.5, 0.5

    rows: list[dict[str, Any]] = []
    reference: dict[str, dict[str, Any]] = {}
    for model in ("er", "ve"):
        z = Z_STAR[model]
        say(f"{model}: tight reference (scipy DOP853, rtol {REFERENCE_RTOL:g})")
        ref_map = PoincareMap(params, model, ScipyIntegrator("DOP853", rtol=REFERENCE_RTOL, atol=REFERENCE_RTOL * 1e-2))
        ref_step = ref_map.step(z)
        z_ref = np.array([ref_step.y_plus[2], ref_step.y_plus[7]])
        eig_ref = float(np.max(np.abs(np.linalg.eigvals(ref_map.jacobian(z, h=1e-5)))))
        reference[model] = {"z": z_ref.tolist(), "period_s": ref_step.period_s, "max_abs_eigenvalue": eig_ref}
        for backend, tol_list in tols.items():
            for rtol in tol_list:
                atol = rtol * 1e-2
                say(f"{model}: {backend} rtol {rtol:g}")
                if backend == "fast":
                    pm: Any = FastPoincareMap(params, model, fast.FastIntegrator(rtol=rtol, atol=atol))
                    r = fast.fast_step(params, model, z, rtol=rtol, atol=atol, jacobian=True)
                    z_new, period, J = r.z_next, r.period_s, r.jacobian
                    assert J is not None  # jacobian=True
                    tm = _time_per_call(
                        lambda: fast.fast_step(params, model, z, rtol=rtol, atol=atol),
                        fast_budget,
                        2000,
                    )
                    tj = _time_per_call(
                        lambda: fast.fast_step(
                            params,
                            model,
                            z,
                            rtol=rtol,
                            atol=atol,
                            jacobian=True,
                        ),
                        fast_budget / 2,
                        500,
                    )
                    nfev, nsteps = r.nfev, r.nsteps
                    per_phase = {"phase_nfev": list(r.phase_nfev), "phase_steps": list(r.phase_steps)}
                else:
                    per_phase = {}
                    pm = PoincareMap(params, model, ScipyIntegrator(backend, rtol=rtol, atol=atol))
                    st = pm.step(z)
                    z_new, period = np.array([st.y_plus[2], st.y_plus[7]]), st.period_s
                    nfev, nsteps = st.nfev, -1
                    tm = _time_per_call(lambda: pm(z), budget, 20)
                    J_ref, tjac = time_once(functools.partial(pm.jacobian, z))
                    J = np.asarray(J_ref)
                    tj = Timing(tjac.cpu_s + tm.cpu_s, tjac.wall_s + tm.wall_s)
                rows.append(
                    {
                        "model": model,
                        "backend": "fast-dop853" if backend == "fast" else f"scipy-{backend}",
                        "rtol": rtol,
                        "atol": atol,
                        "error": float(np.max(np.abs(z_new - z_ref))),
                        "period_error_s": abs(period - ref_step.period_s),
                        "eigenvalue_error": abs(float(np.max(np.abs(np.linalg.eigvals(J)))) - eig_ref),
                        "jacobian_method": "variational" if backend == "fast" else "central-difference h=1e-4",
                        "seconds_per_map": tm.wall_s,
                        "seconds_per_map_and_jacobian": tj.wall_s,
                        "cpu_seconds_per_map": tm.cpu_s,
                        "cpu_seconds_per_map_and_jacobian": tj.cpu_s,
                        "nfev": int(nfev),
                        "nsteps": int(nsteps),
                        **per_phase,
                    }
                )

    speedups = speedups_at_target(rows)
    valid = [s["speedup"] for s in speedups.values() if s["speedup"] is not None]
    valid_wall = [s["speedup_wall"] for s in speedups.values() if s["speedup"] is not None]

    # fixed point with eigenvalues on both paths (after warm-up)
    fixed: dict[str, Any] = {}
    for model in ("er", "ve"):
        guess = Z_STAR[model] + np.array([0.01, -0.05])
        say(f"{model}: fixed point, fast path")
        reps = 3 if quick else 10
        fp, fast_t = _timed_fixed_point(FastPoincareMap(params, model, jacobian_with_map=True), guess, reps)
        # the same fixed point at the loosest rtol whose map meets the target error (the table above), without
        # the recorded step (diagnostics the eigenvalues do not need)
        loose = speedups[model]["fast_rtol"]
        loose_entry: dict[str, Any] = {}
        if loose is not None:
            pm_loose = FastPoincareMap(
                params, model, fast.FastIntegrator(rtol=loose, atol=loose * 1e-2), jacobian_with_map=True
            )
            fp_loose, loose_t = _timed_fixed_point(pm_loose, guess, reps, record=False)
            loose_entry = {
                "rtol": loose,
                "seconds": loose_t.wall_s,
                "cpu_seconds": loose_t.cpu_s,
                "iterations": fp_loose.iterations,
                "z": fp_loose.z.tolist(),
                "max_abs_eigenvalue": fp_loose.max_abs_eigenvalue,
            }
        say(f"{model}: fixed point, reference path")
        pm_ref = PoincareMap(params, model)
        fp_ref, ref_t = time_once(functools.partial(solve_fixed_point, pm_ref, guess))
        fixed[model] = {
            "fast_seconds": fast_t.wall_s,
            "fast_cpu_seconds": fast_t.cpu_s,
            "fast_iterations": fp.iterations,
            "fast_z": fp.z.tolist(),
            "fast_eigenvalues": [
                complex(e).real if abs(complex(e).imag) < 1e-15 else str(complex(e)) for e in fp.eigenvalues
            ],
            "fast_jacobian_method": fp.jacobian_method,
            "reference_seconds": ref_t.wall_s,
            "reference_cpu_seconds": ref_t.cpu_s,
            "ratio": cpu_ratio(ref_t.cpu_s, fast_t.cpu_s),
            "reference_iterations": fp_ref.iterations,
            "reference_z": fp_ref.z.tolist(),
            "reference_jacobian_method": fp_ref.jacobian_method,
            "z_difference": float(np.max(np.abs(fp.z - fp_ref.z))),
            "max_abs_eigenvalue_difference": abs(fp.max_abs_eigenvalue - fp_ref.max_abs_eigenvalue),
        }
        if loose_entry:
            loose_entry["z_difference"] = float(np.max(np.abs(np.asarray(loose_entry["z"]) - fp_ref.z)))
            loose_entry["max_abs_eigenvalue_difference"] = abs(
                loose_entry["max_abs_eigenvalue"] - fp_ref.max_abs_eigenvalue
            )
            fixed[model]["at_target_error"] = loose_entry
    # one critical-slope continuation (Algorithm 1 from 0.05 rad, refined to 1e-6 rad) on both paths;
    # the reference path takes about a minute per model, so --quick times the fast path only
    from rimless.sim.continuation.algorithm1 import critical_slope

    continuation: dict[str, Any] = {}
    for model in ("er", "ve"):
        say(f"{model}: critical-slope continuation, fast path")
        pm_fast = FastPoincareMap(params, model, jacobian_with_map=True)
        cs, cs_t = time_once(
            functools.partial(critical_slope, pm_fast, Z_STAR[model], jacobian_factory=lambda m: m.variational_jacobian)
        )
        entry: dict[str, Any] = {
            "fast_seconds": cs_t.wall_s,
            "fast_cpu_seconds": cs_t.cpu_s,
            "fast_critical_slope_rad": cs.critical_slope_rad,
            "fast_reason": cs.reason,
            "branch_points": len(cs.branch),
            "reference_seconds": None,
            "reference_cpu_seconds": None,
            "ratio": None,
            "reference_critical_slope_rad": None,
        }
        if not quick:
            say(f"{model}: critical-slope continuation, reference path (about a minute)")
            cs_ref, ref_cs_t = time_once(functools.partial(critical_slope, PoincareMap(params, model), Z_STAR[model]))
            entry.update(
                reference_seconds=ref_cs_t.wall_s,
                reference_cpu_seconds=ref_cs_t.cpu_s,
                ratio=cpu_ratio(ref_cs_t.cpu_s, cs_t.cpu_s),
                reference_critical_slope_rad=cs_ref.critical_slope_rad,
                reference_reason=cs_ref.reason,
            )
        continuation[model] = entry
    friction = friction_bench(quick, say)
    say("third-party compiled integrator on one phase")
    peer = _peer_bench(params, quick)
    say("compile cost (fresh processes)")
    compile_cost = _compile_cost(quick)
    compile_cost["in_process_warm_up_s"] = warm_s
    load = machine_load(load_before, load_average())
    return {
        "quick": quick,
        "load_average": load,
        "settings": {
            "params": params.to_dict(),
            "z": {m: v.tolist() for m, v in Z_STAR.items()},
            "reference": f"scipy DOP853 rtol {REFERENCE_RTOL:g} atol {REFERENCE_RTOL * 1e-2:g}",
            "atol": "rtol / 100 for every backend",
            "target_error": TARGET_ERROR,
        },
        "reference": reference,
        "rows": rows,
        "speedup_at_1e-9": min(valid) if valid else None,
        "speedup_at_1e-9_wall": min(valid_wall) if valid_wall else None,
        "ratios_from": "CPU time of the thread that ran the work (time.thread_time); *_wall and seconds* beside",
        "speedup_at_1e-9_by_model": speedups,
        "fixed_point": fixed,
        "critical_slope_continuation": continuation,
        "guide_friction": friction,
        "peer": peer,
        "compile": compile_cost,
        "total_seconds": time.perf_counter() - t0,
        "total_cpu_seconds": CLOCKS.cpu() - c0,
    }


def plot_work_precision(result: dict[str, Any], path: str) -> None:
    """Error (x, log) against time per map (y, log), one line per backend and model; saved to path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    styles = {"er": "-", "ve": "--"}
    keys = sorted({(r["backend"], r["model"]) for r in result["rows"]})
    for backend, model in keys:
        rs = sorted(
            (r for r in result["rows"] if r["backend"] == backend and r["model"] == model), key=lambda r: r["rtol"]
        )
        err = [max(r["error"], 1e-17) for r in rs]
        ax.loglog(
            err,
            [r.get("cpu_seconds_per_map", r["seconds_per_map"]) for r in rs],
            styles.get(model, "-"),
            marker="o",
            label=f"{backend} ({model.upper()})",
        )
    ax.axvline(TARGET_ERROR, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("error of the post-impact state z (inf-norm; rad, rad/s)")
    ax.set_ylabel("CPU time per map (s)")
    sp = result.get("speedup_at_1e-9")
    title = "Poincaré map work-precision"
    if sp:
        busy = (result.get("load_average") or {}).get("busy")
        title += f" (speed-up at 1e-9: {sp:.0f}x CPU time{', busy machine' if busy else ''})"
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _ms(seconds: float | None, digits: int = 3) -> str:
    return "-" if seconds is None else f"{seconds * 1e3:.{digits}f} ms"


def _x(ratio: float | None) -> str:
    return "n/a" if ratio is None else f"{ratio:.0f}x"


def format_table(result: dict[str, Any]) -> str:
    """A plain-text summary of a run_bench result: every ratio in CPU time, wall time beside."""
    lines = [
        f"{'model':5} {'backend':12} {'rtol':>6} {'error':>7} {'T err':>7} {'eig err':>7} {'cpu s':>8} "
        f"{'wall':>8} {'nfev':>6} {'steps':>5}"
    ]
    for r in result["rows"]:
        steps = r.get("nsteps", -1)
        cpu = r.get("cpu_seconds_per_map")
        lines.append(
            f"{r['model']:5} {r['backend']:12} {r['rtol']:6.0e} {r['error']:7.1e} {r['period_error_s']:7.1e} "
            f"{r['eigenvalue_error']:7.1e} {'-' if cpu is None else f'{cpu:.2e}':>8} {r['seconds_per_map']:8.2e} "
            f"{r['nfev']:6d} {steps if steps >= 0 else '-':>5}"
        )
    load = result.get("load_average") or {}
    busy = load.get("busy")
    if load.get("before") is not None:
        lines.append(
            f"load average 1/5/15 min: before {' '.join(f'{v:.2f}' for v in load['before'])}, "
            f"after {' '.join(f'{v:.2f}' for v in load['after'])} ({load['cpus']} cores)"
        )
    lines.append("s per map above; every ratio from CPU time (the thread that ran it), wall beside")
    sp, sp_wall = result["speedup_at_1e-9"], result.get("speedup_at_1e-9_wall")
    wall = "" if sp_wall is None else f" (wall {_x(sp_wall)}{', busy machine' if busy else ''})"
    lines.append(f"speed-up at error <= 1e-9 (DOP853/fast, worst): {_x(sp)}{wall}")
    if busy:
        lines.append("WARNING: other processes loaded the machine during the run (load average above):")
        lines.append("the wall times are not representative; the CPU-time ratios stand.")
    for model, s in result["speedup_at_1e-9_by_model"].items():
        if s["speedup"] is not None:
            lines.append(
                f"  {model}: fast rtol {s['fast_rtol']:.0e} {_ms(s.get('fast_cpu_seconds_per_map'))}, "
                f"DOP853 rtol {s['dop853_rtol']:.0e} {_ms(s.get('dop853_cpu_seconds_per_map'), 1)}: "
                f"{_x(s['speedup'])}"
            )
            if s.get("speedup_wall") is not None:
                lines.append(
                    f"    wall: fast {_ms(s['fast_seconds_per_map'])}, DOP853 "
                    f"{_ms(s['dop853_seconds_per_map'], 1)}: {_x(s['speedup_wall'])}"
                )
        row = next(
            (
                r
                for r in result["rows"]
                if r["model"] == model
                and r["backend"] == "fast-dop853"
                and r["rtol"] == s["fast_rtol"]
                and "phase_nfev" in r
            ),
            None,
        )
        if row is not None:
            names = ("dlsp", "free", "clutched") if model == "er" else ("dlsp", "single")
            nf = [str(row["phase_nfev"][i]) for i in range(len(names))]
            ns = [str(row["phase_steps"][i]) for i in range(len(names))]
            lines.append(f"    per phase ({'/'.join(names)}): nfev {'/'.join(nf)}, steps {'/'.join(ns)}")
    for model, f in result["fixed_point"].items():
        cpu_f, cpu_r = f.get("fast_cpu_seconds"), f.get("reference_cpu_seconds")
        lines.append(
            f"fixed point {model}: fast {_ms(cpu_f, 1)} CPU ({f['fast_iterations']} it, "
            f"{f['fast_jacobian_method']}), reference {'-' if cpu_r is None else f'{cpu_r:.2f}'} s CPU: "
            f"{_x(f.get('ratio'))}; wall {_ms(f['fast_seconds'], 1)} / {f['reference_seconds']:.2f} s; "
            f"|dz| {f['z_difference']:.1e}, |d max|eig|| {f['max_abs_eigenvalue_difference']:.1e}"
        )
        if "at_target_error" in f:
            g = f["at_target_error"]
            lines.append(
                f"  at the map's target-error rtol {g['rtol']:.0e}, no recorded step: {_ms(g.get('cpu_seconds'), 1)} "
                f"CPU, {_ms(g['seconds'], 1)} wall ({g['iterations']} it); |dz| {g['z_difference']:.1e}, "
                f"|d max|eig|| {g['max_abs_eigenvalue_difference']:.1e} against the reference"
            )
    for model, cont in result.get("critical_slope_continuation", {}).items():
        ref = (
            "reference not timed (--quick)"
            if cont["reference_seconds"] is None
            else f"reference {cont.get('reference_cpu_seconds') or float('nan'):.1f} s CPU "
            f"({cont['reference_seconds']:.1f} s wall) -> {cont['reference_critical_slope_rad']:.7f} rad: "
            f"{_x(cont.get('ratio'))}"
        )
        fast_cpu = cont.get("fast_cpu_seconds")
        lines.append(
            f"critical slope {model}: fast {'-' if fast_cpu is None else f'{fast_cpu:.2f}'} s CPU "
            f"({cont['fast_seconds']:.2f} s wall) -> {cont['fast_critical_slope_rad']:.7f} rad "
            f"({cont['fast_reason']}, {cont['branch_points']} branch points); {ref}"
        )
    fr = result.get("guide_friction")
    if fr:
        lines.append(
            f"guide friction {fr['guide_friction_n']:g} N, one step map at rtol {fr['rtol']:.0e} "
            "(errors against scipy DOP853 at rtol 1e-13):"
        )
        for r in fr["rows"]:
            lines.append(
                f"  {r['model']}: fast {_ms(r.get('fast_cpu_seconds_per_map'), 2)} CPU (error {r['fast_error']:.1e}), "
                f"reference {_ms(r.get('reference_cpu_seconds_per_map'), 0)} CPU (error {r['reference_error']:.1e}): "
                f"{_x(r['ratio'])}; wall {_ms(r['fast_seconds_per_map'], 2)} / "
                f"{_ms(r['reference_seconds_per_map'], 0)}: {_x(r.get('ratio_wall'))}"
                f"{' (busy machine)' if busy else ''}; fast vs reference "
                f"{r['fast_vs_reference']:.1e}; friction work {r['friction_work_J']:.4g} J, errors "
                f"{r['fast_friction_work_error_J']:.0e} / {r['reference_friction_work_error_J']:.0e} J"
            )
    peer = result.get("peer") or {}
    if "rows" in peer:
        lines.append(f"peer integrator, one phase: {peer['phase']}, {peer['duration_s']:g} s")
        lines.append(f"  (nbkode's first call, compiling: {peer['peer_first_call_s']:.0f} s)")
        for r in peer["rows"]:
            cpu = r.get("cpu_seconds")
            lines.append(
                f"  {r['backend']:14} rtol {r['rtol']:6.0e} error {r['error']:8.1e} "
                f"{'-' if cpu is None else f'{cpu * 1e3:.3f}'} ms CPU, {r['seconds'] * 1e3:.3f} ms wall"
            )
    elif peer.get("skipped"):
        lines.append("peer integrator (nbkode) not run:")
        lines.append(f"  {peer['skipped']}")
    c = result["compile"]
    for label in ("cold", "warm"):
        if label in c and "first_calls_s" in c[label]:
            lines.append(
                f"compile {label}: import {c[label]['import_s']:.2f} s + first calls {c[label]['first_calls_s']:.2f} s"
                + (f" wall ({c[label]['first_calls_cpu_s']:.2f} s CPU)" if "first_calls_cpu_s" in c[label] else "")
            )
    total_cpu = result.get("total_cpu_seconds")
    lines.append(f"total {result['total_seconds']:.1f} s" + ("" if total_cpu is None else f" ({total_cpu:.1f} s CPU)"))
    return "\n".join(lines)


if __name__ == "__main__":  # python -m rimless.sim.studies.bench [--quick] [--json]
    res = run_bench("--quick" in sys.argv, progress=lambda m: print(m, file=sys.stderr))
    print(json.dumps(res, indent=1, default=str) if "--json" in sys.argv else format_table(res))


def bench_study(
    quick: bool, *, plot: Path | None = None, progress: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """`rimless bench`: run_bench and, with `plot`, the work-precision figure written atomically there."""
    result = run_bench(quick, progress)
    if plot is not None:
        from rimless.output import atomic_file

        with atomic_file(plot, option="--plot") as tmp:
            plot_work_precision(result, str(tmp))
    return result
