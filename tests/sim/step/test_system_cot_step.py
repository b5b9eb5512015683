"""Per-gait cost of transport from the step record against independent truths (tests/support/sim_cot_truth.py):
with no electrical power the system CoT is the mechanical one, tan(phi) (the closed form of passive walking);
the clutch's energy is P_hold x the clutched time measured on the reference path's recorded trajectory."""

import math

import numpy as np
import pytest

from rimless.errors import ParameterError
from rimless.sim.model.electrical import ClutchPower
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import jacobian_factory, make_map
from rimless.sim.step.cot import step_cot, step_transport
from rimless.sim.step.poincare import default_guess, solve_fixed_point
from tests.support.sim_cot_truth import clutched_and_period_s, truth_system_cot, world_travel

P = WheelParams()


@pytest.fixture(scope="module", params=["er", "ve"])
def recorded(request):
    """(model, reference-path step recorded at the fixed point found on the compiled path)."""
    model = request.param
    fast = make_map(P, model, backend="fast")
    fp = solve_fixed_point(fast, default_guess(P, model), jacobian=jacobian_factory("fast")(fast), record=False)
    ref = make_map(P, model, backend="reference")
    return model, ref.step(fp.z, record_dt=1e-3), fast.step(fp.z)


def test_with_no_power_the_system_cot_is_the_mechanical_cot_tan_phi(recorded):
    model, ref, fast = recorded
    for step in (ref, fast):
        out = step_cot(step, P, model, ClutchPower())
        assert out["electrical_energy_per_step_j"] == 0.0
        assert out["system_cot"] == out["mechanical_cot"]
        assert out["mechanical_cot"] == pytest.approx(math.tan(P.slope_rad), rel=1e-12)
    # the travel itself against the hub's world-frame displacement (periodic gait: one step = one foot spacing)
    s_x, s_z = world_travel(ref, P.slope_rad)
    tr = step_transport(ref, P)
    assert tr.s_x_m == pytest.approx(s_x, rel=1e-6) and tr.s_z_m == pytest.approx(s_z, rel=1e-5)
    assert s_z / s_x == pytest.approx(math.tan(P.slope_rad), rel=1e-5)


@pytest.mark.parametrize("ve_electronics", [False, True])
def test_electrical_energy_and_system_cot_match_the_recorded_trajectory(recorded, ve_electronics):
    model, ref, fast = recorded
    power = ClutchPower(
        hold_power_w=0.7, switch_energy_j=0.013, electronics_power_w=0.25, ve_electronics=ve_electronics
    )
    t_c, period = clutched_and_period_s(ref)
    if model == "er":
        assert t_c > 0.5 * period  # the clutch holds for most of the ER step (lock at max compression to impact)
    else:
        assert t_c == 0.0
    s_x, s_z = world_travel(ref, P.slope_rad)
    e_true, cot_true = truth_system_cot(
        P.hub_mass_kg + 8 * P.leg_mass_kg,
        P.gravity_m_s2,
        s_x,
        s_z,
        model,
        t_c,
        period,
        0.7,
        0.013,
        0.25,
        ve_electronics,
    )
    out = step_cot(ref, P, model, power)
    assert out["electrical_energy_per_step_j"] == pytest.approx(e_true, rel=1e-9, abs=1e-15)
    assert out["system_cot"] == pytest.approx(cot_true, rel=1e-6)
    if model == "er":
        assert out["system_cot"] > out["mechanical_cot"]
    # the compiled path's step gives the same energy (its event times agree with the reference's)
    assert step_cot(fast, P, model, power)["electrical_energy_per_step_j"] == pytest.approx(e_true, rel=1e-6, abs=1e-12)


@pytest.mark.parametrize(
    "field,option",
    [
        ("hold_power_w", "--clutch-hold-power-w"),
        ("switch_energy_j", "--clutch-switch-energy-j"),
        ("electronics_power_w", "--electronics-power-w"),
    ],
)
@pytest.mark.parametrize("bad", [-1e-3, math.nan, math.inf])
def test_a_bad_power_names_its_option(field, option, bad):
    with pytest.raises(ParameterError, match=option):
        ClutchPower(**{field: bad})


def test_np_float_is_accepted():
    assert ClutchPower(hold_power_w=np.float64(0.5)).hold_power_w == 0.5
