"""Choosing the integrator: the compiled fast path when available, else the scipy reference.

Commands ask for a backend by name: `fast` (numba, rimless.sim.fast), `reference` (scipy's DOP853 with a
Python right-hand side) or `auto` (fast if it imports). The Poincaré map on the chosen path is built one
layer up, by rimless.sim.step.backend (`make_map`, `jacobian_factory`), which re-exports these names.
"""

from __future__ import annotations

from types import ModuleType

from rimless.errors import ParameterError
from rimless.sim.integrate.reference import Integrator, ScipyIntegrator

BACKENDS = ("auto", "fast", "reference")
DEFAULT_RTOL = 1e-10


def fast_module() -> ModuleType | None:
    """rimless.sim.fast if the compiled path imports in this install, else None."""
    try:
        from rimless.sim import fast
    except ImportError:
        return None
    return fast if hasattr(fast, "FastIntegrator") else None


def resolve(backend: str) -> str:
    """`fast` or `reference` for a backend name (`auto` picks fast when it imports); ParameterError otherwise."""
    if backend not in BACKENDS:
        raise ParameterError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "auto":
        return "fast" if fast_module() is not None else "reference"
    if backend == "fast" and fast_module() is None:
        raise ParameterError("--backend fast: the compiled path is not available in this install")
    return backend


def make_integrator(backend: str = "auto", rtol: float = DEFAULT_RTOL) -> Integrator:
    """An integrator for trajectory recording (phase by phase); atol = rtol / 100."""
    if resolve(backend) == "fast":
        fast = fast_module()
        assert fast is not None  # resolve() picks fast only when it imports
        return fast.FastIntegrator(rtol=rtol, atol=rtol * 1e-2)
    return ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2)
