"""Energy: conserved in every phase without damping; the per-step budget closes with damping."""

import math

import numpy as np
import pytest

from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.hybrid import simulate_step

TIGHT = ScipyIntegrator(rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("model", ["er", "ve"])
def test_energy_conserved_within_each_phase_without_damping(model):
    p = WheelParams(damping_ns_per_m=0.0)
    mech = Mechanics.of(p)
    # without damping the VE stance leg bounces hard: from theta'+ = 2.6 rad/s the stance foot hops
    # (a classified stance-lift-off), so the VE step starts slower
    z = np.array([-0.46, 2.6]) if model == "er" else np.array([-0.43, 2.0])
    res = simulate_step(mech, model, state_from_section(mech, z), TIGHT, record_dt=5e-3)
    assert res.segments, "the step recorded no phase"
    for seg in res.segments:
        energies = np.array([mech.energy(y[:5], y[5:]) for y in seg.y])
        scale = mech.kinetic(seg.y[0][:5], seg.y[0][5:])
        drift = np.max(np.abs(energies - energies[0])) / scale
        assert drift <= 1e-9, f"phase {seg.phase}: relative energy drift {drift:.2e}"


@pytest.mark.parametrize("model", ["er", "ve"])
@pytest.mark.parametrize("c", [8.0, 40.0])
def test_step_energy_budget_closes(model, c):
    """E(start) - E(end) = damping + impact + relabelling losses, to 1e-9 J."""
    p = WheelParams(damping_ns_per_m=c)
    mech = Mechanics.of(p)
    y0 = state_from_section(mech, np.array([-0.46, 2.6]))
    res = simulate_step(mech, model, y0, TIGHT, track_dissipation=True)
    imp = res.impact
    e_start = mech.energy(y0[:5], y0[5:])
    e_end = mech.energy(res.y_plus[:5], res.y_plus[5:])
    impact_loss = imp.kinetic_relabelled - imp.kinetic_plus
    assert impact_loss > 0 and res.dissipated_J > 0
    assert e_start - e_end == pytest.approx(res.dissipated_J + impact_loss + imp.relabel_loss, abs=1e-9)


def test_gravity_input_balances_losses_at_the_fixed_point(er_fixed_point):
    """On the periodic gait every mass drops by s sin(phi): gravity input = all losses (eight-leg)."""
    pmap, fp = er_fixed_point
    p = pmap.params
    mech = Mechanics.of(p)
    y0 = state_from_section(mech, fp.z)
    res = simulate_step(mech, "er", y0, TIGHT, track_dissipation=True)
    step_length = res.y_plus[0] - y0[0]  # the new stance foot's position along the slope, m
    gravity_input = p.total_mass_kg * p.gravity_m_s2 * step_length * math.sin(p.slope_rad)
    imp = res.impact
    losses = res.dissipated_J + (imp.kinetic_relabelled - imp.kinetic_plus) + imp.relabel_loss
    assert gravity_input == pytest.approx(losses, abs=1e-9)
    # the relabelling loss is tiny: the free trailing leg has settled long before touchdown
    assert 0 <= imp.relabel_loss < 1e-3 * losses
