"""The work behind `rimless sim gait` with the ideal clutch: N steps from the fixed point (or a given start),
the trajectory written and plotted on request; returns the command's JSON object."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rimless.errors import ParameterError, RunFailure

TRAJECTORY_SUFFIXES = (".parquet", ".csv")
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def walk_gait(
    params: Any,
    model: str,
    *,
    steps: int = 6,
    theta_dot: float | None = None,
    theta_plus_rad: float | None = None,
    theta_dot_guess: float | None = None,
    theta_plus_guess: float | None = None,
    gait: int | None = None,
    out: Path | None = None,
    plot: Path | None = None,
    forces: bool = False,
    sample_dt_s: float = 1e-3,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """`simulate_walk`, then the trajectory written to `out` and the figure to `plot` (`rimless sim gait`): both or
    neither (rimless.output.atomic_files).

    The summary's `failure` is the reason the walk ended early (None if it did not). progress(k): steps done."""
    from rimless.output import check_output_folder

    for path, exts in ((out, TRAJECTORY_SUFFIXES), (plot, FIGURE_SUFFIXES)):
        if path is not None and path.suffix.lower() not in exts:
            raise ParameterError(f"{path}: the file must end in {' or '.join(exts)}")
    for path, option in ((out, "--out"), (plot, "--plot")):  # before the work, not after
        if path is not None:
            check_output_folder(path.parent if str(path.parent) else ".", option=option)
    traj, summary = simulate_walk(
        params,
        model,
        steps=steps,
        theta_dot=theta_dot,
        theta_plus_rad=theta_plus_rad,
        theta_dot_guess=theta_dot_guess,
        theta_plus_guess=theta_plus_guess,
        gait=gait,
        forces=forces,
        sample_dt_s=sample_dt_s,
        backend=backend,
        rtol=rtol,
        progress=progress,
    )
    if traj.steps and (out is not None or plot is not None):  # no step, no file: the command fails with the reason
        from rimless.output import atomic_files

        # both under temporary names, renamed together at the end: a Ctrl-C while the figure is drawn leaves
        # no trajectory behind (nor a figure without its trajectory)
        with atomic_files((out, "--out"), (plot, "--plot")) as (out_tmp, plot_tmp):
            if out_tmp is not None:
                from rimless.sim.step.gait import write_trajectory

                write_trajectory(traj, out_tmp, {"start": summary["start"], "backend": backend, "rtol": rtol})
            if plot_tmp is not None:
                from rimless.sim.studies.figures import plot_gait, save_figure

                save_figure(plot_gait(traj, None, forces=forces), plot_tmp, option="--plot")
    summary["out"] = str(out) if out and traj.steps else None
    summary["plot"] = str(plot) if plot and traj.steps else None
    return summary


def simulate_walk(
    params: Any,
    model: str,
    *,
    steps: int = 6,
    theta_dot: float | None = None,
    theta_plus_rad: float | None = None,
    theta_dot_guess: float | None = None,
    theta_plus_guess: float | None = None,
    gait: int | None = None,
    forces: bool = False,
    sample_dt_s: float = 1e-3,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: Callable[[int], None] | None = None,
) -> tuple[Any, dict[str, Any]]:
    """Simulate `steps` steps from the fixed point, or from theta'+ = `theta_dot` rad/s (and theta+ =
    `theta_plus_rad`, default -alpha/2) just after an impact. Returns the `GaitTrajectory` and the summary
    (`rimless sim gait --json` without `out` and `plot`)."""
    import numpy as np

    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.mechanics import ALPHA
    from rimless.sim.step.backend import jacobian_factory, make_integrator, make_map
    from rimless.sim.step.gait import simulate_steps
    from rimless.sim.step.poincare import solve_fixed_point
    from rimless.sim.studies.gaits import solve_or_search, start_guess

    if theta_dot is not None:
        if not (math.isfinite(theta_dot) and theta_dot > 0):
            raise ParameterError(f"--theta-dot must be a positive angular velocity in rad/s, got {theta_dot}")
        z0 = np.array([-ALPHA / 2 if theta_plus_rad is None else theta_plus_rad, theta_dot])
        start = "given"
    else:
        pmap = make_map(params, model, backend=backend, rtol=rtol)
        jf = jacobian_factory(backend)
        guess = start_guess(
            params,
            model,
            theta_dot_guess=theta_dot_guess,
            theta_plus_guess=theta_plus_guess,
            gait=gait,
            backend=backend,
            rtol=rtol,
        )
        try:
            if theta_dot_guess is None and theta_plus_guess is None and gait is None:
                fp, _ = solve_or_search(pmap, guess, jacobian=jf(pmap) if jf else None)  # the gaits search if need be
            else:
                fp = solve_fixed_point(pmap, guess, jacobian=jf(pmap) if jf else None)
        except StepFailure as err:
            raise RunFailure(f"no fixed point to start from ({err}); give --theta-dot") from None
        z0 = fp.z
        start = "fixed point"
    traj = simulate_steps(
        params,
        model,
        z0,
        steps,
        make_integrator(backend, rtol),
        record_dt=sample_dt_s,
        forces=forces,
        progress=progress,
    )
    return traj, {
        "model": model,
        "slope_rad": params.slope_rad,
        "k": params.k,
        "c": params.c,
        "start": start,
        "theta_plus_rad": float(z0[0]),
        "theta_dot_plus_rad_s": float(z0[1]),
        "steps_done": len(traj.steps),
        "steps_requested": steps,
        "step_periods_s": [s.period_s for s in traj.steps],
        "energy_ratios": [s.impact.energy_ratio for s in traj.steps],
        "guide_friction_n": params.guide_friction_n,
        "friction_work_per_step_j": [s.friction_work_J for s in traj.steps],
        "failure": None
        if traj.failure is None
        else {"reason": traj.failure.reason.value, "message": str(traj.failure)},
    }
