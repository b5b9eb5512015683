"""`trials floquet`'s slope group says why it gives no multiplier in the words of its trials' reasons: a group of
transient-only trials reads "no trial reached steady walking (all transient-only)", not "too short: 0 pairs". The
trials come from the independent rigid-wheel truth (analysis/validation/floquet_truth.py) through the writer and
the importer: releases far above the gait decay the same way every step (transient-only, as
tests/analysis/inference/test_floquet.py makes them), a walk of two impacts is too short."""

from __future__ import annotations

import numpy as np

from rimless.analysis import floquet, import_trial
from rimless.analysis.validation.floquet_truth import RigidWheel, record, rigid_walk


def _transient(wheel, rng, path):
    return record(rigid_walk(wheel, 4.5, 0.0, 7, rng, start=1.5 * wheel.fixed_point(4.5)), path, rng)


def test_a_group_of_transient_only_trials_says_no_trial_reached_steady_walking(tmp_path):
    rng = np.random.default_rng(6)
    wheel = RigidWheel()
    files = [_transient(wheel, rng, tmp_path / f"transient{i}.csv") for i in range(2)]
    res = floquet([import_trial(f) for f in files], with_model=False)
    assert all(r["status"] == "flagged" and r["reason"].startswith("transient-only") for r in res.trials)
    (group,) = res.groups
    assert group["status"] == "not_estimated"
    assert group["reason"].startswith("no trial reached steady walking (all 2 transient-only")
    assert "0 pairs" not in group["reason"]


def test_a_mixed_group_counts_its_flagged_trials_by_kind(tmp_path):
    rng = np.random.default_rng(6)
    wheel = RigidWheel()
    short = record(rigid_walk(wheel, 4.5, 0.8, 2, rng), tmp_path / "short.csv", rng)
    transient = _transient(wheel, rng, tmp_path / "transient.csv")
    res = floquet([import_trial(short), import_trial(transient)], with_model=False, group_tol_deg=2.0)  # one group
    (group,) = res.groups
    assert group["reason"].startswith("no trial gives pairs of section points (")
    assert "1 too short" in group["reason"] and "1 transient-only" in group["reason"]
