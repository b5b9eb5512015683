"""Numerical stress of the compiled step map: parameter sweeps, agreement with the reference on a parameter
grid, grazing touchdown, and the stiff-leg path (step limit, stiffness indicator, implicit fallback)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from rimless.sim import fast
from rimless.sim.fast import rk
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.guards import TOUCHDOWN
from rimless.sim.model.mechanics import ALPHA, Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.step.fast_map import FastPoincareMap
from rimless.sim.step.poincare import PoincareMap

HUB = 1.892
Z_GRID = (np.array([-0.44, 1.0]), np.array([-0.45, 2.0]), np.array([-0.43, 3.0]))


def test_sweep_every_point_is_a_valid_step_or_a_classified_failure() -> None:
    outcomes: dict[str, int] = {}
    for k, c, phi, ratio in itertools.product(
        [300.0, 2700.0, 1e5, 1e6], [0.0, 8.0, 100.0], [0.001, 0.05, 0.99 * ALPHA / 2], [0.002, 0.02, 0.2]
    ):
        params = WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c, slope_rad=phi, leg_mass_kg=HUB * ratio)
        for model in ("er", "ve"):
            for z in Z_GRID:
                try:
                    r = fast.fast_step(params, model, z, rtol=1e-8)
                except StepFailure as err:
                    assert isinstance(err.reason, FailureReason)
                    assert err.reason is not FailureReason.INTEGRATION, (k, c, phi, ratio, model, z, err)
                    outcomes[err.reason.value] = outcomes.get(err.reason.value, 0) + 1
                    continue
                assert np.all(np.isfinite(r.z_next)) and np.all(np.isfinite(r.y_plus))
                assert 0.0 < r.period_s < 3 * fast.fs.PHASE_TIME_LIMIT_S
                assert np.all(np.diff(r.phase_end_s) >= 0.0)
                assert 0 < r.nsteps < fast.MAX_STEPS
                outcomes["ok"] = outcomes.get("ok", 0) + 1
    # the sweep reaches valid steps and several distinct failure classes
    assert outcomes.get("ok", 0) > 50
    assert len(outcomes) >= 5, outcomes


GRID = [
    (WheelParams(), "er", np.array([-0.45, 2.3])),
    (WheelParams(stiffness_n_per_m=1500.0), "ve", np.array([-0.43, 2.2])),
    (WheelParams(stiffness_n_per_m=3500.0, damping_ns_per_m=2.0), "er", np.array([-0.46, 2.5])),
    (WheelParams(stiffness_n_per_m=1e4, leg_mass_kg=HUB * 0.002), "er", np.array([-0.42, 2.6])),
    (WheelParams(stiffness_n_per_m=1e5, leg_mass_kg=HUB * 0.002), "er", np.array([-0.41, 1.5])),
    (WheelParams(damping_ns_per_m=0.0, slope_rad=0.02), "ve", np.array([-0.44, 1.8])),
    (WheelParams(damping_ns_per_m=100.0, leg_mass_kg=HUB * 0.2), "er", np.array([-0.45, 2.0])),
    pytest.param(
        WheelParams(mass_model="sliding-leg", slope_rad=0.1), "ve", np.array([-0.43, 2.5]), marks=pytest.mark.full
    ),  # compiles the sliding-leg step kernel
    (WheelParams(stiffness_n_per_m=1e6), "ve", np.array([-0.42, 2.6])),
    (WheelParams(stiffness_n_per_m=300.0), "er", np.array([-0.45, 2.0])),
]


@pytest.mark.parametrize(("params", "model", "z"), GRID)
def test_fast_and_reference_agree_on_a_parameter_grid(params: WheelParams, model: str, z: np.ndarray) -> None:
    rtol = 1e-10
    try:
        ref = PoincareMap(params, model, ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2)).step(z)
        ref_out: object = (np.array([ref.y_plus[2], ref.y_plus[7]]), ref.period_s)
    except StepFailure as err:
        ref_out = err.reason
    try:
        r = fast.fast_step(params, model, z, rtol=rtol)
        fast_out: object = (r.z_next, r.period_s)
    except StepFailure as err:
        fast_out = err.reason
    if isinstance(ref_out, FailureReason):
        assert fast_out == ref_out
    else:
        assert isinstance(fast_out, tuple)
        np.testing.assert_allclose(fast_out[0], ref_out[0], atol=1e-8)
        assert fast_out[1] == pytest.approx(ref_out[1], abs=1e-9)


@pytest.mark.full  # calls the phase integrator from Python, which compiles it on its own (about 20 s on a cold
# cache); tests/sim/integrate/test_contact_guards.py checks a dip between solver steps in every run
def test_grazing_touchdown_inside_one_step_is_not_missed() -> None:
    """The swing foot dips below the slope for a fraction of one solver step and comes back up (a stiff
    stance leg re-extending): the guard is positive at both step ends. A sign test on step ends misses it;
    the fast path finds the first crossing on the dense output."""
    params = WheelParams(stiffness_n_per_m=1e5)
    mech = Mechanics.of(params)
    p = np.array(params.as_vector())
    L0 = params.leg_length_m
    L1 = L0 - 0.01
    # theta at which the swing foot touches with L1 fixed: L1 cos(th) = L0 cos(alpha - th)
    lo, hi = 0.0, ALPHA
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if L1 * math.cos(mid) - L0 * math.cos(ALPHA - mid) > 0 else (lo, mid)
    theta_td = lo

    def state(delta: float) -> np.ndarray:
        # compressing stance leg (L1' < 0) that the spring turns round; no rotation
        return np.array([0.0, 0.0, theta_td - delta, L1, L0, 0.0, 0.0, 0.0, -0.05, 0.0])

    codes, dirs = np.array([TOUCHDOWN]), np.array([-1])

    def run(y: np.ndarray, rtol: float):
        return rk.run_phase(0, 1, p, y, 0.0, codes, dirs, 5e-4, rtol, rtol * 1e-2, 10, False, False, -1.0, 10_000)

    # the largest start offset that still touches (tight tolerance), by bisection
    lo, hi = 1e-7, 1e-3
    assert run(state(lo), 1e-12)[3] == 0 and run(state(hi), 1e-12)[3] == -1
    for _ in range(80):
        mid = math.sqrt(lo * hi) if hi / lo > 1.01 else 0.5 * (lo + hi)
        lo, hi = (mid, hi) if run(state(mid), 1e-12)[3] == 0 else (lo, mid)
    for frac in (0.999999, 0.99):
        y = state(lo * frac)
        tight = run(y, 1e-12)
        assert tight[3] == 0
        for rtol in (1e-3, 1e-6):
            loose = run(y, rtol)
            assert loose[5] <= 3  # the whole dip lies inside one or two steps
            assert loose[3] == 0, (frac, rtol)
            assert loose[1] == pytest.approx(tight[1], abs=1e-9)
        # the same through the Integrator interface
        got = fast.FastIntegrator(rtol=1e-3, atol=1e-5).run_phase(mech, 1, y, 0.0, (TOUCHDOWN,), 5e-4)
        assert got.guard == TOUCHDOWN


def test_step_limit_is_reported_and_falls_back_to_an_implicit_method() -> None:
    params = WheelParams(stiffness_n_per_m=1e4, leg_mass_kg=HUB * 0.02)
    z = np.array([-0.42, 2.6])
    with pytest.raises(fast.StiffnessLimit) as info:
        fast.fast_step(params, "er", z, max_steps=20)
    assert info.value.reason is FailureReason.INTEGRATION
    pm = FastPoincareMap(params, "er", fast.FastIntegrator(rtol=1e-8, atol=1e-10, max_steps=20))
    z_fb = pm(z)
    assert pm.last_method == "scipy-Radau"
    z_fast = fast.fast_map(params, "er", z, rtol=1e-11)[0]
    np.testing.assert_allclose(z_fb, z_fast, atol=1e-6)
    pm_off = FastPoincareMap(params, "er", fast.FastIntegrator(max_steps=20), stiff_fallback=False)
    with pytest.raises(fast.StiffnessLimit):
        pm_off(z)


def test_stiffness_indicator_flags_stiff_legs_only() -> None:
    soft = fast.fast_step(WheelParams(), "er", np.array([-0.465155, 2.604441]), rtol=1e-8)
    stiff = fast.fast_step(
        WheelParams(stiffness_n_per_m=3000.0, damping_ns_per_m=100.0, leg_mass_kg=HUB * 0.002),
        "ve",
        np.array([-0.43, 3.0]),
        rtol=1e-8,
    )
    assert soft.nstiff < 0.1 * soft.nsteps
    assert stiff.nstiff > 0.5 * stiff.nsteps


def test_outcome_classes_agree_with_the_reference_on_a_small_stress_grid() -> None:
    from rimless.sim.studies.stress import compare_with_reference

    res = compare_with_reference(
        WheelParams(), k_values=(1000.0,), c_values=(0.0, 8.0), slopes_rad=(0.05,), mass_ratios=(0.02,), rtol=1e-10
    )
    assert res["points"] == 2 * 2 * 3
    assert res["agree"] == res["points"], res["disagreements"]
    assert res["max_dz_valid"] < 1e-8
