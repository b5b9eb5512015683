"""Guide friction on the compiled path: it agrees with the reference path (rimless.sim.integrate.reference,
itself checked against closed forms in tests/sim/integrate/test_friction.py), the energy budget of a periodic
gait closes with the friction work, and F_c = 0 leaves the one-call compiled step as it was."""

import math

import numpy as np
import pytest

from rimless.sim.fast import FastIntegrator, fast_step
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import section_from_state, state_from_section
from rimless.sim.step.backend import jacobian_factory, make_map
from rimless.sim.step.fast_map import friction_step
from rimless.sim.step.hybrid import simulate_step
from rimless.sim.step.poincare import PoincareMap, solve_fixed_point

Z = np.array([-0.46, 2.6])


@pytest.mark.parametrize("model", ["er", "ve"])
@pytest.mark.parametrize("F", [0.5, 3.0])
def test_compiled_step_with_friction_agrees_with_the_reference(model, F):
    mech = Mechanics.of(WheelParams(guide_friction_n=F))
    y0 = state_from_section(mech, Z)
    a = simulate_step(mech, model, y0, ScipyIntegrator(rtol=1e-11, atol=1e-13), track_dissipation=True)
    b = simulate_step(mech, model, y0, FastIntegrator(rtol=1e-11, atol=1e-13), track_dissipation=True)
    assert np.max(np.abs(a.y_plus - b.y_plus)) < 1e-8
    assert b.period_s == pytest.approx(a.period_s, abs=1e-10)
    assert b.friction_work_J == pytest.approx(a.friction_work_J, abs=1e-10) and b.friction_work_J > 0
    assert b.dissipated_J == pytest.approx(a.dissipated_J, abs=1e-10)
    assert np.allclose(b.stick_s, a.stick_s, atol=1e-8)
    assert [p.name for p in a.phases] == [p.name for p in b.phases]


def test_compiled_single_leg_matches_the_closed_form():
    from rimless.sim.integrate.friction import run_with_friction
    from rimless.sim.model.dynamics import SLSP_CLUTCHED
    from tests.support import friction_leg

    F, x0 = 1.0, 0.004
    p = WheelParams(mass_model="sliding-leg", damping_ns_per_m=0.0, slope_rad=0.0, guide_friction_n=F)
    mech = Mechanics.of(p)
    y0 = np.zeros(10)
    y0[3], y0[4] = p.leg_length_m, p.leg_length_m + x0
    w = math.sqrt(p.k / p.leg_mass_kg)
    t_end = 12 * math.pi / w
    run = run_with_friction(
        FastIntegrator(rtol=1e-12, atol=1e-14), mech, SLSP_CLUTCHED, y0, 0.0, (), t_end, record_dt=t_end / 2000
    )
    truth = friction_leg.position(run.t, x0, p.k, p.leg_mass_kg, F)
    assert np.max(np.abs(run.y[:, 4] - p.leg_length_m - truth)) < 1e-9
    tps = friction_leg.turning_points(x0, p.k, F)
    assert run.stick_s[1] == pytest.approx(t_end - (len(tps) - 1) * math.pi / w, abs=1e-6)


# Regression snapshot: fast_step(Table 1, model, z = (-0.46, 2.6)).z_next computed with the code before guide
# friction existed (commit c503cc9); F_c = 0 must reproduce it bit for bit.
BEFORE = {
    "er": ["-0x1.db977945fa16ap-2", "0x1.4a4fc7a36d96fp+1"],
    "ve": ["-0x1.99addd2eab2abp-2", "0x1.5a24e7506bfe3p+1"],
}


@pytest.mark.parametrize("model", ["er", "ve"])
def test_zero_friction_compiled_step_is_bit_identical_to_before(model):
    r = fast_step(WheelParams(guide_friction_n=0.0), model, Z, jacobian=True)
    assert [float(v).hex() for v in r.z_next] == BEFORE[model]


def test_friction_step_is_the_hybrid_step_and_slower_friction_lowers_speed():
    r0 = friction_step(WheelParams(guide_friction_n=0.5), "er", Z)
    assert r0.friction_work_J > 0
    r1 = friction_step(WheelParams(guide_friction_n=2.0), "er", Z)
    assert r1.z_next[1] < r0.z_next[1]  # more friction, less speed after the step


@pytest.fixture(scope="module")
def er_friction_fixed_point():
    p = WheelParams(guide_friction_n=0.5)
    pmap = make_map(p, "er", backend="fast", rtol=1e-11)
    jac = jacobian_factory("fast")(pmap)
    return pmap, solve_fixed_point(pmap, np.array([-0.463, 2.53]), jacobian=jac, diagnostics=True)


def test_gravity_input_balances_losses_with_friction_at_the_fixed_point(er_friction_fixed_point):
    """On the periodic gait: gravity input = damper + friction + impact + relabelling losses."""
    pmap, fp = er_friction_fixed_point
    assert fp.jacobian_method == "variational"  # variational equations through stick/slip (rimless.sim.fast.friction)
    p = pmap.params
    mech = Mechanics.of(p)
    y0 = state_from_section(mech, fp.z)
    res = simulate_step(mech, "er", y0, FastIntegrator(rtol=1e-12, atol=1e-14), track_dissipation=True)
    assert np.max(np.abs(section_from_state(res.y_plus) - fp.z)) < 1e-9
    step_length = res.y_plus[0] - y0[0]
    gravity_input = p.total_mass_kg * p.gravity_m_s2 * step_length * math.sin(p.slope_rad)
    imp = res.impact
    losses = res.dissipated_J + res.friction_work_J + (imp.kinetic_relabelled - imp.kinetic_plus) + imp.relabel_loss
    assert gravity_input == pytest.approx(losses, abs=1e-9)
    assert res.friction_work_J > 0.05 * losses  # friction is a visible part of the budget at 0.5 N (7.7 %)
    assert fp.stable


@pytest.mark.slow
def test_reference_and_compiled_fixed_points_with_friction_agree(er_friction_fixed_point):
    _, fp = er_friction_fixed_point
    ref = solve_fixed_point(
        PoincareMap(WheelParams(guide_friction_n=0.5), "er", ScipyIntegrator(rtol=1e-11, atol=1e-13)),
        fp.z,
        record=False,
    )
    assert np.max(np.abs(ref.z - fp.z)) < 1e-8
    assert np.max(np.abs(np.sort(np.abs(ref.eigenvalues)) - np.sort(np.abs(fp.eigenvalues)))) < 1e-4


# Regression snapshot: the compiled path's Table 1 fixed points (make_map(backend="fast"), default guess, exact
# variational Jacobian), computed with the code before guide friction existed (commit c503cc9, run from an export
# of that commit with its own kernel cache); F_c = 0 reproduces z and |eigenvalues| bit for bit.
BEFORE_FIXED_POINT = {
    "er": (["-0x1.dc51b1ecf5bd2p-2", "0x1.4d5e52621633dp+1"], ["0x1.a06fed9a556d0p-4", "0x1.923b8d720315ap-1"]),
    "ve": (["-0x1.bd370598b06d1p-2", "0x1.250772175f88ap+1"], ["0x1.360ea92bb14c2p-2", "0x1.360ea92bb14c2p-2"]),
}


@pytest.mark.parametrize("model", ["er", "ve"])
def test_zero_friction_compiled_fixed_point_is_bit_identical_to_before(model):
    from rimless.sim.step.poincare import default_guess

    p = WheelParams(guide_friction_n=0.0)
    pm = make_map(p, model, backend="fast")
    fp = solve_fixed_point(pm, default_guess(p, model), jacobian=jacobian_factory("fast")(pm), record=False)
    z, eig = BEFORE_FIXED_POINT[model]
    assert fp.jacobian_method == "variational"
    assert [float(v).hex() for v in fp.z] == z
    assert [float(abs(e)).hex() for e in fp.eigenvalues] == eig
