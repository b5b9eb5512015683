"""A compliant ER wheel that stalls after two steps is classified (stalled, with its two impacts and the period
between them), not refused by step detection. The truth is `tests.support.analysis_trial_truth` (c = 14 N s/m,
k = 2000 N/m, its own integration), whose impact times are the expectation; the bundled SYNTHETIC 1.30 deg
trial is the same case from a different truth model (`SYNTHETIC_crit_truth.toml`)."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.kinematics.build import import_trial
from tests.support.analysis_trial_truth import simulate, write_csv

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(
    "slope, release, origin",
    [
        (1.2, 2.0, (0.03, -0.025, 0.012)),
        (1.0, 2.0, (0.0, 0.0, 0.0)),
        (1.25, 1.95, (0.01, 0.0, 0.0)),
    ],
)
def test_two_step_stall_is_stalled_with_its_steps(tmp_path, slope, release, origin):
    tr = simulate(slope, release, ending="caught", origin_body_m=origin, seed=3)
    assert tr.steps == 2 and tr.stalled  # the case asked for: two impacts, then the stall
    trial = import_trial(write_csv(tmp_path / "s.csv", tr))
    m = trial.meta
    assert m.outcome == "stalled", m.outcome_reason
    assert m.step_refused is None, m.step_refused
    got = np.asarray(trial.impact_time_s)
    assert got.size == 2
    assert np.max(np.abs(got - tr.impact_time_s[:2])) < 0.015, (got, tr.impact_time_s)
    assert trial.step_period_s[0] == pytest.approx(np.diff(tr.impact_time_s[:2])[0], abs=0.01)


def test_one_step_stall_still_has_no_period(tmp_path):
    tr = simulate(1.2, 1.9, ending="caught", origin_body_m=(0.0, 0.0, 0.0), seed=3)
    assert tr.steps == 1
    trial = import_trial(write_csv(tmp_path / "s.csv", tr))
    assert trial.meta.outcome == "stalled" and len(trial.step_period_s) == 0


def test_bundled_two_step_stall(tmp_path):
    """SYNTHETIC_crit_slope1.30deg_release1.9: two impacts 1.0687 s apart in its truth file, then a stall
    (before: refused, 'the wheel turns only 80.1 deg: fewer than two steps')."""
    import tomllib

    from rimless.analysis.examples.critical_series import data_files

    path = next(p for p in data_files() if p.name == "SYNTHETIC_crit_slope1.30deg_release1.9.csv")
    truth = tomllib.loads((path.parent / "SYNTHETIC_crit_truth.toml").read_text())["trials"][path.stem]
    trial = import_trial(path)
    assert trial.meta.outcome == "stalled"
    assert len(trial.impact_time_s) == 2
    assert trial.step_period_s[0] == pytest.approx(np.diff(truth["impact_time_s"])[0], abs=0.005)
