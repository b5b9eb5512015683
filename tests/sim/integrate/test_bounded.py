"""Every step ends in bounded time with a valid result or a classified failure; NaN is never a result."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.errors import ParameterError
from rimless.sim import fast
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.params import WheelParams
from rimless.sim.step.fast_map import FastPoincareMap
from rimless.sim.step.poincare import PoincareMap

Z_ER = np.array([-0.465155, 2.604441])


@pytest.mark.parametrize("model", ["er", "ve"])
@pytest.mark.parametrize("theta_dot", [1e160, 1e300])
def test_overflowing_speed_is_an_integration_failure_on_both_backends(model: str, theta_dot: float) -> None:
    """Contact forces overflow to inf/NaN: NaN must not pass the force checks, and the compiled step-size
    loop must not spin on a NaN step."""
    z = np.array([-0.4627, theta_dot])
    with pytest.raises(StepFailure) as info_fast:
        fast.fast_step(WheelParams(), model, z)
    with pytest.raises(StepFailure) as info_ref:
        PoincareMap(WheelParams(), model).step(z)
    for info in (info_fast, info_ref):
        assert info.value.reason is FailureReason.INTEGRATION
        assert "non-finite" in str(info.value)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("z", [np.array([np.nan, 2.6]), np.array([-0.46, np.nan]), np.array([-0.46, np.inf])])
def test_non_finite_section_points_fail(z: np.ndarray) -> None:
    with pytest.raises(StepFailure):
        fast.fast_step(WheelParams(), "er", z)
    with pytest.raises(StepFailure):
        PoincareMap(WheelParams(), "er").step(z)


@pytest.mark.parametrize(
    ("field", "option"),
    [
        ("leg_mass_kg", "--leg-mass-kg"),
        ("stiffness_n_per_m", "--k"),
        ("damping_ns_per_m", "--c"),
        ("slope_rad", "--slope-rad"),
        ("hub_mass_kg", "--hub-mass-kg"),
    ],
)
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_parameter_is_a_parameter_error_naming_the_option(field: str, option: str, value: float) -> None:
    with pytest.raises(ParameterError) as info:
        WheelParams(**{field: value})
    assert option in str(info.value)


def test_reference_backend_has_an_evaluation_budget() -> None:
    """A phase that would need more right-hand-side evaluations than the budget fails, classified."""
    pm = PoincareMap(WheelParams(), "er", ScipyIntegrator(rtol=1e-10, atol=1e-12, max_nfev=300))
    with pytest.raises(StepFailure) as info:
        pm.step(Z_ER)
    assert info.value.reason is FailureReason.INTEGRATION
    assert "300 right-hand-side evaluations" in str(info.value)


def test_stiff_fallback_is_bounded_and_reports_a_finite_period(monkeypatch: pytest.MonkeyPatch) -> None:
    """The implicit fallback gives the true step period (never NaN) and stops at its evaluation budget:
    with legs of 1e-6 kg handed to it (the compiled path held to 20 steps; scipy's Radau needs too many
    evaluations there) the map fails with a classified reason instead of running for many minutes."""
    params = WheelParams(stiffness_n_per_m=1e4, leg_mass_kg=1.892 * 0.02)
    z = np.array([-0.42, 2.6])
    pm = FastPoincareMap(params, "er", fast.FastIntegrator(rtol=1e-8, atol=1e-10, max_steps=20))
    z_next, period, _ = pm.evaluate(z)
    assert pm.last_method == "scipy-Radau"
    r = fast.fast_step(params, "er", z, rtol=1e-11)
    assert math.isfinite(period) and period == pytest.approx(r.period_s, abs=1e-6)
    np.testing.assert_allclose(z_next, r.z_next, atol=1e-6)

    monkeypatch.setattr(fast, "RADAU_MAX_NFEV", 3000)
    tiny = FastPoincareMap(WheelParams(leg_mass_kg=1e-6), "er", fast.FastIntegrator(max_steps=20))
    with pytest.raises(StepFailure) as info:
        tiny(Z_ER)
    assert info.value.reason is FailureReason.INTEGRATION
    assert "3000 right-hand-side evaluations" in str(info.value)


@pytest.mark.parametrize("model", ["er", "ve"])
def test_very_light_legs_converge_to_the_light_leg_limit_in_bounded_steps(model: str) -> None:
    """With the compiled path alone (no fallback) very light legs now end their step within 5000 steps a phase
    (bfde425: the step limit in double support, the generated equations' rounding eps (m_H / m)^2), and the map
    converges as m -> 0, to first order: legs of 1e-9 and 1e-12 kg give the same step to 1e-8 (measured 1.3e-9), and 1e-6
    kg within 5e-6 of them (measured 1.35e-6: the same O(m) coefficient)."""
    out = {}
    for m in (1e-6, 1e-9, 1e-12):
        pm = FastPoincareMap(
            WheelParams(leg_mass_kg=m), model, fast.FastIntegrator(max_steps=5000), stiff_fallback=False
        )
        out[m] = pm(Z_ER)
        assert np.all(np.isfinite(out[m]))
    np.testing.assert_allclose(out[1e-9], out[1e-12], rtol=0, atol=1e-8)
    np.testing.assert_allclose(out[1e-6], out[1e-12], rtol=0, atol=5e-6)


def test_a_step_over_the_step_limit_is_classified() -> None:
    """Bounded work on the compiled path alone: a phase that needs more steps than the limit ends the step with
    the classified StiffnessLimit (an integration failure), never a result."""
    pm = FastPoincareMap(WheelParams(leg_mass_kg=1e-6), "er", fast.FastIntegrator(max_steps=5), stiff_fallback=False)
    with pytest.raises(fast.StiffnessLimit) as info:
        pm(Z_ER)
    assert info.value.reason is FailureReason.INTEGRATION
