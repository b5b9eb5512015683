"""Numerical stress sweep of the step map: every grid point is a valid step or a classified failure.

Grid: stiffness k, damping c, slope phi, leg-to-hub mass ratio, model, and post-impact starting points.
Anything else (NaN, an unclassified exception, a runaway step count) is counted under `unclassified`
with its parameters, so that a sweep can never hide a numerical failure. `compare_with_reference` runs the
compiled map and the reference path on (part of) such a grid and counts where their outcome classes differ.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rimless.errors import interrupted_by_user
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import SPOKE_ANGLE_RAD, WheelParams

DEFAULT_K = (300.0, 1000.0, 2700.0, 1e4, 1e5, 1e6)
DEFAULT_C = (0.0, 2.0, 8.0, 100.0)
DEFAULT_SLOPES_RAD = (0.001, 0.02, 0.05, 0.15, 0.99 * SPOKE_ANGLE_RAD / 2)
DEFAULT_MASS_RATIOS = (0.002, 0.02, 0.2)
DEFAULT_STARTS = ((-0.44, 1.0), (-0.45, 2.0), (-0.43, 3.0))


def stress_sweep(
    base: WheelParams,
    *,
    k_values: Sequence[float] = DEFAULT_K,
    c_values: Sequence[float] = DEFAULT_C,
    slopes_rad: Sequence[float] = DEFAULT_SLOPES_RAD,
    mass_ratios: Sequence[float] = DEFAULT_MASS_RATIOS,
    models: Sequence[str] = ("er", "ve"),
    starts: Sequence[tuple[float, float]] = DEFAULT_STARTS,
    rtol: float = 1e-8,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Run one compiled step from every start at every grid point; count outcomes by model and reason."""
    from rimless.sim import fast

    grid = list(itertools.product(k_values, c_values, slopes_rad, mass_ratios))
    counts: dict[str, dict[str, int]] = {m: {} for m in models}
    unclassified: list[dict[str, Any]] = []
    max_steps = 0
    worst_seconds = 0.0
    t_start = time.perf_counter()
    total = len(grid)
    for i, (k, c, phi, ratio) in enumerate(grid):
        params = base.replace(
            stiffness_n_per_m=k, damping_ns_per_m=c, slope_rad=phi, leg_mass_kg=base.hub_mass_kg * ratio
        )
        for model, z in itertools.product(models, starts):
            t0 = time.perf_counter()
            key: str
            try:
                r = fast.fast_step(params, model, np.array(z, dtype=float), rtol=rtol)
                ok = bool(np.all(np.isfinite(r.y_plus)) and math.isfinite(r.period_s) and r.period_s > 0)
                key = "valid" if ok else "unclassified"
                max_steps = max(max_steps, int(r.nsteps))
                if not ok:
                    unclassified.append(
                        {
                            "k": k,
                            "c": c,
                            "slope_rad": phi,
                            "mass_ratio": ratio,
                            "model": model,
                            "start": list(z),
                            "error": "non-finite result",
                        }
                    )
            except StepFailure as err:
                key = err.reason.value
            except Exception as err:
                if interrupted_by_user(err):  # Ctrl-C inside compiled code arrives as a SystemError
                    raise KeyboardInterrupt from err
                key = "unclassified"
                unclassified.append(
                    {
                        "k": k,
                        "c": c,
                        "slope_rad": phi,
                        "mass_ratio": ratio,
                        "model": model,
                        "start": list(z),
                        "error": f"{type(err).__name__}: {err}",
                    }
                )
            worst_seconds = max(worst_seconds, time.perf_counter() - t0)
            counts[model][key] = counts[model].get(key, 0) + 1
        if progress:
            progress(i + 1, total)
    return {
        "grid": {
            "k": list(k_values),
            "c": list(c_values),
            "slope_rad": list(slopes_rad),
            "mass_ratio": list(mass_ratios),
            "models": list(models),
            "starts": [list(z) for z in starts],
        },
        "points": total * len(models) * len(starts),
        "counts": counts,
        "unclassified": unclassified,
        "max_integrator_steps": max_steps,
        "slowest_step_s": worst_seconds,
        "seconds": time.perf_counter() - t_start,
        "rtol": rtol,
    }


def compare_with_reference(
    base: WheelParams,
    *,
    k_values: Sequence[float] = (300.0, 1000.0, 2700.0, 1e4),
    c_values: Sequence[float] = DEFAULT_C,
    slopes_rad: Sequence[float] = DEFAULT_SLOPES_RAD,
    mass_ratios: Sequence[float] = DEFAULT_MASS_RATIOS,
    models: Sequence[str] = ("er", "ve"),
    starts: Sequence[tuple[float, float]] = DEFAULT_STARTS,
    rtol: float = 1e-10,
    every: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Outcome classes of the compiled map against the reference (scipy DOP853, Python right-hand side) on
    every `every`-th point of a stress grid: both valid (then the largest |dz| and |dT|) or the same failure
    reason. The default grid leaves out k >= 1e5, where the explicit reference needs minutes per step."""
    from rimless.sim import fast
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.step.poincare import PoincareMap

    grid = list(itertools.product(k_values, c_values, slopes_rad, mass_ratios, models, starts))[::every]
    agree = 0
    disagreements: list[dict[str, Any]] = []
    max_dz = 0.0
    max_dt = 0.0
    t_fast = 0.0
    t_ref = 0.0
    for i, (k, c, phi, ratio, model, z) in enumerate(grid):
        params = base.replace(
            stiffness_n_per_m=k, damping_ns_per_m=c, slope_rad=phi, leg_mass_kg=base.hub_mass_kg * ratio
        )
        zz = np.array(z, dtype=float)
        t0 = time.perf_counter()
        try:
            r = fast.fast_step(params, model, zz, rtol=rtol)
            fast_out: Any = (r.z_next, r.period_s)
        except StepFailure as err:
            fast_out = err.reason.value
        t1 = time.perf_counter()
        try:
            st = PoincareMap(params, model, ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2)).step(zz)
            ref_out: Any = (np.array([st.y_plus[2], st.y_plus[7]]), st.period_s)
        except StepFailure as err:
            ref_out = err.reason.value
        t2 = time.perf_counter()
        t_fast += t1 - t0
        t_ref += t2 - t1
        if isinstance(fast_out, tuple) and isinstance(ref_out, tuple):
            agree += 1
            max_dz = max(max_dz, float(np.max(np.abs(fast_out[0] - ref_out[0]))))
            max_dt = max(max_dt, abs(fast_out[1] - ref_out[1]))
        elif fast_out == ref_out:
            agree += 1
        else:
            disagreements.append(
                {
                    "k": k,
                    "c": c,
                    "slope_rad": phi,
                    "mass_ratio": ratio,
                    "model": model,
                    "start": list(z),
                    "fast": fast_out if isinstance(fast_out, str) else "valid",
                    "reference": ref_out if isinstance(ref_out, str) else "valid",
                }
            )
        if progress:
            progress(i + 1, len(grid))
    return {
        "points": len(grid),
        "agree": agree,
        "disagreements": disagreements,
        "max_dz_valid": max_dz,
        "max_period_difference_s": max_dt,
        "fast_seconds": t_fast,
        "reference_seconds": t_ref,
        "rtol": rtol,
    }
