"""The hub offset's stated standard error on walks whose speed changes a lot, against an independent truth.

Truth: `tests.support.analysis_trial_truth` (the simulator's ER dynamics, written apart from ``rimless.analysis``),
held and released at 2.6-3.0 rad/s on a 1.3-2.0 deg slope, well above its gait's speed: the wheel slows down over its
11 steps (its last step period is 1.3-2.5 times its first), and its legs compress less and less. Recorded as a Tracker object whose origin is 36 mm off
the hub in the wheel plane (`ORIGIN_BODY_M`), so the true offset in the object frame is known exactly: -origin.
The offset's in-plane error |e| is compared with the stated ``hub_offset_sd_m`` (per axis). On main the stated sd
left out what the height model misses when the speed changes (the misfit is read as once a turn and the residuals
do not show it): on these five walks |e| / sd was 0.30, 2.16, 2.31, 2.02, 2.90 (rms per axis 1.50); now 0.30, 0.67,
0.94, 0.77, 2.84 (rms 1.01; measured when written). Asserted: each within 3.5 sd (the 99.8 % radius of a 2-D normal
error) and the rms per axis below 1.4 (for an honest sd a chi^2 with 10 degrees of freedom exceeds that 3 % of the
time).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.kinematics.build import import_trial
from tests.support.analysis_trial_truth import simulate_wheel, write_csv

#: the object's origin in the body frame (m): 36 mm off the hub in the wheel plane (body x, y), 12 mm along the axis
ORIGIN_BODY_M = (0.03, -0.02, 0.012)
#: (slope deg, release rad/s, c N s/m, k N/m, heading deg) of each walk
WALKS = (
    (1.4, 2.9, 14.0, 2100.0, 40.0),
    (1.8, 2.7, 9.0, 3200.0, 150.0),
    (1.3, 3.0, 5.0, 2600.0, 250.0),
    (2.0, 2.8, 17.0, 3700.0, 300.0),
    (1.6, 2.6, 11.0, 1800.0, 10.0),
)


@pytest.mark.slow
def test_the_hub_offsets_stated_sd_covers_its_error_when_the_speed_changes(tmp_path) -> None:
    zs = []
    for i, (slope, release, c, k, yaw) in enumerate(WALKS):
        tr = simulate_wheel(
            slope, release, c_ns_per_m=c, k_n_per_m=k, max_steps=11, ending="walked", seed=40 + i, yaw_deg=yaw,
            origin_body_m=ORIGIN_BODY_M,
        )  # fmt: skip
        impacts = np.diff(tr.impact_time_s)
        assert impacts[-1] / impacts[0] > 1.2  # the wheel slows down: its step periods grow
        meta = import_trial(write_csv(tmp_path / f"w{i}.csv", tr)).meta
        assert meta.hub_offset_m is not None and meta.hub_offset_sd_m is not None, meta.hub_source
        err = np.asarray(meta.hub_offset_m)[:2] + np.asarray(ORIGIN_BODY_M)[:2]  # in the wheel plane (body x, y)
        zs.append(math.hypot(*err) / meta.hub_offset_sd_m)
    zs_arr = np.array(zs)
    assert np.all(zs_arr < 3.5), zs_arr
    assert math.sqrt(np.mean(zs_arr**2) / 2.0) < 1.4, zs_arr
