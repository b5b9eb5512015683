"""Events land on their guards, and results converge as the tolerance tightens."""

import numpy as np
import pytest

from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import guards as ev
from rimless.sim.model.dynamics import DLSP, SLSP_CLUTCHED, SLSP_FREE
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import section_from_state, state_from_section
from rimless.sim.step.hybrid import simulate_step

PHASE_END_GUARD = {
    "dlsp": (DLSP, ev.LIFTOFF_A),
    "slsp_free": (SLSP_FREE, ev.CLUTCH_LOCK),
    "slsp_clutched": (SLSP_CLUTCHED, ev.TOUCHDOWN),
}


@pytest.mark.parametrize("model", ["er", "ve"])
def test_phase_ends_lie_on_their_guards(model):
    mech = Mechanics.of(WheelParams())
    res = simulate_step(
        mech,
        model,
        state_from_section(mech, np.array([-0.46, 2.6])),
        ScipyIntegrator(rtol=1e-10, atol=1e-12),
        record_dt=1e-2,
    )
    for seg, rec in zip(res.segments, res.phases, strict=True):
        phase, guard = PHASE_END_GUARD[rec.name]
        if model == "ve" and rec.name == "slsp_free":
            guard = ev.TOUCHDOWN
        value = ev.guard_value(mech, phase, guard, seg.y[-1])
        assert abs(value) <= 1e-10, f"{rec.name} ends {value:.2e} off its guard"
    assert abs(ev.guard_value(mech, SLSP_CLUTCHED, ev.TOUCHDOWN, res.y_minus)) <= 1e-10


def test_results_converge_as_tolerance_tightens():
    mech = Mechanics.of(WheelParams())
    y0 = state_from_section(mech, np.array([-0.46, 2.6]))
    outs = {}
    for rtol in (1e-6, 1e-8, 1e-10, 1e-12):
        r = simulate_step(mech, "er", y0, ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2))
        outs[rtol] = np.concatenate((section_from_state(r.y_plus), [r.period_s]))
    ref = outs[1e-12]
    errs = [np.max(np.abs(outs[t] - ref)) for t in (1e-6, 1e-8, 1e-10)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-8
