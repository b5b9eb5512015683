"""The one event engine (rimless.sim.integrate.events): closed-form checks of its rules, and the compiled
twin (rimless.sim.fast.rk, codes and directions from the guard table) against the engine on the same phase."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.sim import fast
from rimless.sim.fast import model as fm
from rimless.sim.fast import step as fs
from rimless.sim.integrate import events
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import dynamics
from rimless.sim.model import guards as ev
from rimless.sim.model.mechanics import Mechanics
from tests.support import sim_dip


def test_the_compiled_path_uses_the_table() -> None:
    """The compiled kernels' guard codes and the directions the compiled step passes are the table's."""
    for name in ("LIFTOFF_A", "STALL", "CLUTCH_LOCK", "TOUCHDOWN", "LIFTOFF_B"):
        assert getattr(fm, name) == getattr(ev, name), name
    for codes, dirs in (
        (fs.PHASE_DLSP_CODES, fs.PHASE_DLSP_DIRS),
        (fs.PHASE_FREE_ER_CODES, fs.PHASE_FREE_ER_DIRS),
        (fs.PHASE_SS_CODES, fs.PHASE_SS_DIRS),
    ):
        assert [int(d) for d in dirs] == [ev.DIRECTION[int(c)] for c in codes]


def test_crossed_follows_the_direction_and_the_start_rule() -> None:
    g_old = np.array([1.0, -1.0, 1.0, 0.0, 0.0])
    g_new = np.array([-1.0, 1.0, -1.0, -1.0, -1.0])
    dirs = np.array([-1.0, +1.0, +1.0, -1.0, 0.0])
    assert list(events.crossed(g_old, g_new, dirs)) == [0, 1, 3, 4]  # solve_ivp: a start at 0 counts
    assert list(events.crossed(g_old, g_new, dirs, strict=True)) == [0, 1]  # only from the non-firing side


def test_first_dip_finds_the_first_zero_of_a_closed_form_dip() -> None:
    """g(t) = (t - 0.5)^2 - 0.01 on [0, 1]: positive at both ends, first zero at t = 0.4."""
    assert events.first_dip(lambda t: (t - 0.5) ** 2 - 0.01, 0.0, 1.0) == pytest.approx(0.4, abs=1e-12)
    # a minimum that stays above zero is no dip, however deep relative to the ends
    assert events.first_dip(lambda t: (t - 0.5) ** 2 + 1e-6, 0.0, 1.0) is None


def test_the_locator_finds_a_dip_inside_one_step_on_a_closed_form_trajectory() -> None:
    """A force guard g(t) = 4 t^2 - 3.9 t + 0.75 over one step [0, 1]: positive at both ends (0.75, 0.85),
    negative inside; the locator returns its first zero (3.9 - sqrt(3.21)) / 8 with the state there, and
    nothing when the same curve is lifted to stay positive."""

    def g(t: float, lift: float = 0.0) -> np.ndarray:
        return np.array([4 * t * t - 3.9 * t + 0.75 + lift])

    for lift, expected in ((0.0, (3.9 - math.sqrt(3.21)) / 8), (0.3, None)):
        loc = events.EventLocator(
            (ev.STALL, ev.LIFTOFF_B),
            lambda c, y: 1.0 if c == ev.STALL else float(y[0]),
            0.0,
            g(0.0, lift),
            dense_on=lambda ta, _ya, tb, lift=lift: lambda t: g(t, lift),
        )
        found = loc.step(0.0, 1.0, g(1.0, lift), lambda lift=lift: lambda t: g(t, lift), last_step=True)
        if expected is None:
            assert found is None
        else:
            assert found is not None and found[1] == 1  # the index of LIFTOFF_B in the codes
            assert found[0] == pytest.approx(expected, abs=1e-12)
            assert found[2][0] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("rtol", [1e-10, 1e-8])
def test_the_compiled_twin_locates_the_same_guard_as_the_engine(rtol: float) -> None:
    """One single-support phase with a stance-force dip inside a solver step: the compiled integrator
    (fast.rk, the twin) and the reference integrator (the engine) both end it at the dip's first zero."""
    mech = Mechanics.of(sim_dip.DIP_PARAMS)
    t1, y1 = sim_dip.single_support_start()
    guards = (ev.TOUCHDOWN, ev.STALL, ev.LIFTOFF_B)
    ref = ScipyIntegrator(rtol=rtol, atol=rtol * 1e-2).run_phase(mech, dynamics.SLSP_FREE, y1, t1, guards, 5.0)
    twin = fast.FastIntegrator(rtol=rtol, atol=rtol * 1e-2).run_phase(mech, dynamics.SLSP_FREE, y1, t1, guards, 5.0)
    assert ref.guard == twin.guard == ev.LIFTOFF_B
    assert twin.t_end == pytest.approx(ref.t_end, abs=1e-6)
    assert abs(ev.guard_value(mech, dynamics.SLSP_FREE, ev.LIFTOFF_B, twin.y_end)) < 1e-6  # N: at the zero
