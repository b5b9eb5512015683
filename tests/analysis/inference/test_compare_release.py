"""The comparison's release on a compliant wheel (issue 31): with the first impact's angle offset fitted, the
simulated periods after the first follow the truth's.

Truth: the simulator's ER wheel walked by `floquet_truth.er_walk` (k = 1550 N/m, c = 10 N s/m, away from Table 1's
2700 and 8), released into its gait (its post-impact state, with the speed times 1.06) for 10 steps, written as a
Vicon Tracker export (`critical_truth.record`) and imported; the trial is given its true slope and the simulator the truth's
wheel, so what is left of the periods is the release's and the import's. The periods are checked against the
truth's own (its impact times, noise free), not the imported ones. With the rigid release (on main, and with
``fit_first_angle=False``) the second period missed the truth by 2.4 ms and the sixth still by 0.8 ms; with the
offset (0.44 deg, its test's p = 0.007 < 0.01) all of 2..9 were within 0.03 ms (measured with seed 100; the
import's noise on a period is about 0.3 ms). Since session 21 the importer places the first impact at its own
touchdown (`steps._first_touchdown`): this walk's first period moved by 0.26 ms (-0.05 -> +0.21 ms against the
truth's) and the test's p to 0.011, just above the level; the test's power is measured over walks in
docs/trials.md ("The offset's test, measured for its size"), so here the offset is kept whenever it lowers the
cost (the level at 1, as `first_angle_study.py`'s "always") to check what keeping it does, and the test's own
verdict is checked separately (p < 0.05: regression snapshot, 0.011 at session 21).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rimless.analysis.inference import compare
from rimless.analysis.inference.compare import FIRST_ANGLE_P, PERIOD_NOISE_FLOOR_S, Simulator, compare_trial
from rimless.analysis.inference.release import FIRST_ANGLE_RANGE_RAD
from rimless.analysis.kinematics.build import import_trial
from rimless.analysis.validation.critical_truth import record
from rimless.analysis.validation.floquet_truth import er_walk
from rimless.analysis.validation.importer_coverage import Lab
from rimless.sim.model.params import WheelParams

TRUTH = WheelParams(stiffness_n_per_m=1550.0, damping_ns_per_m=10.0)


def test_the_periods_after_the_first_follow_a_wheel_released_into_its_gait(tmp_path) -> None:
    rng = np.random.default_rng(100)
    slope = 2.4
    wk = er_walk(TRUTH, slope, 0.0, 10, rng, release=1.06)
    tr = import_trial(record(wk, tmp_path / "t0.csv", rng, Lab(up="z", heading_deg=30.0, markers=False), rest_s=0.0))
    tr = dataclasses.replace(tr, meta=dataclasses.replace(tr.meta, slope_deg=slope))
    true_periods = np.diff(wk.impacts)

    rigid = compare_trial(tr, Simulator(model="er", params=TRUTH, fit_first_angle=False))
    tested = compare_trial(tr, Simulator(model="er", params=TRUTH))
    assert tested.first_angle is not None and tested.first_angle_offset_p < 0.05
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(compare, "FIRST_ANGLE_P", 1.0)  # kept whenever the cost falls
        released = compare_trial(tr, Simulator(model="er", params=TRUTH))
    n = min(true_periods.size, released.sim_period_s.size)
    assert n >= 8 and released.status == "ok", released.message
    miss_rigid = rigid.sim_period_s[1:n] - true_periods[1:n]
    miss = released.sim_period_s[1:n] - true_periods[1:n]
    assert abs(miss_rigid[0]) > 1e-3  # the rigid release's approach to the gait: the test can tell the two apart
    assert np.max(np.abs(miss)) < 0.3e-3, miss  # within the import's noise on one period
    assert released.mean_abs_period_error_s < rigid.mean_abs_period_error_s
    # the offset, reported with its unit; the rigid release reports none
    assert 0.0 < abs(released.first_angle_offset_rad) <= FIRST_ANGLE_RANGE_RAD
    assert released.first_angle is not None and released.first_angle.kept and math.isnan(rigid.first_angle_offset_p)
    row = released.metrics()
    assert row["first_angle_offset_deg"] == math.degrees(released.first_angle_offset_rad)
    assert rigid.metrics()["first_angle_offset_deg"] == 0.0


def test_a_dropped_offset_says_it_was_tested_with_its_statistic_and_what_the_choice_moves(tmp_path) -> None:
    """A wheel released from the rigid pose (the tests' independent truth held on uncompressed legs: the model's
    release itself, true offset 0; c, k away from Table 1): the offset is tested and not kept (p 0.67 when written),
    and the output says so with the statistic (its p-value is the F or chi^2 tail of it, a closed form), the offset
    the fit found, and how far keeping it would move a simulated period (checked on the walk simulated with it).
    On main none of these keys existed: the row said offset 0 and a p-value only."""
    from scipy.stats import chi2, f

    from tests.support.analysis_trial_truth import simulate_wheel, write_csv

    c_ns_per_m, k_n_per_m, slope = 13.25, 3743.0, 2.66
    tr = simulate_wheel(
        slope, 2.03, c_ns_per_m=c_ns_per_m, k_n_per_m=k_n_per_m, max_steps=10, ending="caught", seed=7000,
        yaw_deg=108.0, release_leg="uncompressed",
    )  # fmt: skip
    trial = import_trial(write_csv(tmp_path / "t.csv", tr))
    trial = dataclasses.replace(trial, meta=dataclasses.replace(trial.meta, slope_deg=slope))
    sim = Simulator(model="er", params=WheelParams(stiffness_n_per_m=k_n_per_m, damping_ns_per_m=c_ns_per_m))
    res = compare_trial(trial, sim)
    row = res.to_dict()
    assert res.status == "ok", res.message
    assert row["first_angle_offset_tested"] is True and row["first_angle_offset_kept"] is False
    assert row["first_angle_offset_deg"] == 0.0 and row["first_angle_offset_level"] == FIRST_ANGLE_P
    p, stat, test = row["first_angle_offset_p"], row["first_angle_offset_statistic"], row["first_angle_offset_test"]
    assert p >= FIRST_ANGLE_P
    dof = res.n_steps - 2
    assert test in (f"F(1, {dof})", "chi2(1)")
    assert p == pytest.approx(f.sf(stat, 1, dof) if test.startswith("F") else chi2.sf(stat, 1), rel=1e-9)
    fitted = math.radians(row["first_angle_offset_fitted_deg"])
    assert 0.0 < abs(fitted) <= FIRST_ANGLE_RANGE_RAD
    # keeping it would have simulated this walk: its periods after the first differ from the compared ones by
    # what the row says
    kept = sim.walk(slope, res.first_angle.fitted_theta_dot_rad_s, res.n_steps + 2, record=False, offset_rad=fitted)
    moved = np.array([kept.steps[1 + i].period_s for i in range(res.n_steps)]) - res.sim_period_s
    assert row["first_angle_choice_period_change_ms"] == pytest.approx(np.max(np.abs(moved[1:])) * 1e3, abs=0.01)
    # the choice moves something (0.036 ms at session 21, the importer's first impact at its touchdown; 0.05 or more
    # before: regression snapshot)
    assert row["first_angle_choice_period_change_ms"] > 0.01
    # what the test assumed about the periods' noise, said: the floor for chi2, the fit's residuals (not below it)
    # for F
    # for F; since session 23 the test is weighed by the importer's per-impact sds: chi2 at their rms period sd (the
    # closed form of `period_covariance`'s diagonal), F at that scaled by the residuals
    noise = row["first_angle_offset_noise_ms"]
    source = row["first_angle_offset_noise_source"]
    if row["first_angle_offset_weighted"]:
        v = trial.impact_sd_s**2
        period_sd_ms = float(np.sqrt(np.mean(v[:-1] + v[1:]))) * 1e3
        assert "per-impact sds" in source
        if test == "chi2(1)":
            assert noise == pytest.approx(period_sd_ms, rel=1e-9)
        else:
            assert noise > period_sd_ms and "residuals" in source
    elif test == "chi2(1)":
        assert noise == pytest.approx(PERIOD_NOISE_FLOOR_S * 1e3) and "floor" in source
    else:
        assert noise >= PERIOD_NOISE_FLOOR_S * 1e3 and "residuals" in source
