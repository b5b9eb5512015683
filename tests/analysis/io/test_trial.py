"""Parquet trials: a built trial survives the round trip exactly; other files are refused with the reason."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.examples.synthetic import rolling_wheel
from rimless.analysis.io.tracker_csv import write_tracker_csv
from rimless.analysis.io.trial import read_trial
from rimless.analysis.kinematics.build import import_trial
from rimless.errors import InputFileError


def write_markers(tmp_path, w, name="m.csv"):
    return write_tracker_csv(
        tmp_path / name,
        rate_hz=w.rate_hz,
        markers={f"wheel:M{i}": w.markers_m[:, i] for i in range(w.markers_m.shape[1])},
    )


def test_parquet_round_trip(tmp_path):
    w = rolling_wheel(seed=12)
    trial = import_trial(write_markers(tmp_path, w), leg_length_m=w.leg_length_m)
    out = trial.to_parquet(tmp_path / "x" / "t.parquet")
    back = read_trial(out)
    assert back.meta == trial.meta
    for k, v in trial.series.data.items():
        np.testing.assert_array_equal(back.series[k], v)
    np.testing.assert_array_equal(back.time_s, trial.time_s)
    np.testing.assert_array_equal(back.impact_time_s, trial.impact_time_s)
    assert back.summary() == trial.summary()
    assert list(tmp_path.joinpath("x").iterdir()) == [out]  # no temp file left


def test_read_trial_rejects_other_files(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({"a": [1, 2]}), tmp_path / "a.parquet")
    with pytest.raises(InputFileError, match="rimless trial metadata"):
        read_trial(tmp_path / "a.parquet")
    (tmp_path / "b.parquet").write_text("nope")
    with pytest.raises(InputFileError, match="not a readable Parquet"):
        read_trial(tmp_path / "b.parquet")
