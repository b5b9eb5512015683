"""`rimless.analysis.inference.release`: the walk from a release with the first impact's angle moved, checked
against the simulator's compiled step map (`rimless.sim.fast.fast_step`, a separate implementation of the step),
and the least squares of the offset recovering a known release (noise-free)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.inference.release import fit_first_angle, map_frequencies, walk_from_release
from rimless.sim.fast import fast_step
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import make_integrator
from rimless.sim.step.gait import simulate_steps

P = WheelParams(stiffness_n_per_m=2000.0, damping_ns_per_m=12.0).replace(slope_rad=math.radians(3.0))
Z0 = np.array([-math.pi / 8, 2.5])  # walks at offsets -0.07 to 0.03 rad


def test_at_offset_zero_it_is_the_simulators_walk() -> None:
    integ = make_integrator("auto", rtol=1e-8)
    got = walk_from_release(P, "er", float(Z0[1]), 4, integ, 1.0, 0.0)
    ref = simulate_steps(P, "er", Z0, 4, integ, record_dt=1.0)
    assert len(ref.steps) == 4 and [s.period_s for s in got.steps] == [s.period_s for s in ref.steps]


@pytest.mark.parametrize("offset", [-0.06, 0.03])
def test_the_offset_moves_the_first_post_impact_angle_and_the_walk_stays_one(offset: float) -> None:
    integ = make_integrator("auto", rtol=1e-9)
    g = walk_from_release(P, "er", float(Z0[1]), 4, integ, 2e-3, offset)
    assert len(g.steps) == 4 and g.failure is None
    z1 = fast_step(P, "er", Z0, rtol=1e-10).z_next + np.array([offset, 0.0])
    z = z1
    for s in g.steps[1:]:  # every step after the moved impact, against the compiled map from the moved state
        r = fast_step(P, "er", z, rtol=1e-10)
        assert s.period_s == pytest.approx(r.period_s, abs=2e-6)
        z = r.z_next
    for a, b in zip(g.steps, g.steps[1:]):  # one walk: each step starts where the last ended
        assert b.t_start_s == pytest.approx(a.t_start_s + a.period_s, abs=1e-12)
    t, k = g.table["t_s"], g.table["step"]
    assert np.all(np.diff(t) >= 0) and set(np.unique(k)) == {0, 1, 2, 3}
    assert t[-1] == pytest.approx(sum(s.period_s for s in g.steps), abs=3e-3)


def test_the_least_squares_recover_a_known_release() -> None:
    w_true, a_true = 2.6, -0.07  # an ER gait's post-impact angle lies 0.05-0.10 rad below the rigid touchdown
    f_meas = map_frequencies(P, "er", w_true, 8, a_true, 1e-9)
    assert np.all(f_meas > 0)
    got = fit_first_angle(lambda a, w: map_frequencies(P, "er", w, 8, a, 1e-9) - f_meas, f_meas, 2.4)
    assert got is not None
    assert got[0] == pytest.approx(a_true, abs=1e-4) and got[1] == pytest.approx(w_true, rel=1e-4)
