"""Normal-force guards between solver steps, and the relabelling snap's energy.

A stance force that dips below zero and recovers between two accepted solver steps is positive at both step
ends, so a sign test on step ends misses it (the case and its truth: tests.support.sim_dip).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.sim import fast
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import ALPHA
from rimless.sim.model.params import WheelParams
from rimless.sim.step.fast_map import FastPoincareMap
from rimless.sim.step.poincare import PoincareMap
from tests.support import sim_dip
from tests.support.sim_dip import DIP_PARAMS, DIP_Z


@pytest.fixture(scope="module")
def dip_truth() -> dict[str, float]:
    return sim_dip.dip_truth()


def test_the_dip_is_short_and_shallow(dip_truth: dict[str, float]) -> None:
    assert -0.02 < dip_truth["min_N"] < -1e-3
    assert dip_truth["last_negative_s"] - dip_truth["first_zero_s"] < 3e-3


@pytest.mark.parametrize("rtol", [1e-10, 1e-8, 1e-6])
def test_both_backends_catch_a_dip_between_solver_steps(dip_truth: dict[str, float], rtol: float) -> None:
    ref = PoincareMap(DIP_PARAMS, "ve", ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2))
    with pytest.raises(StepFailure) as info_ref:
        ref.step(DIP_Z)
    with pytest.raises(StepFailure) as info_fast:
        fast.fast_step(DIP_PARAMS, "ve", DIP_Z, rtol=rtol)
    for info in (info_ref, info_fast):
        assert info.value.reason is FailureReason.STANCE_LIFT_OFF
        assert info.value.phase == "slsp_free"
        # located at the first zero of the force (the truth is sampled every 2 us)
        assert info.value.time_s == pytest.approx(dip_truth["first_zero_s"], abs=5e-6)
    # the compiled map through the FastIntegrator (phase by phase) and FastPoincareMap agree
    with pytest.raises(StepFailure) as info_int:
        FastPoincareMap(DIP_PARAMS, "ve", fast.FastIntegrator(rtol=rtol, atol=rtol * 1e-2)).step(DIP_Z)
    assert info_int.value.reason is FailureReason.STANCE_LIFT_OFF


def test_a_positive_force_minimum_is_not_a_lift_off() -> None:
    """Just below the dip's stiffness the gait is valid: the check must not invent lift-offs."""
    params = WheelParams(stiffness_n_per_m=2500.0)
    ref = PoincareMap(params, "ve", ScipyIntegrator(rtol=1e-10, atol=1e-12)).step(DIP_Z)
    r = fast.fast_step(params, "ve", DIP_Z, rtol=1e-10)
    np.testing.assert_allclose(r.z_next, [ref.y_plus[2], ref.y_plus[7]], atol=1e-9)


def _snap_energy_closed_form(params: WheelParams, y_minus: np.ndarray) -> float:
    """Energy the snap adds (eight-leg): the old trailing foot (mass m) goes from length L2 and rate L2' to L0
    and rate 0 while the hub and theta' are unchanged; its spring energy vanishes."""
    m, k, g, phi, L0 = (
        params.leg_mass_kg,
        params.stiffness_n_per_m,
        params.gravity_m_s2,
        params.slope_rad,
        params.leg_length_m,
    )
    q, qd = y_minus[:5], y_minus[5:]
    th, L2, dth, dL2 = q[2], q[4], qd[2], qd[4]
    x_b, y_b, _, L1, _ = q
    dx, dy, _, dL1, _ = qd
    hub_v = np.array(
        [dx + dL1 * math.sin(th) + L1 * math.cos(th) * dth, dy + dL1 * math.cos(th) - L1 * math.sin(th) * dth]
    )
    u = np.array([math.sin(th + ALPHA), math.cos(th + ALPHA)])
    u_perp = np.array([math.cos(th + ALPHA), -math.sin(th + ALPHA)])
    v_before = hub_v - dL2 * u - L2 * dth * u_perp
    v_after = hub_v - L0 * dth * u_perp
    d_kinetic = 0.5 * m * (v_after @ v_after - v_before @ v_before)
    d_gravity = -m * g * (L0 - L2) * math.cos(th + ALPHA + phi)
    return d_kinetic + d_gravity - 0.5 * k * (L2 - L0) ** 2


@pytest.mark.parametrize(
    ("model", "z", "sign"),
    [
        ("ve", np.array([-0.434780, 2.289290]), +1.0),
        ("er", np.array([-0.465155, 2.604441]), -1.0),
    ],
)
def test_relabel_snap_energy_sign_size_and_both_backends(model: str, z: np.ndarray, sign: float) -> None:
    params = WheelParams()
    step = PoincareMap(params, model, ScipyIntegrator(rtol=1e-12, atol=1e-14)).step(z)
    expected = _snap_energy_closed_form(params, step.y_minus)
    assert step.relabel_snap_J == pytest.approx(expected, abs=1e-12)
    assert step.relabel_snap_J == pytest.approx(-step.impact.relabel_loss, abs=1e-15)
    assert sign * step.relabel_snap_J > 0.0
    assert 1e-7 < abs(step.relabel_snap_J) < 1e-4  # tiny next to the ~0.1 J lost per step
    r = fast.fast_step(params, model, z, rtol=1e-12, atol=1e-14)
    assert r.relabel_snap_J == pytest.approx(step.relabel_snap_J, abs=1e-10)
