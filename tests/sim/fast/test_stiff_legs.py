"""Near-massless legs (0.1 g, what a user describing a rigid-legged wheel writes): single support by the compiled
Rosenbrock method (rimless.sim.fast.stiff) agrees with the explicit DOP853 at a tight tolerance, in a bounded
number of right-hand-side evaluations (counted, never timed); Table 1 stays on DOP853."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.sim.fast import FastIntegrator, fast_step, param_vector, stiff
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.gait import simulate_steps
from rimless.sim.step.hybrid import simulate_step

# the rigid truth wheel of rimless.analysis.validation.critical_truth (M 2.6 kg, I_hub 0.05 kg m^2, L 0.21 m) as
# its wheel_params() writes it: legs of 0.1 g, M = m_H + 8 m, I_hub = I_c + 8 m L^2; a 4 deg ramp
M_LEG = 1e-4
LIGHT = WheelParams(
    hub_mass_kg=2.6 - 8 * M_LEG,
    leg_mass_kg=M_LEG,
    inertia_kg_m2=0.05 - 8 * M_LEG * 0.21**2,
    leg_length_m=0.21,
    slope_rad=math.radians(4.0),
)
RELEASE = np.array([-math.pi / 8, 2.0])  # theta (rad), theta' (rad/s): released on two feet


def test_table1_stays_on_dop853_and_light_legs_are_stiff() -> None:
    """The switch is the free leg's fastest root max(c/m, sqrt(k/m)): ~270 1/s at Table 1, 8e4 1/s at 0.1 g."""
    assert stiff.leg_rate(param_vector(WheelParams())) == pytest.approx(math.sqrt(2700 / 0.0378))
    assert not stiff.leg_stiff(param_vector(WheelParams()))
    assert stiff.leg_rate(param_vector(LIGHT)) == pytest.approx(8.0 / M_LEG)
    assert stiff.leg_stiff(param_vector(LIGHT))


@pytest.fixture(scope="module")
def reference():
    """Three ER steps with DOP853 everywhere at rtol 1e-12 (the explicit method, stability-limited but exact)."""
    return simulate_steps(LIGHT, "er", RELEASE, 3, FastIntegrator(rtol=1e-12, atol=1e-14, stiff_legs=False))


@pytest.mark.parametrize("rtol", [1e-8, 1e-10])
def test_light_leg_walk_agrees_with_tight_dop853_in_bounded_evaluations(reference, rtol: float) -> None:
    """Rosenbrock single support: periods and post-impact sections of a 3-step walk agree with the tight DOP853
    walk to the tolerance's accuracy, phases in the same order, with at most 12 000 field evaluations per step
    (DOP853 alone needed some 60 000 per step at either rtol, its stability limit h |lambda| < 6)."""
    walk = simulate_steps(LIGHT, "er", RELEASE, 3, FastIntegrator(rtol=rtol, atol=rtol * 1e-2))
    assert walk.failure is None and len(walk.steps) == 3
    for got, ref in zip(walk.steps, reference.steps, strict=True):
        assert got.period_s == pytest.approx(ref.period_s, abs=1e-7)
        np.testing.assert_allclose(got.y_plus[[2, 7]], ref.y_plus[[2, 7]], atol=1e-7)
        assert list(got.phase_durations_s) == list(ref.phase_durations_s)
        assert got.nfev < 12_000
    # and the same walk on DOP853 at the same rtol is no closer to the reference (the switch loses nothing)
    dop = simulate_steps(LIGHT, "er", RELEASE, 3, FastIntegrator(rtol=rtol, atol=rtol * 1e-2, stiff_legs=False))
    err_new = max(abs(a.period_s - b.period_s) for a, b in zip(walk.steps, reference.steps, strict=True))
    err_old = max(abs(a.period_s - b.period_s) for a, b in zip(dop.steps, reference.steps, strict=True))
    assert err_new <= max(err_old, 1e-9) * 3
    assert sum(s.nfev for s in dop.steps) > 3 * sum(s.nfev for s in walk.steps)


def test_light_leg_map_agrees_with_the_walk_in_bounded_evaluations(reference) -> None:
    """The compiled step map (the comparison's scans) on 0.1 g legs: the walk's steps to 1e-8, double support in
    a few steps (its tightened tolerance stays above the KKT solve's rounding, eps m_H / m) and at most 5000
    field evaluations per step at rtol 1e-8 (today's main: some 140 000, 5300 steps of them in double
    support)."""
    z = RELEASE
    for ref in reference.steps:
        r = fast_step(LIGHT, "er", z, rtol=1e-8)
        assert r.period_s == pytest.approx(ref.period_s, abs=1e-8)
        np.testing.assert_allclose(r.z_next, ref.y_plus[[2, 7]], atol=1e-7)
        assert r.phase_steps[0] < 50
        assert r.nfev < 5000
        z = r.z_next


def test_light_leg_stall_is_classified_on_both_integrators() -> None:
    """Released too slowly, the 0.1 g-leg wheel rolls back: a stall on the Rosenbrock path as on DOP853, at the
    same time (to 1e-6 s)."""
    slow = np.array([-math.pi / 8, 0.3])
    runs = [
        simulate_steps(LIGHT, "er", slow, 2, FastIntegrator(rtol=1e-10, atol=1e-12, stiff_legs=s))
        for s in (True, False)
    ]
    for walk in runs:
        assert walk.failure is not None and walk.failure.reason is FailureReason.STALL
    assert runs[0].failure.time_s == pytest.approx(runs[1].failure.time_s, abs=1e-6)
    with pytest.raises(StepFailure) as info:
        fast_step(LIGHT, "er", slow, rtol=1e-10)
    assert info.value.reason is FailureReason.STALL


def test_light_leg_step_energy_balance_with_the_dampers_work() -> None:
    """Invariant: over one step's continuous phases the mechanical energy lost equals the dampers' integrated
    work, sum c L_i'^2 dt (the 11th component the Rosenbrock phase carries with its Jacobian row), to 1e-9 J of
    the ~0.05 J, in a bounded number of evaluations."""
    mech = Mechanics.of(LIGHT)
    y0 = state_from_section(mech, RELEASE)
    res = simulate_step(mech, "er", y0, FastIntegrator(rtol=1e-10, atol=1e-12), track_dissipation=True)
    lost = mech.energy(y0[:5], y0[5:]) - mech.energy(res.y_minus[:5], res.y_minus[5:])
    assert res.dissipated_J > 0.01
    assert lost == pytest.approx(res.dissipated_J, abs=1e-9)
    assert res.nfev < 15_000


def test_light_leg_exact_jacobian_on_rosenbrock_agrees_with_map_differences(reference) -> None:
    """The map with its exact Jacobian (the variational equations carried through the Rosenbrock single support,
    the field's second derivative by central differences inside the stage solves): on the Rosenbrock path
    (today's main: DOP853 there, some 40 000-60 000 evaluations a step), under 12 000 field evaluations a step at
    rtol 1e-8, the walk's periods (2e-8 s) and sections (5e-8), a Jacobian that moves by under 1e-8 from rtol 1e-8
    to 1e-10 and agrees with central differences of the map (rtol 1e-12, dz 1e-6: their error some 1e-8 / 1e-6)
    to 5e-4 of its largest entry, on the walk's three post-impact states."""
    z = RELEASE
    for ref in reference.steps:
        loose = fast_step(LIGHT, "er", z, rtol=1e-8, jacobian=True)
        assert loose.method == "fast-dop853+rosenbrock"
        assert loose.nfev < 12_000
        # the map itself to the light-leg map's accuracy (double support's floor: 2-4e-8 per step, as without the
        # Jacobian; with V the field comes from the directional kernels, another rounding of the same noise)
        assert loose.period_s == pytest.approx(ref.period_s, abs=2e-8)
        np.testing.assert_allclose(loose.z_next, ref.y_plus[[2, 7]], atol=5e-8)
        tight = fast_step(LIGHT, "er", z, rtol=1e-10, jacobian=True)
        assert loose.jacobian is not None and tight.jacobian is not None
        np.testing.assert_allclose(loose.jacobian, tight.jacobian, atol=1e-8)
        d = 1e-6
        fd = np.empty((2, 2))
        for j in range(2):
            e = np.zeros(2)
            e[j] = d
            up = fast_step(LIGHT, "er", z + e, rtol=1e-12).z_next
            down = fast_step(LIGHT, "er", z - e, rtol=1e-12).z_next
            fd[:, j] = (up - down) / (2 * d)
        assert np.max(np.abs(tight.jacobian - fd)) < 5e-4 * np.max(np.abs(fd))
        z = ref.y_plus[[2, 7]]
