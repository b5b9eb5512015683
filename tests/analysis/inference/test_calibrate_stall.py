"""A recorded stall in the calibration (issue 31, session 21): a trial that stalled says so in the least squares,
and a simulated walk that stalls where the recording walked is never free.

Truth: `tests.support.analysis_trial_truth` (an ER wheel with c = 12 N s/m, k = 2200 N/m, away from Table 1's 8
and 2700; held on its legs, released, walked until it stalls: a rigid stance that rises, turns back and rests),
written as Vicon Tracker exports and read by the importer with the slope given. On low slopes it stalls after
0-4 impacts (measured: 0.3 deg at 2.4 rad/s after 2, 0.6 deg after 3, 1.0 deg after 4, 0.6 deg at 1.9 rad/s after
1, which the importer does not see). Before this change a stalled trial's stall said nothing: at c = 4 N s/m the
simulated walk of the 1.0 deg trial went on for three more steps past the recorded stall at no cost, a stall after
one period was refused ("fewer than two consecutive step periods"), and a walk that stalled in its release step
had a CoM residual of zeros (a flat 0 cost on an impact-line reference).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tests.support.analysis_trial_truth as tt
from rimless.analysis.inference import calibrate as cal
from rimless.analysis.kinematics.build import import_trial
from rimless.sim.model.params import WheelParams

C_TRUE, K_TRUE = 12.0, 2200.0
CASES = ((1.8, 1.9), (2.4, 2.4), (1.0, 2.4), (0.3, 2.4), (0.6, 1.9))


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """(truth, imported trial) per (slope deg, release rad/s) of `CASES`."""
    tmp = tmp_path_factory.mktemp("stall")
    out = {}
    for i, (s, w) in enumerate(CASES):
        tr = tt.simulate_wheel(s, w, c_ns_per_m=C_TRUE, k_n_per_m=K_TRUE, max_steps=9, ending="walked", seed=i)
        out[(s, w)] = (tr, import_trial(tt.write_csv(tmp / f"er_{s}_{w}.csv", tr), slope_deg=s))
    return out


def _independent_next_frequency(p: WheelParams, slope_deg: float, w: float, n: int) -> float:
    """The frequency (Hz) of step n + 1 after the release step of the simulator's own walk from (-alpha/2, w),
    0 when the walk stalls before it ends (`simulate_steps`, not the calibration's walk)."""
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.gait import simulate_steps

    g = simulate_steps(
        p.replace(slope_rad=math.radians(slope_deg)),
        "er",
        np.array([-math.pi / 8, w]),
        n + 2,
        make_integrator("auto", rtol=1e-8),
        record_dt=0.01,
    )
    return 1.0 / g.steps[n + 1].period_s if len(g.steps) > n + 1 else 0.0


def test_a_recorded_stall_rules_out_a_walk_that_goes_on(exports) -> None:
    """The 1.0 deg trial stalled after 3 periods. Its residuals hold one more row, the simulated next step's
    frequency over the period sigma: at the truth's c the simulated walk stalls too (0), at c = 4 N s/m it walks
    on (1.4 Hz, from the simulator directly). Fails before: no such row (the walk going on cost nothing)."""
    truth, trial = exports[(1.0, 2.4)]
    assert truth.outcome == "stalled" and trial.meta.outcome == "stalled"
    d = cal._trial_data(trial, "stall_1.0")
    assert not isinstance(d, str)
    n = d.periods_s.size
    assert n == truth.steps - 1 == 3 and d.stall_rows == 1
    assert d.stalled_after_s > 0.3  # the importer's rest (0.3 s) at least
    sim = cal._Sim("er", 1e-8, 2e-3)
    rel = cal._ReleaseFit(sim, lambda: None)
    rows = {}
    for c in (4.0, C_TRUE):
        p = WheelParams(damping_ns_per_m=c, stiffness_n_per_m=K_TRUE)
        w, _ = rel.fit(p, d, None)
        obj = cal._Objective(sim, cal._Globals.of(p, ["c"]), [d], lambda: None)
        r = obj.trial_res(p, 0, w, 0.0)
        assert r.size == n + 1 + d.t_s.size == obj.offs[-1]
        expected = _independent_next_frequency(p, d.slope_deg, w, n)
        assert r[n] * obj.sig["t"] == pytest.approx(expected, rel=1e-4, abs=1e-9)
        rows[c] = r[n] * obj.sig["t"]
    assert rows[C_TRUE] == 0.0  # the truth's model stalls where the recording did
    assert rows[4.0] > 1.0  # Hz: three more steps simulated past the recorded stall


def test_a_stall_after_one_period_is_fitted_and_one_without_a_period_is_refused_with_its_reason(exports) -> None:
    """0.3 deg: two impacts, one period, then the stall: usable (the period fixes the release speed, the stall says
    the next step never ends). Fails before: refused as "fewer than two consecutive step periods". 0.6 deg at 1.9
    rad/s: no impact the importer saw: refused, saying that the stall alone would fix only its release speed."""
    truth, trial = exports[(0.3, 2.4)]
    assert truth.outcome == "stalled" and len(trial.impact_time_s) == 2
    d = cal._trial_data(trial, "one")
    assert not isinstance(d, str), d
    assert d.periods_s.size == 1 and d.stall_rows == 1
    _, none = exports[(0.6, 1.9)]
    assert len(none.impact_time_s) < 2 and none.meta.outcome == "stalled"
    why = cal._trial_data(none, "none")
    assert isinstance(why, str) and "stalled after" in why and "release speed" in why


def test_a_walking_trial_records_no_stall(exports) -> None:
    """A walk whose data stop mid-step (the truth's ``walked`` ending) has no stall row: nothing is known after."""
    _, trial = exports[(1.8, 1.9)]
    d = cal._trial_data(trial, "walk")
    assert not isinstance(d, str) and d.stall_rows == 0 and math.isnan(d.stalled_after_s)


def test_a_walk_that_stalls_in_its_release_step_pays_for_the_com_curve_it_lacks(exports) -> None:
    """At a release of 0.5 rad/s the simulated wheel never leaves its release step on the 1.8 deg trial, which
    walked: every period residual is the whole measured frequency, and the CoM residuals are those of a flat curve
    (the wheel at rest) at the measured mean, their sum of squares n var(h) by hand. Fails before: zeros (an
    impact-line reference), a CoM part that cost nothing."""
    _, trial = exports[(1.8, 1.9)]
    d = cal._trial_data(trial, "walk")
    assert not isinstance(d, str)
    p = WheelParams(damping_ns_per_m=C_TRUE, stiffness_n_per_m=K_TRUE)
    sim = cal._Sim("er", 1e-8, 2e-3)
    rp, rh = cal._residuals(sim, p, d, 0.5, 0.0)
    np.testing.assert_allclose(rp, -1.0 / d.periods_s)
    assert rh.size == d.t_s.size > 0
    assert float(np.sum(rh**2)) == pytest.approx(d.com_m.size * float(np.var(d.com_m)), rel=1e-9)
    assert float(np.var(d.com_m)) > (1e-3) ** 2  # a walk's CoM swings by millimetres: not free


@pytest.mark.slow
def test_c_with_stalled_trials_beside_sustained_ones_is_covered(exports) -> None:
    """c fitted (k given, the truth's) on two sustained trials and two stalls (after 3 periods and after 1): the
    stalls are fitted (not refused), the simulated walks at the solution stall where they did (their stall rows
    0), and the truth lies in c's 95 % interval, within 3 %."""
    keys = ((1.8, 1.9), (2.4, 2.4), (1.0, 2.4), (0.3, 2.4))
    trials = [exports[k][1] for k in keys]
    names = [f"er_{s}_{w}" for s, w in keys]
    res = cal.calibrate(trials, names, ["c"], params=WheelParams(stiffness_n_per_m=K_TRUE))
    s = res.summary()
    assert not s.get("failed"), s.get("failed")
    (c,) = res.params
    lo, hi = c.ci95
    assert lo <= C_TRUE <= hi and abs(c.value - C_TRUE) <= 0.03 * C_TRUE, (c.value, c.se, c.note)
    stalled = {r["trial"]: r for r in s["residuals"] if r["trial"] in names[2:]}
    assert set(stalled) == set(names[2:])
    for r in stalled.values():
        assert r["calibrated_steps_reached"] == r["n_period"]
