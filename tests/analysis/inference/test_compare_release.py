"""The comparison's release on a compliant wheel (issue 31): with the first impact's angle offset fitted, the
simulated periods after the first follow the truth's.

Truth: the simulator's ER wheel walked by `floquet_truth.er_walk` (k = 1550 N/m, c = 10 N s/m, away from Table 1's
2700 and 8), released into its gait (its post-impact state, with the speed times 1.06) for 10 steps, written as a
Vicon Tracker export (`critical_truth.record`) and imported; the trial is given its true slope and the simulator the truth's
wheel, so what is left of the periods is the release's and the import's. The periods are checked against the
truth's own (its impact times, noise free), not the imported ones. With the rigid release (on main, and with
``fit_first_angle=False``) the second period missed the truth by 2.4 ms and the sixth still by 0.8 ms; with the
offset (0.44 deg, its test's p = 0.007 < 0.01) all of 2..9 were within 0.03 ms (measured with seed 100; the
import's noise on a period is about 0.3 ms).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rimless.analysis.inference.compare import FIRST_ANGLE_P, Simulator, compare_trial
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
    assert released.first_angle_offset_p < FIRST_ANGLE_P and math.isnan(rigid.first_angle_offset_p)
    row = released.metrics()
    assert row["first_angle_offset_deg"] == math.degrees(released.first_angle_offset_rad)
    assert rigid.metrics()["first_angle_offset_deg"] == 0.0
