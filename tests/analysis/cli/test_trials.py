"""`rimless trials import|show` through typer's CliRunner."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.cli import app
from rimless.analysis.examples.synthetic import rolling_wheel
from rimless.analysis.io.tracker_csv import write_tracker_csv
from rimless.analysis.io.trial import read_trial
from tests.support.analysis_data import PUBLIC
from tests.support.cli_lines import stderr_lines

runner = CliRunner()
#: The keys of `trials import --json` (issue contract: the old six plus the walk's).
CONTRACT = {
    "file",
    "status",
    "reason",
    "frames",
    "rate_hz",
    "steps",
    "source",
    "slope_deg",
    "ramp_slope_deg",
    "outcome",
    "window_s",
    "impact_times_s",
    "step_periods_s",
    "hub_offset_mm",
    "warnings",
    "errors",
    "trial",
    "slope_source",
    "slope_ci_deg",
    "up_axis",
    "hub_offset_sd_mm",
    "hub_offset_sd_axes_mm",
    "parameters",
}  # the issues' keys, plus the path of the trial written (None when
# refused); slope_source (ramp | given | estimated) and slope_ci_deg ([low, high]) are issue 19's; up_axis (the lab
# axis taken as up, found or given by --up-axis), hub_offset_sd_mm (the fitted hub offset's standard error, its
# covariance's worst axis), hub_offset_sd_axes_mm (both axes, largest first: the trial JSON's key) and parameters
# (what the slope interval held) issue 31's


@pytest.fixture()
def wheel_csv(tmp_path):
    w = rolling_wheel(seed=21)
    p = write_tracker_csv(
        tmp_path / "wheel.csv", rate_hz=w.rate_hz, markers={f"wheel:M{i}": w.markers_m[:, i] for i in range(4)}
    )
    return w, p


def test_import_json_mixed_good_and_bad(tmp_path, wheel_csv):
    w, good = wheel_csv
    bad = tmp_path / "bad.csv"
    bad.write_text("Trajectories\n100\n,,A\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,x\n")
    out = tmp_path / "out"
    res = runner.invoke(app, ["import", str(bad), str(good), "--slope-deg", "2", "--out", str(out), "--json"])
    assert res.exit_code != 0  # one was refused
    rows = json.loads(res.stdout)
    assert [set(r) for r in rows] == [CONTRACT] * 2
    assert rows[0]["status"] == "refused" and "line 6, column 5" in rows[0]["reason"]
    assert rows[0]["errors"] == [
        f"{rows[0]['file']}:6:5: section 'Trajectories': cell 'x' is not a number [non-numeric]"
    ]
    assert rows[1]["status"] == "imported" and rows[1]["reason"] is None
    assert rows[1]["frames"] == len(w.time_s) and rows[1]["rate_hz"] == 100.0
    assert len(w.impact_time_s) - 3 <= rows[1]["steps"] <= len(w.impact_time_s) - 1
    assert sorted(p.name for p in out.iterdir()) == ["wheel.trial.parquet"]  # nothing half-imported
    trial = read_trial(out / "wheel.trial.parquet")
    assert trial.step_period_s.size == rows[1]["steps"]
    assert trial.meta.slope_deg == pytest.approx(2.0) and trial.meta.slope_source == "given"
    assert rows[0]["hub_offset_sd_axes_mm"] is None  # refused
    axes = rows[1]["hub_offset_sd_axes_mm"]  # the offset's sd per axis, as the trial written holds it
    assert axes is not None and axes[0] >= axes[1] > 0.0
    assert axes[0] == pytest.approx(rows[1]["hub_offset_sd_mm"], abs=1e-4)  # the worst axis
    np.testing.assert_allclose(axes, [v * 1e3 for v in trial.meta.hub_offset_sd_axes_m], atol=1e-4)


def test_import_all_good_exits_zero_and_show(tmp_path, wheel_csv):
    _, good = wheel_csv
    res = runner.invoke(app, ["import", str(good), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert "imported" in res.stdout
    trial_path = tmp_path / "wheel.trial.parquet"
    res = runner.invoke(app, ["show", str(trial_path), "--json"])
    assert res.exit_code == 0
    s = json.loads(res.stdout)
    expected = read_trial(trial_path)
    assert s["steps"] == expected.step_period_s.size > 5
    np.testing.assert_allclose(s["step_period_s"], expected.step_period_s)
    assert abs(s["slope_deg"] - 2.0) < 0.05
    res = runner.invoke(app, ["show", str(trial_path)])
    assert res.exit_code == 0 and "slope_deg" in res.stdout and "period s" in res.stdout


def test_show_missing_file_is_user_error(tmp_path):
    res = runner.invoke(app, ["show", str(tmp_path / "none.parquet")])
    assert res.exit_code == 2 and "no such trial file" in res.output


def test_bad_hub_offset_option(tmp_path, wheel_csv):
    _, good = wheel_csv
    res = runner.invoke(app, ["import", str(good), "--hub-offset-mm", "1,2", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "--hub-offset-mm" in res.output


def test_public_files_through_cli(tmp_path):
    if not PUBLIC.exists():
        pytest.skip(f"public Vicon exports not found at {PUBLIC}")
    files = sorted(PUBLIC.glob("*.csv"))
    res = runner.invoke(app, ["import", *map(str, files), "--out", str(tmp_path), "--json"])
    rows = {Path(r["file"]).name: r for r in json.loads(res.stdout)}
    assert res.exit_code == 2
    assert rows["tracker_objects_vantage_tube8.csv"]["status"] == "imported"
    assert rows["tracker_objects_vantage_tube8.csv"]["frames"] == 547
    for name in (
        "nexus_devices_pyomeca_analogs.csv",
        "nexus_trajectories_pyomeca.csv",
        "nexus_multisection_wpi_walk.csv",
    ):
        assert rows[name]["status"] == "refused" and rows[name]["reason"]


def test_import_json_reports_the_walk(tmp_path, wheel_csv):
    w, good = wheel_csv
    res = runner.invoke(app, ["import", str(good), "--out", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    (row,) = json.loads(res.stdout)
    assert row["status"] == "imported" and row["errors"] == []
    assert row["source"]["markers"] == [f"wheel:M{i}" for i in range(4)] and row["source"]["why"]
    assert abs(row["slope_deg"] - w.slope_deg) < 0.05 and row["ramp_slope_deg"] is None
    assert row["outcome"] == "walked"
    assert len(row["step_periods_s"]) == row["steps"] == len(row["impact_times_s"]) - 1
    assert row["window_s"][1] == row["impact_times_s"][-1]
    assert len(row["hub_offset_mm"]) == 3


@pytest.mark.parametrize("command", ["import", "report"])
def test_object_option_named_in_messages_on_import_and_report(tmp_path, wheel_csv, command):
    _, good = wheel_csv
    args = [command, str(good), "--object", "Nope", "--out", str(tmp_path / "o")]
    res = runner.invoke(app, args)
    assert res.exit_code == 2
    assert "--object Nope" in res.output and "object=" not in res.output
    res = runner.invoke(app, [command, str(good), "--hub-offset-mm", "1,x,3", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "error: --hub-offset-mm" in res.output
    res = runner.invoke(app, [command, str(good), "--markers", "wheel:M0,,", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "error: --markers" in res.output


def test_report_exits_nonzero_when_no_trial_can_be_compared(tmp_path):
    # a wheel that turns less than two steps: imported, but no steps to compare
    w = rolling_wheel(seed=3, periods_s=(0.4, 0.4))
    p = write_tracker_csv(
        tmp_path / "short.csv", rate_hz=w.rate_hz, markers={f"wheel:M{i}": w.markers_m[:, i] for i in range(4)}
    )
    before = set(tmp_path.iterdir())
    for out in (tmp_path / "rep", tmp_path / "new" / "rep"):
        res = runner.invoke(app, ["report", str(p), "--out", str(out)])
        assert res.exit_code == 1, res.output
        lines = stderr_lines(res.stderr)
        assert len(lines) == 1 and lines[0].startswith("error: no trial could be compared"), lines
        assert "short.csv: no steps detected" in lines[0] and "no report written" in lines[0]
        assert res.stdout.strip() == ""
        assert set(tmp_path.iterdir()) == before  # no report folder, no empty one, no temporary
    # into a folder that holds an earlier report and other files: they stay as they were
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "report.html").write_text("the earlier report")
    (kept / "notes.txt").write_text("mine")
    res = runner.invoke(app, ["report", str(p), "--out", str(kept), "--json"])
    assert res.exit_code == 1 and res.stdout.strip() == ""
    assert {q.name: q.read_text() for q in kept.iterdir()} == {"report.html": "the earlier report", "notes.txt": "mine"}


def test_show_on_a_folder_is_a_user_error(tmp_path):
    res = runner.invoke(app, ["show", str(tmp_path)])
    assert res.exit_code == 2 and "is a folder" in res.output
