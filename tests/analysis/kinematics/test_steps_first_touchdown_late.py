"""The first stance's measurement (`steps._first_touchdown`) when the release comes less than a third of a step before
the first impact (issue 31): only the end of the first stance's window is then seen.

The truth: the independent compliant walks of `tests.support.analysis_trial_truth` (those of
`test_steps_first_touchdown.py`: both holds, wheels away from Table 1, low marker noise), their recording before a
cut replaced by a hold at the pose of the first frame after it (a hand holding the wheel on its stance foot and
letting it go with the walk's own speed there): the dynamics after the cut, and so every impact time, are the
truth's own, and the release is 30, 20 or 12 % of the first step before the first impact. The truth's impact times
are the expectation.

On main the first stance's mean height over the end of its window was set against the later stances' mean over the
whole window: the heights brought to the touchdown angle are not flat over the window (about 5 mm over it, the
compliant stance leg touching down short of alpha/2), so the first impact was moved by up to 5.2 ms (first periods
-0.94, -2.50, -4.20, +0.06, -1.45, -2.52, -0.81, -3.24, -5.19, +0.18, -1.35, -2.22 ms, rms 2.6 ms; left at the
gait's phase: -1.32, -0.12, +0.02, +0.63 ms). Now every stance is taken over the turn the first one was seen in."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rimless.analysis.kinematics.build import import_trial
from tests.support.analysis_trial_truth import FIRST_TOUCHDOWN_WALKS, simulate_wheel, write_csv

pytestmark = pytest.mark.slow

WALKS = FIRST_TOUCHDOWN_WALKS  # (hold, slope deg, release rad/s, c N s/m, k N/m)
HOLD_S = 0.4  # the truth's own hold before its release (`analysis_trial_truth.simulate`'s default)
NOISE_M, ANGLE_NOISE_RAD = 0.05e-3, 0.2e-3


def _released_late(truth, fraction: float, seed: int):
    """The truth's recording with every frame before the cut (``fraction`` of the first step before the first impact)
    replaced by the pose of the first frame after it, with fresh marker noise: (truth, the release's time s)."""
    rng = np.random.default_rng(seed)
    t_imp = float(truth.impact_time_s[0])
    j = int(np.searchsorted(truth.time_s, t_imp - fraction * (t_imp - HOLD_S)))
    held = truth.time_s < truth.time_s[j]
    n = int(held.sum())
    trans = truth.hub_world[j] + truth.rot[j].apply(truth.origin_body_m)
    rot = Rotation.from_rotvec(rng.normal(0, ANGLE_NOISE_RAD, (n, 3))) * Rotation.from_quat(
        np.repeat(truth.rot[j].as_quat()[None], n, 0)
    )
    truth.pose[held, :3] = rot.as_rotvec()
    truth.pose[held, 3:] = trans + rng.normal(0, NOISE_M, (n, 3))
    return truth, float(truth.time_s[j])


def test_a_release_late_in_the_first_step_keeps_the_first_period_unbiased(tmp_path):
    first, later = [], []
    for i, (hold, slope, w, c, k) in enumerate(WALKS):
        for fraction in (0.3, 0.2, 0.12):
            tr = simulate_wheel(
                slope, w, c_ns_per_m=c, k_n_per_m=k, max_steps=8, ending="caught", seed=5 + i, yaw_deg=30.0,
                release_leg=hold, noise_m=NOISE_M, angle_noise_rad=ANGLE_NOISE_RAD,
            )  # fmt: skip
            tr, t_release = _released_late(tr, fraction, seed=i)
            # the release really is late: under a third of the first step before the first impact
            step = tr.impact_time_s[1] - tr.impact_time_s[0]
            assert 0 < tr.impact_time_s[0] - t_release < step / 3
            trial = import_trial(write_csv(tmp_path / f"t{i}.csv", tr))
            got = trial.impact_time_s + tr.time_s[0]  # the recording's time 0 is its first frame
            assert got.size == tr.impact_time_s.size, (hold, fraction, got, tr.impact_time_s)
            err = got - tr.impact_time_s
            assert np.max(np.abs(err)) < 0.01  # every impact within a frame (100 Hz)
            first.append(err[1] - err[0])
            later.append(np.diff(err)[1:])
    first_ms = np.array(first) * 1e3
    # within 0.75 ms each (main: up to 5.2 ms), rms under 0.45 ms (main 2.6 ms; at the gait's phase 0.74 ms)
    assert np.all(np.abs(first_ms) < 0.75), first_ms
    assert np.sqrt(np.mean(first_ms**2)) < 0.45, first_ms
    assert np.sqrt(np.mean(np.concatenate(later) ** 2)) < 0.3e-3  # the later periods untouched (rms 0.2 ms)
