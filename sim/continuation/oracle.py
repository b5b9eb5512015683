"""The Poincaré map as the continuation sees it: P(z; p) and its Jacobian for one wheel parameter p
(`MapOracle`), and the parameters a branch can be continued in (`PARAMETERS`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.params import WheelParams

# parameter name -> (WheelParams field, typical size used to scale it, unit)
PARAMETERS: dict[str, tuple[str, float, str]] = {
    "slope": ("slope_rad", 0.01, "rad"),
    "k": ("stiffness_n_per_m", 1000.0, "N/m"),
    "c": ("damping_ns_per_m", 5.0, "N s/m"),
    "hub_mass": ("hub_mass_kg", 1.0, "kg"),
    "leg_mass": ("leg_mass_kg", 0.02, "kg"),
    "inertia": ("inertia_kg_m2", 0.02, "kg m^2"),
}


class MapOracle:
    """P(z; p), J_z and F_p = dP/dp for one base parameter set; counts map evaluations.

    `map_factory(params)` gives a Poincaré map (recorded steps for the contact facts, and the map itself on
    the reference path). A map with `integrator.rtol` and a compiled `evaluate` is evaluated through
    rimless.sim.fast.fast_step directly, without building a map object per parameter value (not with guide
    friction, which fast_step does not model: its maps step phase by phase).
    """

    def __init__(
        self, map_factory: Callable[[WheelParams], Any], base: WheelParams, parameter: str, model: str
    ) -> None:
        if parameter not in PARAMETERS:
            raise ValueError(f"unknown continuation parameter {parameter!r}; known: {', '.join(PARAMETERS)}")
        self.field, self.scale, self.unit = PARAMETERS[parameter]
        self.map_factory = map_factory
        self.base = base
        self.model = model
        self.evaluations = 0
        self._maps: dict[float, Any] = {}
        self._params: dict[float, WheelParams] = {}
        probe = map_factory(base)
        # guide friction: the map runs phase by phase (its stick/slip phases), not through fast_step
        self.compiled = (
            hasattr(probe, "evaluate") and getattr(probe, "clutch", None) is None and base.guide_friction_n == 0.0
        )
        self.rtol = float(getattr(getattr(probe, "integrator", None), "rtol", 1e-10))
        self.atol = float(getattr(getattr(probe, "integrator", None), "atol", self.rtol * 1e-2))
        self.bilateral = bool(getattr(probe, "bilateral", False))

    def pmap(self, p: float) -> Any:
        m = self._maps.get(p)
        if m is None:
            if len(self._maps) > 16:
                self._maps.clear()
            m = self.map_factory(self.params(p))
            self._maps[p] = m
        return m

    def params(self, p: float) -> WheelParams:
        q = self._params.get(p)
        if q is None:
            if len(self._params) > 256:
                self._params.clear()
            q = self.base.replace(**{self.field: float(p)})
            self._params[p] = q
        return q

    def evaluate(self, z: np.ndarray, p: float, *, jacobian: bool) -> tuple[np.ndarray, float, np.ndarray | None]:
        """(P(z), period_s, dP/dz or None); raises StepFailure (a parameter out of range is a StepFailure too)."""
        try:
            params = self.params(p)
        except ValueError as err:  # ParameterError: the continuation left the valid parameter range
            raise StepFailure(FailureReason.NO_CONVERGENCE, f"parameter out of range: {err}") from None
        self.evaluations += 1
        z = np.asarray(z, dtype=float)
        if not np.all(np.isfinite(z)):
            raise StepFailure(FailureReason.INTEGRATION, "non-finite section point")
        if self.compiled:
            from rimless.sim import fast

            r = fast.fast_step(
                params,
                self.model,
                z,
                rtol=self.rtol,
                atol=self.atol,
                jacobian=jacobian,
                bilateral=self.bilateral,
                record_contact=False,
            )
            zn, period, J = r.z_next, r.period_s, r.jacobian
        else:
            from rimless.sim.model.section import section_from_state

            m = self.pmap(p)
            step = m.step(z)
            zn, period, J = section_from_state(step.y_plus), step.period_s, (m.jacobian(z) if jacobian else None)
        if not np.all(np.isfinite(zn)) or not math.isfinite(period) or (J is not None and not np.all(np.isfinite(J))):
            raise StepFailure(FailureReason.INTEGRATION, "the map returned a non-finite value")
        return zn, period, J
