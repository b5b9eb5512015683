"""A period-1 gait checked apart from the gait search and the continuation: P(z) = z solved by scipy's `root`
(Powell hybrid) on the reference integrator's map (solve_ivp, not the compiled kernels), its Jacobian by central
differences of that map, and its contact facts from the recorded step. Used to confirm gaits the sweep reports
(e.g. issue 33's VE "medium" gait at k = 2000 N/m, slope 0.0228 rad, max|eig| 0.572)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class CheckedGait:
    z: np.ndarray  # (theta+ rad, theta'+ rad/s) on the post-impact section
    residual: float  # max |P(z) - z|
    max_abs_eigenvalue: float
    period_s: float
    min_stance_force_N: float  # smallest single-support stance normal force
    min_impulse_N_s: float


def check_gait(model: str, k: float, slope_rad: float, z_guess, *, rtol: float = 1e-10) -> CheckedGait:
    """Solve P(z) = z near z_guess for the `model` wheel at Table 1 with stiffness k (N/m) on slope_rad."""
    from scipy.optimize import root

    from rimless.sim.continuation.contact import contact_facts
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_map

    pmap = make_map(WheelParams(stiffness_n_per_m=k, slope_rad=slope_rad), model, backend="reference", rtol=rtol)
    sol = root(
        lambda z: pmap(np.asarray(z, dtype=float)) - z,
        np.asarray(z_guess, dtype=float),
        method="hybr",
        options={"xtol": 1e-12},
    )
    z = np.asarray(sol.x, dtype=float)
    residual = float(np.max(np.abs(pmap(z) - z)))
    h = 1e-6
    J = np.column_stack([(pmap(z + h * e) - pmap(z - h * e)) / (2 * h) for e in np.eye(2)])
    facts = contact_facts(pmap, z, 5e-4)
    return CheckedGait(
        z,
        residual,
        float(np.max(np.abs(np.linalg.eigvals(J)))),
        pmap.step(z).period_s,
        facts.min_stance_force_single_support_N,
        facts.min_impulse_N_s,
    )
