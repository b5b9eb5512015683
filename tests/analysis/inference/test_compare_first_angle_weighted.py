"""The comparison's first-angle offset test weighed by the importer's per-impact sds (issue 31; `compare.first_angle_test`
with ``impact_sd_s``, `compare_trial` passes the trial's): generalised least squares on the periods, whose covariance
follows from the impacts' independent errors (`compare.period_covariance`). On main the test took every period's
noise alike and had no ``impact_sd_s``.

Its size on a truth with no offset: the tests' compliant truth (`tests.support.analysis_trial_truth`, written apart
from the comparison and the importer) held on uncompressed legs at -alpha/2 and released, which is the comparison's
own rigid release (true offset 0); c 2-20 N s/m, k 1500-4000 N/m, slopes 1.5-3 deg, 10 steps, Tracker exports
imported, the true slope and wheel given (`first_angle_study.py --truth uncompressed --seed 7`, its first 20 draws,
the walks of `test_compare_first_angle_size.py`). At the nominal 1 % a test of the right size keeps the offset in 20
walks 3 times or more with probability 0.001 (binomial), and at 10 % 6 times or more with probability 0.011.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.inference import compare
from rimless.analysis.inference.compare import Simulator, first_angle_test, period_covariance


def test_the_periods_covariance_is_that_of_differences_of_independent_impact_errors() -> None:
    sd = np.array([0.6, 0.3, 0.35, 0.28, 0.4]) * 1e-3
    d = np.diff(np.eye(sd.size), axis=0)  # periods = D @ impact times
    np.testing.assert_allclose(period_covariance(sd), d @ np.diag(sd**2) @ d.T, rtol=1e-12, atol=0.0)


@pytest.mark.slow
@pytest.mark.full
def test_the_weighted_test_keeps_no_more_than_its_level_on_a_truth_without_offset(tmp_path: Path) -> None:
    from tests.analysis.inference.first_angle_study import no_offset_cases

    ps = []
    for trial, per, slope, sim, w0 in no_offset_cases(tmp_path):
        sd = compare._consecutive_impact_sd(trial)
        assert sd is not None and sd.size == per.size + 1
        test = first_angle_test(sim, slope, per, w0, sd)
        assert test.weighted and math.isfinite(test.p)
        ps.append(test.p)
    p = np.array(ps)
    assert p.size >= 18, p.size
    assert int((p < 0.01).sum()) <= 2, np.sort(p)
    assert int((p < 0.1).sum()) <= 5, np.sort(p)


@pytest.mark.slow
def test_the_comparison_weighs_the_first_angle_test_by_the_trials_impact_sds(tmp_path: Path) -> None:
    """An imported truth walk (the tests' truth, released from the rigid pose; c, k away from Table 1): the row
    says the test was weighted and its noise came from the per-impact sds; without them (a trial imported before
    they were recorded) the test is main's."""
    from rimless.analysis.kinematics.build import import_trial
    from rimless.sim.model.params import WheelParams
    from tests.support.analysis_trial_truth import simulate_wheel, write_csv

    c, k, slope = 13.25, 3743.0, 2.66
    tr = simulate_wheel(
        slope, 2.03, c_ns_per_m=c, k_n_per_m=k, max_steps=10, ending="caught", seed=7000, yaw_deg=108.0,
        release_leg="uncompressed",
    )  # fmt: skip
    trial = import_trial(write_csv(tmp_path / "t.csv", tr))
    trial = dataclasses.replace(trial, meta=dataclasses.replace(trial.meta, slope_deg=slope))
    sim = Simulator(model="er", params=WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c))
    row = compare.compare_trial(trial, sim).to_dict()
    assert row["first_angle_offset_tested"] is True and row["first_angle_offset_weighted"] is True
    assert "per-impact sds" in row["first_angle_offset_noise_source"]
    old = dataclasses.replace(trial, meta=dataclasses.replace(trial.meta, impact_sd_s=()))
    row_old = compare.compare_trial(old, sim).to_dict()
    assert row_old["first_angle_offset_tested"] is True and row_old["first_angle_offset_weighted"] is False
