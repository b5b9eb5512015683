"""The calibration's release state on a compliant wheel (issue 31): its first simulated period fits the truth's.

Truth: the simulator's ER wheel walked by `floquet_truth.er_walk` (k = 1600 N/m, c = 15 N s/m: soft and damped, away
from Table 1's 2700 and 8), released into its gait (the gait's post-impact state, theta+ 5.4 deg below the rigid
touchdown -alpha/2, with its speed times 1.06 and 0.97), written as Vicon Tracker exports (`critical_truth.record`)
and imported; each trial is given its true slope, so what is left of the first period is the release's. The first
simulated period is taken from the simulator itself (`rimless.sim.fast.fast_step`: one release step from the
rigid touchdown at the reported speed, the post-impact angle moved by the reported offset, then the first
measured step), not from the calibration's code, and compared with the truth's first period. With no offset (the
calibration before this change) it missed by 1.9-2.6 ms, four to six times the import's noise on a period
(measured on this series with seed 100).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rimless.analysis.inference.calibrate import calibrate
from rimless.analysis.kinematics.build import import_trial
from rimless.analysis.validation.critical_truth import record
from rimless.analysis.validation.floquet_truth import er_walk
from rimless.analysis.validation.importer_coverage import Lab
from rimless.sim.fast import fast_step
from rimless.sim.model.params import WheelParams

TRUTH = WheelParams(stiffness_n_per_m=1600.0, damping_ns_per_m=15.0)


def test_the_first_period_of_a_wheel_released_into_its_gait_fits_the_truth_within_its_noise(tmp_path) -> None:
    rng = np.random.default_rng(100)
    lab = Lab(up="z", heading_deg=30.0, markers=False)
    trials, walks = [], []
    for j, (slope, release) in enumerate(((2.4, 1.06), (3.4, 0.97))):
        wk = er_walk(TRUTH, slope, 0.0, 10, rng, release=release)
        tr = import_trial(record(wk, tmp_path / f"t{j}.csv", rng, lab, rest_s=0.0))
        trials.append(dataclasses.replace(tr, meta=dataclasses.replace(tr.meta, slope_deg=slope)))
        walks.append(wk)
    res = calibrate(trials, ["t0", "t1"], ("c",), params=TRUTH)
    sigma_period_s = math.sqrt(2.0) * res.adequacy["noise"]["impact_time_ms"] * 1e-3  # a period: two impacts
    assert 0.1e-3 < sigma_period_s < 0.6e-3  # the import's noise on objects (0.22 ms an impact, session 16)
    for row, wk, tr in zip(res.residuals, walks, trials):
        p = res.calibrated_params.replace(slope_rad=math.radians(tr.meta.slope_deg))
        # the walk the calibration reports: released at the rigid touchdown one step before the first measured
        # impact, whose post-impact angle is then moved by the fitted offset (0 on main: no such key)
        z1 = fast_step(p, "er", np.array([-math.pi / 8, row["calibrated_release_theta_dot_rad_s"]])).z_next
        first = fast_step(p, "er", z1 + np.array([math.radians(row.get("first_angle_offset_deg", 0.0)), 0.0]))
        true_first = float(np.diff(wk.impacts)[0])
        assert abs(first.period_s - true_first) < 3.0 * sigma_period_s, (row["trial"], first.period_s - true_first)
    assert res.adequacy["fits"], res.adequacy["statement"]
    assert "first period is no longer excused" in res.adequacy["allowed"]["periods"]
