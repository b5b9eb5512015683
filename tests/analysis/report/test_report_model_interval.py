"""The report (and so `rimless demo`) gives a model's critical-slope interval as `trials critical-slope` and
`rimless.analysis.critical_slope` do (issue 31: "the output never contradicts itself"). The report took the held
parameters' sensitivities by forward differences, the command by central ones: on the bundled critical series the
demo printed ER 0.908-1.748 deg where the command printed 0.895-1.761 deg for the same wheel."""

from __future__ import annotations

import pytest

from rimless.analysis import critical_slope
from rimless.analysis.examples.critical_series import data_files
from rimless.analysis.report.html import build_report

#: two sustained trials of the bundled critical series (the models' part depends on the wheel input, not on them)
TRIALS = ("SYNTHETIC_crit_slope1.75deg_release2.5.csv", "SYNTHETIC_crit_slope1.90deg_release2.5.csv")


@pytest.mark.slow
def test_the_report_gives_the_models_interval_the_command_gives(tmp_path):
    files = [f for f in data_files() if f.name in TRIALS]
    assert len(files) == len(TRIALS)
    rep = build_report(files, tmp_path / "rep", import_kwargs={"max_gap_s": 0.05})
    cmd = critical_slope(files)
    got = rep.summary()["critical_slope"]["parameter_uncertainty"]["models"]["er"]
    want = cmd.to_dict()["parameter_uncertainty"]["models"]["er"]
    assert got["differences"] == want["differences"] == "central"
    assert got["critical_slope_deg"] == pytest.approx(want["critical_slope_deg"], abs=1e-9)
    assert got["ci_deg"] == pytest.approx(want["ci_deg"], abs=1e-6)
    names = [r["name"] for r in got["contributions"]]
    assert len(names) >= 7 and names == [r["name"] for r in want["contributions"]]
