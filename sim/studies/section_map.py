"""The Poincaré map as a function of the section point and the slope, P(z, slope_rad), for the robustness studies
(basin of attraction, gait sensitivity, mean first-passage time on rough terrain).

The studies take any callable `step_map(z, slope_rad) -> z_next` (a numpy array (theta+ rad, theta'+ rad/s))
that raises `StepFailure` for a failed step; the GSN also uses `step(z, slope_rad) -> (z_next, period_s)`.
`SlopeMap` is that callable for one compliant wheel. On the compiled path it calls the step kernel with the
slope put into the parameter vector, so one object serves every slope, and a slope below 0 (an uphill step on
rough terrain, outside WheelParams' range 0 <= slope < alpha/2, which is the range of period-1 gaits) is a
step like any other: gravity is g (sin phi, -cos phi) for any phi. For a slope in WheelParams' range it is the
map of `Wheel.with_params(slope_rad=...)` (the same kernel; a phase too stiff for the explicit integrator is
recomputed by that map's implicit fallback). On the reference path (scipy) only slopes in that range exist.

Rough-terrain convention: each step is taken on one plane of slope phi_k, and the section point carries over
from step to step unchanged (theta is measured from the normal of the plane the step is on). This is the
convention of Byl and Tedrake's rimless wheel on rough terrain (the map w_{n+1} = f(w_n, gamma_n)).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.errors import ParameterError
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.params import SPOKE_ANGLE_RAD, WheelParams

StepMap = Callable[[np.ndarray, float], np.ndarray]

#: fates of a section point that are not a failure of a step
GAIT = "gait"
OTHER_GAIT = "other-gait"
UNDECIDED = "undecided"
FATES: tuple[str, ...] = (GAIT, OTHER_GAIT, UNDECIDED, *(r.value for r in FailureReason if r.value != "no-convergence"))


def failure_fate(err: BaseException) -> str:
    """The fate of a failed step: its FailureReason's value (integration-failure for anything unclassified)."""
    reason = getattr(err, "reason", None)
    return reason.value if isinstance(reason, FailureReason) else FailureReason.INTEGRATION.value


def apply(step_map: StepMap, z: np.ndarray, slope_rad: float) -> np.ndarray:
    """step_map(z, slope); a non-finite result is an integration failure (never a value)."""
    zn = np.asarray(step_map(z, slope_rad), dtype=float)
    if zn.shape != (2,) or not np.all(np.isfinite(zn)):
        raise StepFailure(FailureReason.INTEGRATION, f"the map returned {zn!r}")
    return zn


class SlopeMap:
    """P(z, slope_rad) and the step period of one compliant wheel (model "er" or "ve") at any slope."""

    def __init__(self, params: WheelParams, model: str, *, backend: str = "auto", rtol: float = 1e-10) -> None:
        from rimless.sim.step.backend import resolve

        self.params = params
        self.model = model
        self.backend = backend
        self.rtol = float(rtol)
        self.fast = resolve(backend) == "fast" and params.guide_friction_n == 0.0
        self._maps: dict[float, Any] = {}
        self.evaluations = 0
        if self.fast:
            from rimless.sim.fast import MAX_STEPS, mass_model_index, param_vector

            self._max_steps = int(MAX_STEPS)

            self._p = param_vector(params)
            self._mi = mass_model_index(params)
            self._counts = np.zeros((3, 2), dtype=np.int64)

    def _map_at(self, slope_rad: float) -> Any:
        """The map of the wheel with this slope (a valid WheelParams slope), built once per slope."""
        pm: Any = self._maps.get(slope_rad)
        if pm is None:
            from rimless.sim.step.backend import make_map

            if not 0.0 <= slope_rad < SPOKE_ANGLE_RAD / 2:
                raise ParameterError(
                    f"a step on the slope {slope_rad:.6g} rad (outside [0, alpha/2)) needs the compiled path "
                    "(backend 'auto' or 'fast', no guide friction)"
                )
            if len(self._maps) > 64:
                self._maps.clear()
            pm = make_map(self.params.replace(slope_rad=slope_rad), self.model, backend=self.backend, rtol=self.rtol)
            pm.jacobian_with_map = False
            self._maps[slope_rad] = pm
        return pm

    def step(self, z: np.ndarray, slope_rad: float) -> tuple[np.ndarray, float]:
        """(z_next, period_s) of one step from z on the slope; raises StepFailure."""
        self.evaluations += 1
        slope_rad = float(slope_rad)
        z = np.asarray(z, dtype=np.float64).reshape(2)
        if not (math.isfinite(slope_rad) and abs(slope_rad) < SPOKE_ANGLE_RAD / 2):
            raise ParameterError(f"slope must be finite with |slope| < alpha/2, got {slope_rad!r} rad")
        if not self.fast:
            pm = self._map_at(slope_rad)
            res = pm.step(z)
            from rimless.sim.model.section import section_from_state

            return section_from_state(res.y_plus), float(res.period_s)
        from rimless.sim.fast import raise_failure
        from rimless.sim.fast import step as fs

        p = self._p.copy()
        p[7] = slope_rad
        atol = self.rtol * 1e-2
        st, detail, phase, t, yp, _J, _times, _nfev, nsteps, _nstiff, _snap = fs.step_map(
            self._mi, self.model == "er", p, z, self.rtol, atol, False, self._max_steps, self._counts
        )
        if st == fs.TOO_MANY_STEPS and 0.0 <= slope_rad < SPOKE_ANGLE_RAD / 2:
            zn, period, _ = self._map_at(slope_rad).evaluate(z)  # the map's implicit fallback
            return np.asarray(zn, dtype=float), float(period)
        if st != fs.OK:
            raise_failure(st, detail, phase, t, nsteps)
        return np.array([yp[2], yp[7]]), float(t)

    def __call__(self, z: np.ndarray, slope_rad: float) -> np.ndarray:
        return self.step(z, slope_rad)[0]
