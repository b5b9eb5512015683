"""A stance-force dip between solver steps, and its truth (shared by the event-engine, contact-guard and
firmware-in-the-loop tests).

The VE fast gait at k = 2551.4 N/m (Table 1 otherwise, slope 0.05 rad) has, early in single support, a
stance normal force that dips about 4 mN below zero for about 1.3 ms: inside one solver step at rtol 1e-10
and at 1e-8, so a sign test on step ends misses it. Truth: the force sampled every 2 us along a tight
trajectory integrated without the lift-off guard.
"""

from __future__ import annotations

import numpy as np

from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import dynamics
from rimless.sim.model import guards as ev
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section

DIP_PARAMS = WheelParams(stiffness_n_per_m=2551.4)
DIP_Z = np.array([-0.4493748982626989, 3.2115968976066744])  # the VE fast gait listed by `gaits` there


def single_support_start(rtol: float = 1e-12) -> tuple[float, np.ndarray]:
    """(t s, y) at the end of double support (foot a lifts) of the step from DIP_Z."""
    mech = Mechanics.of(DIP_PARAMS)
    r1 = ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2).run_phase(
        mech, dynamics.DLSP, state_from_section(mech, DIP_Z), 0.0, (ev.LIFTOFF_A,), 5.0
    )
    assert r1.guard == ev.LIFTOFF_A
    return r1.t_end, r1.y_end


def dip_truth() -> dict[str, float]:
    """The sampled stance force along a tight single-support trajectory with the touchdown guard only:
    its minimum (N), first non-positive sample and last negative sample (s)."""
    mech = Mechanics.of(DIP_PARAMS)
    t1, y1 = single_support_start()
    tight = ScipyIntegrator(rtol=1e-12, atol=1e-14)
    r2 = tight.run_phase(mech, dynamics.SLSP_FREE, y1, t1, (ev.TOUCHDOWN,), 5.0, record_dt=2e-6)
    assert r2.guard == ev.TOUCHDOWN and r2.t is not None and r2.y is not None
    lam = np.array([dynamics.accel(mech, dynamics.SLSP_FREE, y[:5], y[5:])[1][1] for y in r2.y])
    neg = np.nonzero(lam < 0.0)[0]
    assert neg.size, "the truth trajectory must contain the dip"
    return {"min_N": float(lam.min()), "first_zero_s": float(r2.t[neg[0]]), "last_negative_s": float(r2.t[neg[-1]])}
