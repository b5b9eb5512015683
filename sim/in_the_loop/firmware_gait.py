"""The ER gait under the robot's own controller: its walk, fitted fixed point and energy against the ideal
clutch (`firmware_gait`), the lowest slope it still walks (`firmware_critical`) and its speed
(`firmware_bench`). Every function returns the plain dict that `--json` emits; failures are RunFailures."""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.errors import ParameterError, RunFailure
from rimless.sim.in_the_loop.ideal import ideal_fixed_point


def _f(x: Any) -> Any:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def firmware_summary(params: Any, config: Any, ideal: Any, fp: Any) -> dict[str, Any]:
    """JSON-able summary of a firmware walk and its fixed point against the ideal clutch."""
    walk = fp.walk
    ideal_stored = 0.5 * params.k * (params.leg_length_m - float(ideal.step.y_minus[3])) ** 2
    steps = walk.steps
    classes = Counter(s.lock_class for s in steps)
    late = [s.release_lateness_s for s in steps if s.release_lateness_s is not None]
    faults = [f.get("fault") for _, name, f in walk.events if name == "fault"]
    return {
        "clutch": "firmware",
        "model": "er",
        "slope_rad": params.slope_rad,
        "rate_hz": config.rate_hz,
        "engage_delay_ms": config.engage_delay_s * 1e3,
        "release_delay_ms": config.release_delay_s * 1e3,
        "noise_counts": config.noise_counts,
        "jitter_ms": config.jitter_s * 1e3,
        "holding_force_N": config.holding_force_N if math.isfinite(config.holding_force_N) else None,
        "cpi": config.cpi,
        "sensors": config.sensors,
        "seed": config.seed,
        "steps_done": len(steps),
        "ideal": {
            "theta_plus_rad": float(ideal.z[0]),
            "theta_dot_plus_rad_s": float(ideal.z[1]),
            "step_period_s": float(ideal.step.period_s),
            "stored_energy_J": ideal_stored,
            "max_abs_eigenvalue": float(np.max(np.abs(ideal.eigenvalues))),
        },
        "fixed_point": {
            "method": "linear fit z_{k+1} = A z_k + c to the walk's section points, z* = (I - A)^-1 c",
            "theta_plus_rad": _f(fp.z[0]),
            "theta_dot_plus_rad_s": _f(fp.z[1]),
            "mean_last_rad_rad_s": [_f(v) for v in fp.z_mean],
            "std_last_rad_rad_s": [_f(v) for v in fp.z_std],
            "n_average": fp.n_average,
            "eigenvalues_fitted": [[_f(e.real), _f(e.imag)] for e in fp.eigenvalues],
            "stable_fitted": fp.stable,
            "fit_residual": _f(fp.fit_residual),
            "step_period_s": fp.period_s,
            "step_period_std_s": fp.period_std_s,
            "stored_energy_J": fp.stored_energy_J,
            "stored_energy_ratio_to_ideal": fp.stored_energy_J / ideal_stored if ideal_stored > 0 else None,
        },
        "lock_classes": dict(classes),
        "release_lateness_mean_ms": float(np.mean(late)) * 1e3 if late else None,
        "energy_per_step_mean_J": {
            key: float(np.mean([getattr(s, key) for s in steps])) if steps else None
            for key in ("stored_energy_J", "damper_J", "clutch_loss_J", "recontact_loss_J", "impact_loss_J")
        },
        "energy_residual_max_J": max((abs(s.energy_residual_J) for s in steps), default=None),
        "firmware_faults": faults,
        "failure": None
        if walk.failure is None
        else {"reason": walk.failure.reason.value, "message": str(walk.failure)},
        "steps": [s.to_dict() for s in steps],
    }


def firmware_gait(
    params: Any, config: Any, *, steps: int, backend: str, rtol: float, progress: Callable[[int], None] | None = None
) -> dict[str, Any]:
    """Walk `steps` steps from the ideal-clutch fixed point with the firmware in the loop; its summary.

    progress(k): k steps done. Raises RunFailure when there is no ideal gait to start from or the walk fails
    within its first steps."""
    from rimless.sim.in_the_loop.studies import firmware_fixed_point
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.poincare import NoFixedPoint

    try:
        ideal = ideal_fixed_point(params, backend=backend, rtol=rtol)
    except (StepFailure, NoFixedPoint) as err:
        raise RunFailure(
            f"no ideal-clutch ER gait to start the firmware walk from at {params.slope_deg:.4f} deg: {err}"
        ) from None
    try:
        fp = firmware_fixed_point(params, config, ideal.z, steps=steps, n_average=min(4, steps), progress=progress)
    except StepFailure as err:
        raise RunFailure(f"the walk under the firmware failed within its first steps: {err}") from None
    return firmware_summary(params, config, ideal, fp)


def firmware_bench(params: Any, *, rates_hz: tuple[float, ...] = (300.0, 1000.0), steps: int = 3) -> dict[str, Any]:
    """Simulated steps per second with the firmware in the loop, beside the ideal clutch on the reference
    path (same start, same integrator family), and the difference of their section points."""
    from rimless.sim.in_the_loop.loop import FirmwareLoop, FirmwareLoopConfig
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section
    from rimless.sim.step.hybrid import simulate_step

    ideal = ideal_fixed_point(params, backend="reference", rtol=1e-9)
    mech = Mechanics.of(params)
    t = time.perf_counter()
    y = state_from_section(mech, ideal.z)
    for _ in range(steps):
        y = simulate_step(mech, "er", y, ScipyIntegrator(rtol=1e-9, atol=1e-11)).y_plus
    ref_s = (time.perf_counter() - t) / steps
    rows = []
    for rate, sensors in [(r, "one") for r in rates_hz] + [(rates_hz[0], "per-leg")]:
        loop = FirmwareLoop(params, FirmwareLoopConfig(rate_hz=rate, sensors=sensors))
        t = time.perf_counter()
        walk = loop.walk(ideal.z, steps)
        el = time.perf_counter() - t
        loop.close()
        done = max(len(walk.steps), 1)
        per_step = el / (done + 1)  # the priming step is simulated and sampled as well
        z_err = float(np.max(np.abs(walk.steps[0].z_end - ideal.z))) if walk.steps else float("nan")
        rows.append(
            {
                "rate_hz": rate,
                "sensors": sensors,
                "steps": len(walk.steps),
                "steps_per_s": 1.0 / per_step,
                "samples_per_step": walk.samples / (done + 1),
                "reference_ideal_steps_per_s": 1.0 / ref_s,
                "slowdown_vs_ideal": per_step / ref_s,
                "first_step_section_difference": z_err,
            }
        )
    return {"benchmark": "firmware-in-the-loop", "steps": steps, "rows": rows, "load_average": list(os.getloadavg())}


def critical_bisections(params: Any, low_deg: float, tol_deg: float) -> int:
    """Upper bound of the walks `firmware_critical` bisects with (both boundaries): the progress total."""
    return 2 * (2 + max(1, math.ceil(math.log2(max((params.slope_deg - low_deg) / tol_deg, 1.0)))))


def firmware_critical(
    params: Any,
    config: Any,
    *,
    steps: int,
    low_deg: float,
    tol_deg: float,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """The lowest slope (deg) at which the firmware keeps the wheel walking, and the mechanical boundary.

    progress(k): k walks done (at most `critical_bisections`). Raises ParameterError for a low end outside
    [0, the slope), RunFailure when the bisection has no bracket."""
    from rimless.sim.in_the_loop.studies import firmware_boundaries

    if not (math.isfinite(low_deg) and 0.0 <= low_deg < params.slope_deg):
        raise ParameterError(f"--critical-low-deg must be in [0, the slope {params.slope_deg:g} deg), got {low_deg}")
    try:
        res = firmware_boundaries(
            params, config, low_rad=math.radians(low_deg), steps=steps, tol_rad=math.radians(tol_deg), progress=progress
        )
    except ValueError as err:
        raise RunFailure(str(err)) from None
    return critical_summary(res, config, steps=steps, tol_deg=tol_deg)


def critical_summary(res: Any, config: Any, *, steps: int, tol_deg: float) -> dict[str, Any]:
    """JSON-able summary of `firmware_boundaries`: both boundaries and which one limits the wheel."""
    from rimless.sim.in_the_loop.studies import MECHANICAL_WALK_FACTOR

    fw, mech = res.firmware, res.mechanical

    def evals(r: Any) -> list[dict[str, Any]]:
        return [{"slope_deg": math.degrees(s), "walks": ok, "reason": why} for s, ok, why in r.evaluations]

    mech_deg = math.degrees(res.mechanical_slope_rad)
    return {
        "clutch": "firmware",
        "rate_hz": config.rate_hz,
        "engage_delay_ms": config.engage_delay_s * 1e3,
        "release_delay_ms": config.release_delay_s * 1e3,
        "noise_counts": config.noise_counts,
        "definition": f"lowest slope at which a walk of {steps} steps from the ideal-clutch gait completes with no "
        "failed step and no firmware fault (bisection; one boundary assumed)",
        "critical_slope_deg": math.degrees(fw.critical_slope_rad),
        "failing_slope_deg": math.degrees(fw.failing_slope_rad),
        "tolerance_deg": tol_deg,
        "reason_below": fw.reason_below,
        "limited_by": res.limited_by,
        "limit_detail": res.detail,
        "firmware_fault_below": fw.limited_by == "firmware",
        "mechanical_critical_slope_deg": mech_deg if math.isfinite(mech_deg) else None,
        "mechanical": None
        if mech is None
        else {
            "definition": f"the firmware's step-timing fail-safes relaxed (max_step_s 10 s, step_period_tolerance "
            f"0.9, max_hold_s 60 s) so that a walk ends only by the mechanics, walks "
            f"{MECHANICAL_WALK_FACTOR * steps} steps long: first at the failing slope, then bisected "
            "below it if the wheel walks there",
            "critical_slope_deg": mech_deg if math.isfinite(mech_deg) else None,
            "failing_slope_deg": math.degrees(mech.failing_slope_rad),
            "reason_below": mech.reason_below,
            "evaluations": evals(mech),
        },
        "evaluations": evals(fw),
    }
