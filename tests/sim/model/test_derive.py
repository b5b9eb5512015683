"""The generated equations against the symbolic derivation and independent numeric checks."""

import math

import numpy as np
import pytest

from rimless.sim.model import derive
from rimless.sim.model.mechanics import ALPHA, Mechanics
from rimless.sim.model.params import WheelParams
from tests.support.sim_states import random_states


@pytest.mark.parametrize("mass_model", ["eight-leg", "sliding-leg", "active-feet"])
def test_generated_code_matches_a_fresh_derivation(mass_model):
    path = derive.GENERATED_DIR / f"{derive.MODEL_NAMES[mass_model]}.py"
    assert path.read_text(encoding="utf-8") == derive.generate_source(mass_model), (
        "generated code is stale: run `python -m rimless.sim.model.derive`"
    )


@pytest.mark.parametrize("mass_model", ["eight-leg", "sliding-leg", "active-feet"])
def test_mass_matrix_symmetric_positive_definite(mass_model):
    mech = Mechanics.of(WheelParams(mass_model=mass_model))
    rng = np.random.default_rng(1)
    for q, _ in random_states(rng, 50):
        M = mech.mass_matrix(q)
        assert np.array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 0


def _point_masses(q, p: WheelParams):
    """Independent eight-leg geometry: (mass, position) of the hub and the eight feet."""
    x, y, th, L1, L2 = q
    hub = np.array([x + L1 * math.sin(th), y + L1 * math.cos(th)])
    out = [(p.hub_mass_kg, hub)]
    for j in range(8):
        length = L1 if j == 0 else L2 if j == 1 else p.leg_length_m
        out.append((p.leg_mass_kg, hub - length * np.array([math.sin(th + j * ALPHA), math.cos(th + j * ALPHA)])))
    return out


def test_eight_leg_energies_match_point_masses():
    p = WheelParams()
    mech = Mechanics.of(p)
    rng = np.random.default_rng(2)
    h = 1e-6
    for q, qd in random_states(rng, 20):
        # kinetic energy from numerically differentiated positions of every point mass
        t_num = 0.5 * p.inertia_kg_m2 * qd[2] ** 2
        for (m, pos_plus), (_, pos_minus) in zip(
            _point_masses(q + h * qd, p), _point_masses(q - h * qd, p), strict=True
        ):
            v = (pos_plus - pos_minus) / (2 * h)
            t_num += 0.5 * m * v @ v
        assert mech.kinetic(q, qd) == pytest.approx(t_num, rel=1e-8)
        v_num = sum(
            m * p.gravity_m_s2 * (-pos[0] * math.sin(p.slope_rad) + pos[1] * math.cos(p.slope_rad))
            for m, pos in _point_masses(q, p)
        )
        v_num += 0.5 * p.k * ((q[3] - p.leg_length_m) ** 2 + (q[4] - p.leg_length_m) ** 2)
        assert mech.potential(q) == pytest.approx(v_num, rel=1e-12, abs=1e-12)


def test_foot_a_jacobian_is_the_papers():
    mech = Mechanics.of(WheelParams())
    rng = np.random.default_rng(3)
    for q, _ in random_states(rng, 20):
        _, _, th, L1, L2 = q
        paper = np.array(
            [
                [1, 0, L1 * math.cos(th) - L2 * math.cos(th + ALPHA), math.sin(th), -math.sin(th + ALPHA)],
                [0, 1, -L1 * math.sin(th) + L2 * math.sin(th + ALPHA), math.cos(th), -math.cos(th + ALPHA)],
            ]
        )
        np.testing.assert_allclose(mech.jac_a(q), paper, rtol=0, atol=1e-15)


def test_bias_is_lagrangian():
    """h = d/dt(dT/dqd) - M qdd - dT/dq + dV/dq + damping, checked by finite differences of T and V."""
    p = WheelParams()
    mech = Mechanics.of(p)
    rng = np.random.default_rng(4)
    eps = 1e-6
    for q, qd in random_states(rng, 10):
        # Coriolis part: (dM/dt) qd - dT/dq, with dM/dt = sum_k dM/dq_k qd_k
        dmdt = (mech.mass_matrix(q + eps * qd) - mech.mass_matrix(q - eps * qd)) / (2 * eps)
        dT = np.array([(mech.kinetic(q + eps * e, qd) - mech.kinetic(q - eps * e, qd)) / (2 * eps) for e in np.eye(5)])
        dV = np.array([(mech.potential(q + eps * e) - mech.potential(q - eps * e)) / (2 * eps) for e in np.eye(5)])
        damping = np.array([0, 0, 0, p.c * qd[3], p.c * qd[4]])
        expected = dmdt @ qd - dT + dV + damping
        np.testing.assert_allclose(mech.bias(q, qd), expected, rtol=1e-6, atol=1e-6)
