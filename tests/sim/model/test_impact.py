import math

import numpy as np
import pytest

from rimless.sim.model.impact import double_support_jacobian, impact, relabel
from rimless.sim.model.mechanics import ALPHA, Mechanics, swing_height
from rimless.sim.model.params import WheelParams
from tests.support.sim_states import random_states


def _touchdown_state(rng, mech):
    """A pre-impact state with the swing foot on the slope: theta solved from the touchdown condition."""
    L0 = mech.params.leg_length_m
    L1 = rng.uniform(0.215, L0)
    # L1 cos(th) = L0 cos(alpha - th)  ->  tan(th) = (L1 - L0 cos a) / (L0 sin a)
    th = math.atan2(L1 - L0 * math.cos(ALPHA), L0 * math.sin(ALPHA))
    q = np.array([rng.uniform(-1, 1), 0.0, th, L1, rng.uniform(0.22, 0.24)])
    qd = np.array([0.0, 0.0, rng.uniform(1, 4), rng.uniform(-0.3, 0.3), rng.normal()])
    assert abs(swing_height(q, L0)) < 1e-15
    return q, qd


@pytest.mark.parametrize("mass_model", ["eight-leg", "sliding-leg"])
def test_impact_never_adds_kinetic_energy_and_satisfies_constraints(mass_model):
    mech = Mechanics.of(WheelParams(mass_model=mass_model))
    rng = np.random.default_rng(5)
    for _ in range(50):
        q, qd = _touchdown_state(rng, mech)
        res = impact(mech, q, qd)
        assert res.kinetic_plus <= res.kinetic_relabelled * (1 + 1e-14)
        Jc = double_support_jacobian(mech, res.q_plus)
        assert np.max(np.abs(Jc @ res.qd_plus)) <= 1e-12
        # the impulse reproduces the velocity jump: M (q'+ - q'~) = Jc^T Lambda
        _, qd_t = relabel(q, qd, mech.params.leg_length_m)
        M = mech.mass_matrix(res.q_plus)
        np.testing.assert_allclose(M @ (res.qd_plus - qd_t), Jc.T @ res.impulse, atol=1e-12)


def test_relabel_puts_the_new_stance_foot_where_the_swing_foot_was():
    mech = Mechanics.of(WheelParams())
    rng = np.random.default_rng(6)
    L0 = mech.params.leg_length_m
    for q, qd in random_states(rng, 20):
        qn, qdn = relabel(q, qd, L0)
        hub = np.array([q[0] + q[3] * math.sin(q[2]), q[1] + q[3] * math.cos(q[2])])
        swing = hub - L0 * np.array([math.sin(q[2] - ALPHA), math.cos(q[2] - ALPHA)])
        np.testing.assert_allclose(qn[:2], swing, atol=1e-15)
        hub_new = np.array([qn[0] + qn[3] * math.sin(qn[2]), qn[1] + qn[3] * math.cos(qn[2])])
        np.testing.assert_allclose(hub_new, hub, atol=1e-15)  # the hub does not move
        assert qn[3] == L0 and qdn[3] == 0.0 and qn[4] == q[3] and qdn[4] == qd[3]

        # hub velocity unchanged by relabelling
        def hub_vel(q_, qd_):
            return np.array(
                [
                    qd_[0] + qd_[3] * math.sin(q_[2]) + q_[3] * math.cos(q_[2]) * qd_[2],
                    qd_[1] + qd_[3] * math.cos(q_[2]) - q_[3] * math.sin(q_[2]) * qd_[2],
                ]
            )

        np.testing.assert_allclose(hub_vel(qn, qdn), hub_vel(q, qd), atol=1e-13)


def test_fixed_point_impulses_are_compressive_and_need_friction_two_to_three(er_fixed_point):
    _, fp = er_fixed_point
    imp = fp.step.impact
    assert imp.impulse[1] > 0 and imp.impulse[3] > 0
    assert all(1.0 < mu < 4.0 for mu in imp.friction_required)
    assert imp.kinetic_plus < imp.kinetic_minus
