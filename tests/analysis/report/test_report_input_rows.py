"""`trials report --json`'s ``inputs`` rows say what each import assumed, as `trials import --json` rows do: the
slope's 95 % interval, the lab's up axis, and the import's held ``parameters`` (the legs' drift time from the wheel
or the bound: value, sd, source each). Checked against `import_trial` on the same file, the independent path."""

from __future__ import annotations

import math

from rimless.analysis import import_trial
from rimless.analysis.examples.bundled import data_files
from rimless.analysis.kinematics.inputs import load_input


def test_report_input_row_names_the_slope_interval_the_up_axis_and_the_held_parameters() -> None:
    path = data_files()[0]
    row = load_input(path).summary()
    trial = import_trial(path)
    lo, hi = (math.degrees(v) for v in trial.meta.slope_ci_rad)
    assert row["slope_ci_deg"] == [lo, hi] and lo < row["slope_deg"] < hi
    assert row["up_axis"] == trial.meta.up_axis
    assert row["parameters"] == trial.to_dict()["parameters"]
    assert row["parameters"], "the import held the legs' drift bound: it is listed"
    assert all({"value", "source"} <= set(p) for p in row["parameters"])
