"""The bundled SYNTHETIC recordings import under defaults with the truth written beside them (SYNTHETIC_truth.toml)."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.examples.bundled import data_files, load_truth
from rimless.analysis.kinematics.build import import_trial


@pytest.mark.parametrize("path", data_files(), ids=lambda p: p.stem)
def test_bundled_recording_window_outcome_periods(path):
    tr = load_truth()["trials"][path.stem]
    trial = import_trial(path)  # defaults only
    m = trial.meta
    assert m.outcome == tr["outcome"] == "caught"
    assert abs(m.slope_deg - tr["slope_deg"]) < 0.05
    # the release is found within a frame of the end of the hold
    assert abs(m.window_s[0] - tr["hold_s"]) <= 0.011
    true_imp = np.asarray(tr["impact_time_s"]) - tr["first_frame_time_s"]
    true_per = np.asarray(tr["step_period_s"])  # step j+1 ends at impact j
    j = np.array([int(np.argmin(np.abs(true_imp - t))) for t in trial.impact_time_s])
    assert np.all(np.abs(trial.impact_time_s - true_imp[j]) < 0.025)  # CoM minimum lags the touchdown
    ends = j[np.searchsorted(trial.impact_step, trial.period_step)]
    # within a third of a frame: the CoM minimum follows the touchdown of the compliant leg by a varying few ms
    np.testing.assert_allclose(trial.step_period_s, true_per[ends], atol=3e-3)
    gap = tr["long_gap_s"]
    if gap:
        g0, g1 = np.asarray(gap) - tr["first_frame_time_s"]
        lost = ((true_imp > g0) & (true_imp < g1)).sum()
        assert lost >= 1 and trial.step_period_s.size == 7 - 2 * lost
    else:
        assert trial.step_period_s.size == 7
    if "ramp_slope_deg" in tr:
        assert m.ramp_slope_deg == pytest.approx(tr["ramp_slope_deg"], abs=0.05)
        assert m.object == "Wheel"
    else:
        assert m.ramp_slope_deg is None
