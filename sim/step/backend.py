"""The Poincaré map on the chosen computational path (`--backend auto|fast|reference`).

The integrator choice is rimless.sim.integrate.backend (re-exported here, so that commands import every
backend name from this one module); the map built on it is `FastPoincareMap` (rimless.sim.step.fast_map)
on the compiled path, else the reference `PoincareMap` (rimless.sim.step.poincare) with scipy's DOP853.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rimless.sim.integrate.backend import BACKENDS, DEFAULT_RTOL, make_integrator, resolve
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.params import WheelParams
from rimless.sim.step.poincare import PoincareMap

__all__ = ["BACKENDS", "DEFAULT_RTOL", "jacobian_factory", "make_integrator", "make_map", "resolve"]


def make_map(params: WheelParams, model: str, *, backend: str = "auto", rtol: float = DEFAULT_RTOL) -> PoincareMap:
    """The Poincaré map of `model` on the chosen path (atol = rtol / 100)."""
    if resolve(backend) == "fast":
        from rimless.sim.fast import FastIntegrator
        from rimless.sim.step.fast_map import FastPoincareMap

        integrator = FastIntegrator(rtol=rtol, atol=rtol * 1e-2)
        fast_map = FastPoincareMap(params, model, integrator=integrator, jacobian_with_map=True)
        return fast_map  # type: ignore[return-value]
    return PoincareMap(params, model, ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2))


def jacobian_factory(backend: str = "auto") -> Callable[[PoincareMap], Callable[[np.ndarray], np.ndarray]] | None:
    """The map-Jacobian method for a path: exact (variational) on the fast path, else central differences."""
    if resolve(backend) == "fast":
        # exact (variational equations with saltation) where the whole step is one compiled call; else (guide
        # friction, a non-ideal clutch) central differences of the map, labelled as such
        return lambda pmap: pmap.jacobian if getattr(pmap, "exact_jacobian", True) else _Central(pmap)
    return None


class _Central:
    """dP/dz by central differences of the map (FastPoincareMap.jacobian with a step)."""

    method_name = "central-difference"

    def __init__(self, pmap: PoincareMap) -> None:
        self.pmap = pmap

    def __call__(self, z: np.ndarray) -> np.ndarray:
        return self.pmap.jacobian(z, 1e-5)
