"""Independent references for the continuation, sweep and paper tests of the simulator's studies.

- `er_stall_by_bisection(k)`: the ER wheel's critical slope at Table 1 (stiffness k, N/m) located by the paper's
  Algorithm 1 refined by plain bisection on the map (no pseudo-arclength, no test functions): a second method
  for what the continuation and the sweep locate with pseudo-arclength.
- `NEAR_1_26_DEG`: model.md section 9's order of magnitude of the ER and VE (medium) critical slopes at
  Table 1 ("near 1.26 deg", two significant digits, for catching gross errors only), as a bracket in deg.
- `stance_force_n(...)`: the smallest single-support stance force (N) of a VE gait under bilateral contact (the
  stance foot held), from its own fixed point and recorded step: the quantity whose sign change defines the end
  of a gait's contact-valid range.
"""

from __future__ import annotations

import functools

NEAR_1_26_DEG = (1.21, 1.31)


@functools.lru_cache(maxsize=4)
def er_stall_by_bisection(k: float = 2700.0) -> tuple[str, float]:
    """(end reason, critical slope rad) of the ER wheel at Table 1 with stiffness k, by bisection to 1e-9 rad."""
    from rimless.sim.continuation.algorithm1 import critical_slope
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import default_guess

    p = WheelParams(stiffness_n_per_m=k)
    cs = critical_slope(
        make_map(p, "er", backend="fast"), default_guess(p, "er"), method="bisection", refine_tol_rad=1e-9
    )
    return cs.reason, cs.critical_slope_rad


def stance_force_n(model: str, k: float, slope_rad: float, z_guess) -> float:
    """Smallest single-support stance force (N) of the `model` gait near `z_guess` at (k N/m, slope rad), the
    stance foot held (so the gait exists on both sides of the force's sign change)."""
    from rimless.sim.continuation.contact import contact_facts
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import bilateral_map, solve_fixed_point

    q = WheelParams(stiffness_n_per_m=k, slope_rad=slope_rad)
    held = bilateral_map(make_map(q, model, backend="fast"))
    fp = solve_fixed_point(held, z_guess)
    return contact_facts(held, fp.z).min_stance_force_single_support_N
