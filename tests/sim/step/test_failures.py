"""Every step is a valid step or a classified failure; the clutch decision is a pluggable policy."""

import numpy as np
import pytest

from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.hybrid import DelayedClutch, IdealClutch, simulate_step

INTEG = ScipyIntegrator(rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(
    ("model", "k", "c", "theta_dot", "reason"),
    [
        ("er", 2700, 8, 0.3, FailureReason.STALL),  # too slow to pass mid-stance: rolls back
        ("ve", 2700, 8, 0.3, FailureReason.STALL),
        ("er", 300, 8, 2.6, FailureReason.TOUCHDOWN_BEFORE_CLUTCH),  # soft legs: still compressing at touchdown
        ("ve", 2700, 0, 2.6, FailureReason.STANCE_LIFT_OFF),  # undamped rebound lifts the stance foot
    ],
)
def test_failures_are_classified(model, k, c, theta_dot, reason):
    mech = Mechanics.of(WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c))
    with pytest.raises(StepFailure) as info:
        simulate_step(mech, model, state_from_section(mech, np.array([-0.42, theta_dot])), INTEG)
    assert info.value.reason == reason
    assert reason.value in str(info.value)


def test_strict_contact_rejects_the_leading_foot_tension_of_table_1():
    mech = Mechanics.of(WheelParams())
    y0 = state_from_section(mech, np.array([-0.465, 2.6]))
    assert simulate_step(mech, "er", y0, INTEG).period_s > 0
    with pytest.raises(StepFailure) as info:
        simulate_step(mech, "er", y0, INTEG, strict_contact=True)
    assert info.value.reason == FailureReason.LEADING_FOOT_TENSION


def test_zero_delay_clutch_is_the_ideal_clutch():
    mech = Mechanics.of(WheelParams())
    y0 = state_from_section(mech, np.array([-0.465, 2.6]))
    a = simulate_step(mech, "er", y0, INTEG, clutch=IdealClutch())
    b = simulate_step(mech, "er", y0, INTEG, clutch=DelayedClutch(0.0))
    np.testing.assert_array_equal(a.y_plus, b.y_plus)


def test_late_clutch_lock_loses_energy_and_the_budget_still_closes():
    mech = Mechanics.of(WheelParams())
    y0 = state_from_section(mech, np.array([-0.465, 2.6]))
    tight = ScipyIntegrator(rtol=1e-12, atol=1e-14)
    late = simulate_step(mech, "er", y0, tight, clutch=DelayedClutch(0.005), track_dissipation=True)
    ideal = simulate_step(mech, "er", y0, tight, track_dissipation=True)
    assert late.clutch_loss_J > 1e-4  # the leg is rebounding 5 ms after maximum compression
    assert late.phase_durations_s["slsp_free"] == pytest.approx(ideal.phase_durations_s["slsp_free"] + 0.005, abs=1e-9)
    imp = late.impact
    e0 = mech.energy(y0[:5], y0[5:])
    e1 = mech.energy(late.y_plus[:5], late.y_plus[5:])
    losses = late.dissipated_J + late.clutch_loss_J + (imp.kinetic_relabelled - imp.kinetic_plus) + imp.relabel_loss
    assert e0 - e1 == pytest.approx(losses, abs=1e-9)
