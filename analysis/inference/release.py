"""The release of a trial's walk: the model's state at the first measured impact.

A walk is simulated from the rigid-touchdown state theta = -alpha/2 with speed theta' one step before the first
measured impact (a hand release, or any earlier step, ends in such a touchdown). The post-impact section is
two-dimensional (model.md section 6), so that speed and the first measured impact's post-impact angle, moved by
an offset from where the release puts it (``first_angle_offset_rad``, within +-`FIRST_ANGLE_RANGE_RAD`), hold any
state of the model there: a wheel held in its rigid pose and pushed (offset 0) and one released into its gait,
whose stance leg was compressed at the touchdown before (an ER wheel's gait lies 0.05-0.10 rad lower). The offset
shows mostly in the first period (the fast multiplier of the section map is 0.05-0.12 on ER wheels), the speed in
the approach to the gait. Used by `rimless.analysis.inference.calibrate` (`_ReleaseFit.fit_first_angle`) and
`rimless.analysis.inference.compare` (`fit_first_angle_offset`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["FIRST_ANGLE_RANGE_RAD", "fit_first_angle", "map_frequencies", "walk_from_release"]

#: the range of the first measured impact's post-impact angle about the rigid-touchdown release's (rad)
FIRST_ANGLE_RANGE_RAD = 0.1
RELEASE_SPEED_BOUNDS_RAD_S = (0.05, 20.0)


def fit_first_angle(
    freq_res: Callable[[float, float], np.ndarray],
    f_meas: np.ndarray,
    w0: float,
    offsets: tuple[float, ...] = (0.0,),
) -> tuple[float, float, float] | None:
    """(offset rad, release theta' rad/s, cost Hz^2): least squares on the step-frequency residuals
    ``freq_res(offset, w)`` (simulated minus ``f_meas``, Hz; a step not reached has frequency 0) in (offset, w)
    from (a, ``w0``) for each start offset a of ``offsets`` (clipped to the range), the lowest cost kept; None when
    no start walks (least squares would see a flat cost there)."""
    from scipy.optimize import least_squares

    lo, hi = -FIRST_ANGLE_RANGE_RAD, FIRST_ANGLE_RANGE_RAD
    w_lo, w_hi = RELEASE_SPEED_BOUNDS_RAD_S
    best: tuple[float, float, float] | None = None
    for a0 in dict.fromkeys(min(max(a, lo), hi) for a in offsets):
        r0 = freq_res(a0, w0)
        if not np.all(r0 + f_meas > 0):
            continue  # the start does not walk
        r = least_squares(
            lambda q: freq_res(float(q[0]), float(q[1])), [a0, w0], bounds=([lo, w_lo], [hi, w_hi]), method="trf",
            diff_step=[1e-5, 1e-5], x_scale=[0.01, 0.01 * w0], xtol=1e-8, ftol=1e-10, max_nfev=40,
        )  # fmt: skip
        if best is None or 2 * r.cost < best[2]:
            best = (float(r.x[0]), float(r.x[1]), float(2 * r.cost))
    return best


def map_frequencies(p: Any, model: str, w: float, n: int, offset: float, rtol: float) -> np.ndarray:
    """Step frequencies (1/s) of the n steps after the release step from (-alpha/2, ``w``) on the wheel ``p``
    (its slope included), the post-impact angle after the release step moved by ``offset`` (rad), on the compiled
    step map (phase by phase with guide friction); 0 for steps not reached (the wheel stalled or a step failed)."""
    from rimless.analysis.io.trial import ALPHA_RAD
    from rimless.sim.fast import fast_step
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.fast_map import friction_step

    z = np.array([-ALPHA_RAD / 2, w])
    out = np.zeros(n)
    step = fast_step if p.guide_friction_n == 0.0 else friction_step
    try:
        for k in range(n + 1):
            r = step(p, model, z, rtol=rtol)
            if k:
                out[k - 1] = 1.0 / r.period_s
            z = r.z_next + np.array([offset if k == 0 else 0.0, 0.0])
    except StepFailure:
        pass
    return out


def walk_from_release(
    p: Any, model: str, w: float, n_steps: int, integrator: Any, record_dt: float, offset: float
) -> Any:
    """`simulate_steps` of ``n_steps`` from the release (-alpha/2, ``w``) on the wheel ``p``, the post-impact angle
    after the first step moved by ``offset`` (rad; the state rebuilt from its section, model.md section 6): one
    walk (times and step numbers continuous), as `simulate_steps` returns it; that walk itself at offset 0."""
    from rimless.analysis.io.trial import ALPHA_RAD
    from rimless.sim.step.gait import GaitTrajectory, simulate_steps

    z0 = np.array([-ALPHA_RAD / 2, w])
    first = simulate_steps(p, model, z0, 1 if offset else n_steps, integrator, record_dt=record_dt)
    if not offset or first.failure is not None or n_steps <= 1:
        return first
    y = first.steps[0].y_plus
    rest = simulate_steps(p, model, np.array([y[2] + offset, y[7]]), n_steps - 1, integrator, record_dt=record_dt)
    t1 = first.steps[0].period_s
    steps = first.steps + [dataclasses.replace(s, t_start_s=s.t_start_s + t1) for s in rest.steps]
    table = {}
    for name, col in first.table.items():
        later = rest.table[name]
        later = later + t1 if name == "t_s" else (later + 1 if name == "step" else later)
        table[name] = np.concatenate([col, later])
    return GaitTrajectory(p, model, steps, table, rest.failure)
