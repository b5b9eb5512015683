"""Near-massless legs with guide friction: the stick/slip phases of single support (rimless.sim.integrate.friction)
on the compiled Rosenbrock method (rimless.sim.fast.stiff) agree with the explicit DOP853 at a tight tolerance,
with the same sequence of stick/slip events, in a bounded number of field evaluations (counted, never timed),
and the energy lost is the dampers' work plus the friction work."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from rimless.sim.fast import FastIntegrator
from rimless.sim.model import friction as fr
from rimless.sim.model.dynamics import DLSP
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.gait import simulate_steps
from rimless.sim.step.hybrid import simulate_step
from tests.sim.fast.test_stiff_legs import LIGHT as FRICTIONLESS
from tests.sim.fast.test_stiff_legs import RELEASE

# test_stiff_legs' 0.1 g-leg wheel (the rigid truth of rimless.analysis.validation.critical_truth as its
# wheel_params() writes it, on a 4 deg ramp) with the audit truth's guide friction 0.3 N, released on two feet
FRICTION_N = 0.3
LIGHT = replace(FRICTIONLESS, guide_friction_n=FRICTION_N)
N_STEPS = 3


class EventLog:
    """An integrator that passes every phase to `inner` and logs (phase code, guard fired): the stick/slip
    classification of a walk, as rimless.sim.integrate.friction switched it."""

    def __init__(self, inner: FastIntegrator) -> None:
        self.inner = inner
        self.events: list[tuple[int, int | None]] = []
        self.single_support_nfev = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def run_phase(self, mech: Mechanics, phase: int, *args: Any, **kwargs: Any) -> Any:
        run = self.inner.run_phase(mech, phase, *args, **kwargs)
        self.events.append((phase, run.guard))
        base = phase if phase < fr.FRICTION_PHASE0 else fr.decode(phase)[0]
        if base != DLSP:
            self.single_support_nfev += run.nfev
        return run


def _walk(rtol: float, stiff_legs: bool) -> tuple[Any, EventLog]:
    log = EventLog(FastIntegrator(rtol=rtol, atol=rtol * 1e-2, stiff_legs=stiff_legs))
    return simulate_steps(LIGHT, "er", RELEASE, N_STEPS, log), log


@pytest.fixture(scope="module")
def reference() -> tuple[Any, EventLog]:
    """Three ER steps with friction, DOP853 everywhere at rtol 1e-12 (stability-limited but exact)."""
    return _walk(1e-12, False)


def test_the_walk_has_stick_and_slip_in_single_support(reference) -> None:
    """The case is one where friction acts: single-support friction phases with a stuck and a slipping leg both
    occur, and stick/slip guards fire (else the tests below would not exercise them)."""
    walk, log = reference
    assert walk.failure is None and len(walk.steps) == N_STEPS
    states = [fr.decode(code) for code, _ in log.events if code >= fr.FRICTION_PHASE0]
    single = [(s1, s2) for base, s1, s2 in states if base != DLSP]
    assert any(fr.STUCK in s for s in single)
    assert any(s2 in (fr.SLIP_UP, fr.SLIP_DOWN) for _, s2 in single)
    assert any(g in fr.friction_guards(code) for code, g in log.events if code >= fr.FRICTION_PHASE0)
    assert all(s.friction_work_J > 0.0 for s in walk.steps)


@pytest.mark.parametrize("rtol", [1e-8, 1e-10])
def test_light_legs_with_friction_agree_with_tight_dop853_in_bounded_evaluations(reference, rtol: float) -> None:
    """Rosenbrock stick/slip phases: the same sequence of friction phases and fired guards as the tight DOP853
    walk, periods, post-impact states, friction work and stuck times within 1e-7 (s, rad, rad/s, J, s), and single
    support in under a third of DOP853's field evaluations at the same rtol (today's main: the same count, all
    of these phases on DOP853 held by its stability limit)."""
    ref, ref_log = reference
    walk, log = _walk(rtol, True)
    assert walk.failure is None and len(walk.steps) == N_STEPS
    assert log.events == ref_log.events
    for got, want in zip(walk.steps, ref.steps, strict=True):
        assert got.period_s == pytest.approx(want.period_s, abs=1e-7)
        np.testing.assert_allclose(got.y_plus, want.y_plus, atol=1e-7)
        assert got.friction_work_J == pytest.approx(want.friction_work_J, abs=1e-7)
        np.testing.assert_allclose(got.stick_s, want.stick_s, atol=1e-7)
    _dop, dop_log = _walk(rtol, False)
    assert log.single_support_nfev * 3 < dop_log.single_support_nfev


def test_light_leg_friction_step_energy_balance() -> None:
    """Invariant: over one step's continuous phases the mechanical energy lost equals the dampers' work (the
    Rosenbrock phase's 11th component, sum c L_i'^2 dt) plus the friction work (F_c times the distance slid), to
    1e-9 J of the ~0.05 J; and the friction work is a sizeable part of it."""
    mech = Mechanics.of(LIGHT)
    y0 = state_from_section(mech, RELEASE)
    log = EventLog(FastIntegrator(rtol=1e-10, atol=1e-12))
    res = simulate_step(mech, "er", y0, log, track_dissipation=True)
    lost = mech.energy(y0[:5], y0[5:]) - mech.energy(res.y_minus[:5], res.y_minus[5:])
    assert res.friction_work_J > 1e-3
    assert lost == pytest.approx(res.dissipated_J + res.friction_work_J, abs=1e-9)
    # the balance fails without either term: both are far above the tolerance
    assert res.dissipated_J > 1e-3
    # and single support went through the Rosenbrock method (DOP853 needs tens of thousands here)
    dop = EventLog(FastIntegrator(rtol=1e-10, atol=1e-12, stiff_legs=False))
    simulate_step(mech, "er", y0, dop, track_dissipation=True)
    assert log.single_support_nfev * 5 < dop.single_support_nfev


def test_table1_with_friction_stays_on_dop853() -> None:
    """Table 1's legs (fastest root ~270 1/s) keep DOP853 with friction too: the stiff_legs switch changes nothing,
    bit for bit."""
    params = replace(WheelParams(), guide_friction_n=FRICTION_N)
    z = np.array([-0.465155, 2.604441])
    walks = [simulate_steps(params, "er", z, 1, FastIntegrator(rtol=1e-8, stiff_legs=s)) for s in (True, False)]
    assert walks[0].steps[0].period_s == walks[1].steps[0].period_s
    assert np.array_equal(walks[0].steps[0].y_plus, walks[1].steps[0].y_plus)
