import math

import pytest
from scipy.integrate import solve_ivp

from rimless.sim.model.params import WheelParams
from rimless.sim.model.rigid import ALPHA, RigidWheel


def test_coleman_critical_slope_of_table_1_is_2_799_deg():
    p = WheelParams()
    assert math.degrees(RigidWheel.from_params(p, "paper").critical_slope_rad()) == pytest.approx(2.799, abs=5e-4)
    # the rigid wheel consistent with the eight-leg mass model (model.md section 8)
    assert RigidWheel.from_params(p, "eight-leg").critical_slope_rad() == pytest.approx(0.045386, abs=1e-6)


def test_step_map_eigenvalue_is_beta_squared():
    wheel = RigidWheel.from_params(WheelParams(), "paper")
    phi = 0.06
    w = wheel.fixed_point_omega(phi)
    assert wheel.step_map(w, phi) == pytest.approx(w, rel=1e-14)
    h = 1e-6
    slope = (wheel.step_map(w + h, phi) - wheel.step_map(w - h, phi)) / (2 * h)
    assert slope == pytest.approx(wheel.beta**2, rel=1e-8)


def test_at_the_critical_slope_the_gait_just_clears_mid_stance():
    wheel = RigidWheel.from_params(WheelParams(), "paper")
    phi_c = wheel.critical_slope_rad()
    assert wheel.fixed_point_omega(phi_c) ** 2 == pytest.approx(wheel.barrier(phi_c), rel=1e-10)
    assert math.isnan(wheel.step_map(0.9 * math.sqrt(wheel.barrier(phi_c)), phi_c))


def test_step_period_matches_direct_integration_of_the_inverted_pendulum():
    p = WheelParams()
    wheel = RigidWheel.from_params(p, "paper")
    phi = 0.06
    inertia = wheel.inertia_kg_m2 + wheel.mass_kg * wheel.leg_length_m**2

    def f(_t, y):
        return [y[1], wheel.mass_kg * p.gravity_m_s2 * wheel.leg_length_m * math.sin(y[0] + phi) / inertia]

    def reach(_t, y):
        return y[0] - ALPHA / 2

    reach.terminal = True
    sol = solve_ivp(f, (0, 5), [-ALPHA / 2, wheel.fixed_point_omega(phi)], events=reach, rtol=1e-12, atol=1e-12)
    assert wheel.step_period_s(phi) == pytest.approx(sol.t_events[0][0], rel=1e-8)
    # the pre-impact rate maps back onto the fixed point through beta
    assert wheel.beta * sol.y_events[0][0][1] == pytest.approx(wheel.fixed_point_omega(phi), rel=1e-8)
