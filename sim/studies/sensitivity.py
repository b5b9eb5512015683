"""The gait sensitivity norm (`rimless sim sensitivity`; Hobbelen and Wisse, IEEE T-RO 2007).

Gait indicators of step k (the choice): its period T_k (s) and the theta'+ it ends with, w_{k+1} (rad/s).
Disturbances, each of unit size at step 0 only:

- "slope": step 0 is taken on the slope phi + e (rad), every later step on phi (a one-step change of slope);
- "push": theta'+ at the start of step 0 is changed by e (rad/s).

Linearised at the gait z*: x_{k+1} = A x_k + B e_k, g_k = C x_k + D e_k, with A = dP/dz (the exact map Jacobian
when given, else central differences), C = [dT/dz; A's theta'+ row] (dT/dz by central differences), and B, D
the derivatives of the step (next section point, period) with respect to the disturbance by central differences
with a checked step (the step among h0, h0/10, ... whose result changes least when the step is divided by ten;
its change is reported as the error estimate). The response to e_0 = 1 is g_0 = D, g_k = C A^(k-1) B, summed
until a term is below 1e-12 of the largest. GSN = sqrt(sum over k and indicators of g_k^2), the 2-norm of
Hobbelen and Wisse; with indicators in s and rad/s it mixes units as their definition does, so each
indicator's own norm (`gsn_by_indicator`, in s or rad/s per unit disturbance) and the norm of the indicators
relative to the gait's (T/T*, w/w*: `gsn_relative`, per unit disturbance) are reported too.

The check: the same sums from simulated finite disturbances e (the steps' deviations from the gait divided by e,
one-sided, as many steps as the linear sum used, at most 500); `relative_difference` = |simulated - linear| /
linear, which is O(e): the map's curvature. And the same from +e and -e together (the steps' (y(+e) - y(-e)) /
(2 e): `simulated_two_sided`, `relative_difference_two_sided`), whose difference from the linear norm is
O(e^2), so a wrong Jacobian shows there and the curvature does not. Measured (VE at Table 1, push on theta'+):
the one-sided difference is 14.4 % at e = 0.02 rad/s, 7.1 % at 0.01, 3.5 % at 0.005, 1.4 % at 0.002, 0.35 % at
0.0005 (7.1 per rad/s throughout), and -13.3 % at e = -0.02 (0.334 against the linear 0.385): the VE map's
second derivative in theta'+, not the Jacobians (the ER wheel: 0.2 % at 0.02).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.errors import ParameterError, RunFailure
from rimless.sim.model.failures import StepFailure

StepWithPeriod = Callable[[np.ndarray, float], tuple[np.ndarray, float]]
INDICATORS = ("step_period_s", "theta_dot_plus_rad_s")
INDICATOR_CHOICE = (
    "step k's period T_k (s) and the theta'+ it ends with (rad/s), the post-impact angular velocity of step k+1"
)


def checked_derivative(f: Callable[[float], np.ndarray], h0: float, tries: int = 5) -> tuple[np.ndarray, float, float]:
    """(df/de at 0, the step used, the error estimate) by central differences: h0, h0/10, ...; the step whose
    derivative differs least (max norm) from the next smaller step's is used."""
    hs = [h0 / 10**i for i in range(tries)]
    ders = []
    for h in hs:
        ders.append((np.asarray(f(h), dtype=float) - np.asarray(f(-h), dtype=float)) / (2 * h))
    errs = [float(np.max(np.abs(ders[i] - ders[i + 1]))) for i in range(tries - 1)]
    best = int(np.argmin(errs))
    return ders[best], hs[best], errs[best]


def _along(
    ind: Callable[[np.ndarray, float], np.ndarray], z: np.ndarray, slope: float, i: int, part: slice
) -> Callable[[float], np.ndarray]:
    """e -> part of ind(z + e * unit vector i, slope)."""

    def f(e: float) -> np.ndarray:
        return ind(z + e * np.eye(2)[i], slope)[part]

    return f


def _norms(g: np.ndarray, nominal: np.ndarray) -> dict[str, Any]:
    return {
        "gsn": float(np.sqrt(np.sum(g**2))),
        "gsn_by_indicator": {name: float(np.sqrt(np.sum(g[:, i] ** 2))) for i, name in enumerate(INDICATORS)},
        "gsn_relative": float(np.sqrt(np.sum((g / nominal) ** 2))),
    }


def _simulated_response(
    step: StepWithPeriod,
    first_step: Callable[[float], np.ndarray],
    eps: float,
    slope_rad: float,
    n: int,
    period: float,
    z1: np.ndarray,
) -> np.ndarray:
    """The first n steps' (period, theta'+) deviations from the gait after the finite disturbance eps, over eps."""
    sim = np.zeros((n, 2))
    first = first_step(eps)
    z, t = np.asarray(first[:2], dtype=float), float(first[2])
    sim[0] = [(t - period) / eps, (z[1] - z1[1]) / eps]
    for j in range(1, n):
        zn, t = step(z, slope_rad)
        z = np.asarray(zn, dtype=float)
        sim[j] = [(t - period) / eps, (z[1] - z1[1]) / eps]
    return sim


def gait_sensitivity(
    step: StepWithPeriod,
    slope_rad: float,
    z_star: Any,
    jacobian: Callable[[np.ndarray], np.ndarray] | None = None,
    *,
    push_rad_s: float = 0.02,
    slope_step_rad: float = math.radians(0.05),
    max_steps: int = 100_000,
) -> dict[str, Any]:
    """The GSN of the gait z* of `step(z, slope) -> (z_next, period_s)` for slope steps and pushes, linear and
    simulated (finite disturbances push_rad_s and slope_step_rad)."""
    for name, v in (("push_rad_s", push_rad_s), ("slope_step_rad", slope_step_rad)):
        if not (math.isfinite(v) and v != 0):
            raise ParameterError(f"{name} must be a finite number other than 0, got {v!r}")
    zs = np.asarray(z_star, dtype=float)
    try:
        z1, period = step(zs, slope_rad)
    except StepFailure as err:
        raise RunFailure(f"the gait's own step fails: {err}") from None
    z1 = np.asarray(z1, dtype=float)
    nominal = np.array([period, z1[1]])

    def ind(z: np.ndarray, s: float) -> np.ndarray:
        zn, t = step(z, s)
        return np.array([zn[0], zn[1], t])

    if jacobian is not None:
        A = np.asarray(jacobian(zs), dtype=float)
        a_method = "exact (given)"
        a_err = 0.0
    else:
        cols = [checked_derivative(_along(ind, zs, slope_rad, i, slice(0, 2)), 1e-3) for i in range(2)]
        A = np.column_stack([c[0] for c in cols])
        a_method = "central differences (checked step)"
        a_err = max(c[2] for c in cols)
    dT = [checked_derivative(_along(ind, zs, slope_rad, i, slice(2, 3)), 1e-3) for i in range(2)]
    C = np.vstack([[d[0][0] for d in dT], A[1]])
    eig = np.linalg.eigvals(A)
    if np.max(np.abs(eig)) >= 1:
        raise RunFailure(f"the gait is not stable (max |eigenvalue| {np.max(np.abs(eig)):.4f}): the GSN diverges")

    disturbances = {
        "slope": (
            lambda e: ind(zs, slope_rad + e),
            slope_step_rad,
            "rad",
            "step 0 on the slope phi + e, later steps on phi",
            math.radians(1.0),
        ),
        "push": (
            lambda e: ind(zs + np.array([0.0, e]), slope_rad),
            push_rad_s,
            "rad/s",
            "theta'+ + e before step 0",
            0.1,
        ),
    }
    out_d: dict[str, Any] = {}
    for name, (f, eps, unit, what, h0) in disturbances.items():
        der, h, fd_err = checked_derivative(f, h0)
        B, D = der[:2], np.array([der[2], der[1]])
        resp = [D]
        x = B.copy()
        peak = float(np.max(np.abs(D)))
        k = 0
        while k < max_steps:
            g = C @ x
            resp.append(g)
            peak = max(peak, float(np.max(np.abs(g))))
            x = A @ x
            k += 1
            if float(np.max(np.abs(g))) < 1e-12 * max(peak, 1e-300):
                break
        lin = np.array(resp)
        # simulated finite disturbance
        n_sim = min(len(resp), 500)
        try:
            sim = _simulated_response(step, f, eps, slope_rad, n_sim, period, z1)
            sim_minus = _simulated_response(step, f, -eps, slope_rad, n_sim, period, z1)
        except StepFailure as fail_err:
            raise RunFailure(f"the {name} disturbance of +-{eps:g} {unit} makes the wheel fail: {fail_err}") from None
        lin_n, sim_n = _norms(lin, nominal), _norms(sim, nominal)
        two_n = _norms(0.5 * (sim + sim_minus), nominal)
        out_d[name] = {
            "disturbance": what,
            "unit": unit,
            **lin_n,
            "steps_summed": len(resp),
            "fd_step": h,
            "fd_error_estimate": fd_err,
            "simulated": {"disturbance": eps, "steps": n_sim, **sim_n},
            "relative_difference": abs(sim_n["gsn"] - lin_n["gsn"]) / max(lin_n["gsn"], 1e-300),
            "simulated_two_sided": {"disturbance": eps, "steps": n_sim, **two_n},
            "relative_difference_two_sided": abs(two_n["gsn"] - lin_n["gsn"]) / max(lin_n["gsn"], 1e-300),
            "relative_difference_by_indicator": {
                k_: abs(sim_n["gsn_by_indicator"][k_] - lin_n["gsn_by_indicator"][k_])
                / max(lin_n["gsn_by_indicator"][k_], 1e-300)
                for k_ in INDICATORS
            },
        }
    return {
        "slope_rad": float(slope_rad),
        "indicators": list(INDICATORS),
        "indicator_choice": INDICATOR_CHOICE,
        "fixed_point": {
            "theta_plus_rad": float(zs[0]),
            "theta_dot_plus_rad_s": float(zs[1]),
            "step_period_s": float(period),
        },
        "map_jacobian": a_method,
        "map_jacobian_error_estimate": a_err,
        "eigenvalues": [[float(e.real), float(e.imag)] for e in eig],
        "max_abs_eigenvalue": float(np.max(np.abs(eig))),
        "slope": out_d["slope"],
        "push": out_d["push"],
    }


def sensitivity_study(
    params: Any,
    model: str,
    *,
    push_rad_s: float = 0.02,
    slope_step_deg: float = 0.05,
    backend: str = "auto",
    rtol: float = 1e-10,
) -> dict[str, Any]:
    """The GSN of the wheel's period-1 gait (found as `rimless sim fixed-point` finds it), with the exact map
    Jacobian of the compiled path (central differences on the reference path)."""
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.studies.gaits import fixed_point_study
    from rimless.sim.studies.section_map import SlopeMap

    for name, v in (("push_rad_s", push_rad_s), ("slope_step_deg", slope_step_deg)):  # before the work
        if not (math.isfinite(v) and v != 0):
            raise ParameterError(f"{name} must be a finite number other than 0, got {v!r}")
    fp = fixed_point_study(params, model, backend=backend, rtol=rtol)
    z_star = np.array([fp["theta_plus_rad"], fp["theta_dot_plus_rad_s"]])
    smap = SlopeMap(params, model, backend=backend, rtol=rtol)
    jf = jacobian_factory(backend)
    jac = None
    if jf is not None:
        pmap = make_map(params, model, backend=backend, rtol=rtol)
        jac = jf(pmap)
    out = gait_sensitivity(
        smap.step, params.slope_rad, z_star, jac, push_rad_s=push_rad_s, slope_step_rad=math.radians(slope_step_deg)
    )
    if jac is not None and getattr(pmap, "exact_jacobian", False):
        out["map_jacobian"] = "exact (variational equations with saltation, compiled path)"
    return {"model": model, "slope_deg": params.slope_deg, **out}
