"""Choosing the computational path: the compiled fast path when available, else the scipy reference.

Commands ask for a backend by name: `fast` (numba, rimless.sim.fast), `reference` (solve_ivp DOP853 with
a Python right-hand side) or `auto` (fast if it imports).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rimless.errors import ParameterError
from rimless.sim.integrate.reference import Integrator, ScipyIntegrator
from rimless.sim.model.params import WheelParams
from rimless.sim.step.poincare import PoincareMap

BACKENDS = ("auto", "fast", "reference")
DEFAULT_RTOL = 1e-10


def _fast_module():  # noqa: ANN202
    try:
        from rimless.sim import fast
    except ImportError:
        return None
    return fast


def resolve(backend: str) -> str:
    if backend not in BACKENDS:
        raise ParameterError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "auto":
        return "fast" if _fast_module() is not None and hasattr(_fast_module(), "FastPoincareMap") else "reference"
    if backend == "fast" and (_fast_module() is None or not hasattr(_fast_module(), "FastPoincareMap")):
        raise ParameterError("--backend fast: the compiled path is not available in this install")
    return backend


def make_integrator(backend: str = "auto", rtol: float = DEFAULT_RTOL) -> Integrator:
    """An integrator for trajectory recording (phase by phase)."""
    if resolve(backend) == "fast":
        return _fast_module().FastIntegrator(rtol=rtol, atol=rtol * 1e-2)  # type: ignore[union-attr]
    return ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2)


def make_map(params: WheelParams, model: str, *, backend: str = "auto", rtol: float = DEFAULT_RTOL) -> PoincareMap:
    """The Poincaré map of `model` on the chosen path."""
    if resolve(backend) == "fast":
        fast = _fast_module()
        integrator = fast.FastIntegrator(rtol=rtol, atol=rtol * 1e-2)  # type: ignore[union-attr]
        return fast.FastPoincareMap(params, model, integrator=integrator, jacobian_with_map=True)  # type: ignore[union-attr]
    return PoincareMap(params, model, ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2))


def jacobian_factory(backend: str = "auto") -> Callable[[PoincareMap], Callable[[np.ndarray], np.ndarray]] | None:
    """The map-Jacobian method for a path: exact (variational) on the fast path, else central differences."""
    if resolve(backend) == "fast":
        return lambda pmap: pmap.jacobian  # exact: variational equations with saltation
    return None
