"""`rimless.analysis.validation.er_truth`: the ER truth written apart from `rimless.sim` (hub coordinates,
Newton-Euler, scipy events) against the simulator's step map, the only place the two meet; and its own invariants.

States and wheels away from Table 1 (k 1500-4000 N/m, c 2-20 N s/m, slopes 2-3.5 deg; F_c 0 and 0.05-0.6 N).
The tolerances: with F_c = 0 both integrate the same smooth phases to rtol 1e-11 and locate the same events, so
they agree to the integrators' error (measured 1e-14 to 5e-11; asserted 1e-8). With guide friction both switch
stick/slip exactly at events (the simulator's friction phases, this truth's own state machine), so the
agreement stays at the events' location error (measured 5e-12 to 5e-11 on these states; asserted 1e-8).
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.validation import er_truth as et

#: (k N/m, c N s/m, slope deg, F_c N, theta+ rad, theta'+ rad/s): post-impact states off each wheel's gait
CASES = [
    (2200.0, 12.0, 2.5, 0.0, -0.37, 2.4),
    (3500.0, 4.0, 3.0, 0.0, -0.37, 2.4),
    (1600.0, 18.0, 3.4, 0.0, -0.40, 2.9),
    (2200.0, 12.0, 2.5, 0.4, -0.37, 2.4),
    (3500.0, 4.0, 3.0, 0.05, -0.37, 2.4),
    (3900.0, 2.5, 2.1, 0.6, -0.38, 2.2),
]


def test_the_truth_does_not_import_the_simulator_or_the_methods() -> None:
    """Every import statement of the module (top level and inside functions), read from its syntax tree."""
    tree = ast.parse(Path(et.__file__).read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    banned = ("rimless.sim", "rimless.analysis.inference", "rimless.analysis.kinematics")
    assert names and not [n for n in names if n.startswith(banned)], names


@pytest.mark.parametrize(("k", "c", "slope_deg", "fc", "th", "thd"), CASES)
def test_step_map_agrees_with_the_simulator(k: float, c: float, slope_deg: float, fc: float, th: float,
                                             thd: float) -> None:  # fmt: skip
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.params import WheelParams
    from rimless.sim.model.section import state_from_section
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.hybrid import simulate_step

    p = WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c, slope_rad=math.radians(slope_deg), guide_friction_n=fc)
    z = np.array([th, thd])
    sim = simulate_step(
        Mechanics.of(p), "er", state_from_section(Mechanics.of(p), z), make_integrator("auto", rtol=1e-11)
    )
    w = et.ERWheel.of(p)
    truth = et.step(w, et.state_from_section(w, z), rtol=1e-11)
    assert truth.y_plus[[2, 7]] == pytest.approx(sim.y_plus[[2, 7]], abs=1e-8)
    assert truth.period_s == pytest.approx(sim.period_s, abs=1e-8)
    # the whole post-impact state: the simulator's foot-b coordinates mapped to the hub's
    q, qd = sim.y_plus[:5], sim.y_plus[5:]
    hub_y = q[1] + q[3] * math.cos(q[2])
    hub_vx = qd[0] + qd[3] * math.sin(q[2]) + q[3] * qd[2] * math.cos(q[2])
    assert truth.y_plus[1] - truth.y_plus[3] * math.cos(truth.y_plus[2]) == pytest.approx(0.0, abs=1e-8)
    assert truth.y_plus[1] == pytest.approx(hub_y, abs=1e-8)
    assert truth.y_plus[5] == pytest.approx(hub_vx, abs=1e-8)
    assert truth.y_plus[[4, 9]] == pytest.approx(sim.y_plus[[4, 9]], abs=1e-8)
    assert [n for n, _ in truth.phases] == ["dlsp", "slsp-free", "slsp-clutched"]
    assert truth.snap_added_j == pytest.approx(sim.relabel_snap_J, abs=1e-8)
    if fc > 0:
        assert truth.friction_work_j == pytest.approx(sim.friction_work_J, abs=1e-8)


def test_energy_balance_of_a_frictionless_undamped_phase() -> None:
    """c = 0, F_c = 0: in each continuous phase T + V is conserved (the constraints do no work), so the energy
    at the impact's start equals the energy right after the previous impact (checked to the integrator's 1e-8)."""
    w = et.ERWheel(damping_ns_per_m=0.0, stiffness_n_per_m=3000.0, slope_rad=math.radians(2.5))
    y0 = et.state_from_section(w, np.array([-0.37, 2.4]))

    def energy(y: np.ndarray) -> float:
        return et.energy(w, y)

    samples: list = []
    t, y1, why, _ = et._run_phase(w, et._enter(w, et.DLSP, y0), y0, 0.0, 1e-11, 3.0, samples)
    assert why == "liftoff" and energy(y1) == pytest.approx(energy(y0), abs=1e-8)
    t, y2, why, _ = et._run_phase(w, et._enter(w, et.SLSP_FREE, y1), y1, t, 1e-11, 3.0, samples)
    assert why == "lock" and energy(y2) == pytest.approx(energy(y1), abs=1e-8)


def test_section_state_satisfies_the_constraints_and_the_impact_stops_both_feet() -> None:
    w = et.ERWheel(stiffness_n_per_m=1800.0, damping_ns_per_m=15.0, slope_rad=0.04)
    y = et.state_from_section(w, np.array([-0.36, 2.1]), foot_b_x_m=0.3)
    J, _ = et._jacobians(w, y[:5], y[5:])
    u, _ = et._units(y[2])
    assert y[0] + y[3] * u[0, 0] == pytest.approx(0.3, abs=1e-15)  # foot b where asked, on the slope
    assert y[1] + y[3] * u[0, 1] == pytest.approx(0.0, abs=1e-15)
    assert y[1] + y[4] * u[1, 1] == pytest.approx(0.0, abs=1e-14)  # foot a on the slope
    assert np.abs(J[0] @ y[5:]).max() < 1e-12 and np.abs(J[1] @ y[5:]).max() < 1e-12
    st = et.step(w, y, rtol=1e-10)
    J, _ = et._jacobians(w, st.y_plus[:5], st.y_plus[5:])
    assert np.abs(J[0] @ st.y_plus[5:]).max() < 1e-12 and np.abs(J[1] @ st.y_plus[5:]).max() < 1e-12


def test_fixed_point_is_a_fixed_point_and_a_stall_is_refused() -> None:
    w = et.ERWheel(stiffness_n_per_m=2500.0, damping_ns_per_m=6.0, slope_rad=math.radians(2.8))
    z = et.fixed_point(w)
    assert et.step_map(w, z) == pytest.approx(z, abs=1e-8)
    with pytest.raises(et.TruthFailure) as err:
        et.step(w, et.state_from_section(w, np.array([z[0], 0.4])))
    assert err.value.reason == "stall"


def test_a_walk_from_its_own_gait_matches_the_simulators_walk() -> None:
    """`er_truth_walk` (this truth's own fixed point and steps) against `floquet_truth.er_walk` (the simulator's)
    on one wheel with guide friction, released 5 % fast: the impact times and post-impact speeds agree to 1e-6
    (both solve their fixed point to about 1e-9), and the recorded paths to 1e-5 (m, rad: both are sampled every
    1 ms, the simulator's at its solver steps too, and compared by linear interpolation, whose error near an
    impact's kink measured 1.1e-6 rad)."""
    from rimless.analysis.validation.floquet_truth import er_walk
    from rimless.sim.model.params import WheelParams

    p = WheelParams(stiffness_n_per_m=3200.0, damping_ns_per_m=5.0, guide_friction_n=0.3)
    mine = et.er_truth_walk(p, 2.5, 0.0, 4, np.random.default_rng(1), release=1.05)
    sim = er_walk(p, 2.5, 0.0, 4, np.random.default_rng(1), release=1.05)
    assert mine.impacts == pytest.approx(sim.impacts, abs=1e-6)
    assert mine.post_impact_speed == pytest.approx(sim.post_impact_speed, abs=1e-6)
    t = np.linspace(0.0, min(mine.t[-1], sim.t[-1]), 200)
    for a, b in ((mine.x, sim.x), (mine.h, sim.h), (mine.body, sim.body)):
        assert np.interp(t, mine.t, a) == pytest.approx(np.interp(t, sim.t, b), abs=1e-5)


def _chain(params, slopes_deg: list[float], z0: np.ndarray, release: float) -> tuple[list[float], list[float]]:
    """Impact times (s) and post-impact speeds (rad/s) of `et.step` chained by hand from the gait ``z0`` released
    with theta'+ times ``release``, step k on slope ``slopes_deg[k]``."""
    w0 = et.ERWheel.of(params, slope_rad=math.radians(2.5))
    y = et.state_from_section(w0, z0 * np.array([1.0, release]))
    t, times, speeds = 0.0, [], []
    for s in slopes_deg:
        st = et.step(et.ERWheel.of(params, slope_rad=math.radians(s)), y, rtol=1e-9)
        t += st.period_s
        y = st.y_plus
        times.append(t)
        speeds.append(float(y[7]))
    return times, speeds


def test_a_walk_without_wander_is_its_steps_chained_by_hand_whatever_the_seed() -> None:
    """slope sd 0: the walk is `step` chained from the truth's own gait on the nominal slope, bit for bit, and the
    generator's draws (one a step, as `er_walk` draws) change nothing; every step is recorded on 2.5 deg."""
    from rimless.sim.model.params import WheelParams

    p = WheelParams(stiffness_n_per_m=2600.0, damping_ns_per_m=9.0)
    a = et.er_truth_walk(p, 2.5, 0.0, 3, np.random.default_rng(1), release=1.04)
    b = et.er_truth_walk(p, 2.5, 0.0, 3, np.random.default_rng(99), release=1.04)
    z0 = et.fixed_point(et.ERWheel.of(p, slope_rad=math.radians(2.5)), rtol=1e-9)
    times, speeds = _chain(p, [2.5] * 4, z0, 1.04)
    assert a.impacts.tolist() == times[:3] and a.post_impact_speed.tolist() == speeds[:3]
    assert np.array_equal(a.t, b.t) and np.array_equal(a.body, b.body) and np.array_equal(a.x, b.x)
    assert a.step_slope_deg is not None and a.step_slope_deg.tolist() == [2.5] * 4


def test_a_wandering_walk_walks_each_step_on_its_drawn_slope_as_the_simulators_walk_does() -> None:
    """slope sd 0.6 deg: step k walks 2.5 + 0.6 n_k deg, n_k the generator's k-th standard normal (drawn here from
    the same seed), recorded in ``step_slope_deg``; the post-impact speeds are `step` chained by hand on those
    slopes (bit for bit); and the simulator's wandering walk (`floquet_truth.er_walk`, the same seed) draws the
    same slopes and meets this one to 1e-6 in impact times and speeds, the step-map test's agreement carried over
    four steps (measured 5e-9 s and 1.4e-9 rad/s at k 2000, c 14 over 15 steps)."""
    from rimless.analysis.validation.floquet_truth import er_walk
    from rimless.sim.model.params import WheelParams

    p = WheelParams(stiffness_n_per_m=2000.0, damping_ns_per_m=14.0)
    drawn = (2.5 + 0.6 * np.random.default_rng(5).standard_normal(5)).tolist()
    mine = et.er_truth_walk(p, 2.5, 0.6, 4, np.random.default_rng(5), release=0.97)
    assert mine.step_slope_deg is not None and mine.step_slope_deg.tolist() == drawn
    z0 = et.fixed_point(et.ERWheel.of(p, slope_rad=math.radians(2.5)), rtol=1e-9)
    times, speeds = _chain(p, drawn, z0, 0.97)
    assert mine.impacts.tolist() == times[:4] and mine.post_impact_speed.tolist() == speeds[:4]
    sim = er_walk(p, 2.5, 0.6, 4, np.random.default_rng(5), release=0.97)
    assert sim.step_slope_deg is not None and sim.step_slope_deg.tolist() == drawn
    assert mine.impacts == pytest.approx(sim.impacts, abs=1e-6)
    assert mine.post_impact_speed == pytest.approx(sim.post_impact_speed, abs=1e-6)


def test_the_truths_multiplier_is_the_simulators_eigenvalue() -> None:
    """`et.multiplier` (this truth's step map differenced at its own gait) against the simulator's dominant
    eigenvalue (`model_multiplier`) at the floquet study's wheel (k 2000, c 14, 2.5 deg): measured 0.73806777 both,
    3.7e-10 apart; asserted 1e-6 (the differences' error, rtol 1e-11 over h 1e-5)."""
    from rimless.analysis.inference.floquet import model_multiplier
    from rimless.sim.model.params import WheelParams

    p = WheelParams(stiffness_n_per_m=2000.0, damping_ns_per_m=14.0, slope_rad=math.radians(2.5))
    mine = et.multiplier(et.ERWheel.of(p))
    assert mine == pytest.approx(model_multiplier(p, "er")["eigenvalue"], abs=1e-6)
    assert 0.5 < mine < 0.9
