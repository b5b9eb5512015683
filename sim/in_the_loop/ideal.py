"""The ideal-clutch ER fixed point every firmware walk starts from (and is compared with)."""

from __future__ import annotations

from typing import Any


def ideal_fixed_point(params: Any, *, backend: str, rtol: float) -> Any:
    """The ideal-clutch ER fixed point (rimless.sim.step.poincare.FixedPoint) from the default guess."""
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.step.poincare import default_guess, solve_fixed_point

    pmap = make_map(params, "er", backend=backend, rtol=rtol)
    jf = jacobian_factory(backend)
    return solve_fixed_point(pmap, default_guess(params, "er"), jacobian=jf(pmap) if jf else None)
