"""`rimless trials critical-slope` and `rimless trials calibrate` on the bundled SYNTHETIC_crit series."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from rimless.analysis.examples.critical_series import data_files, load_truth
from rimless.cli import app as root_app

runner = CliRunner()


@pytest.mark.slow
def test_critical_slope_json_contract_and_truth():
    files = [str(p) for p in data_files()]
    assert len(files) == 12
    res = runner.invoke(root_app, ["trials", "critical-slope", *files, "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    for key in ("critical_slope_deg", "bracket_deg", "ci_deg", "method", "per_trial", "model_critical_slope_deg"):
        assert key in out
    assert len(out["per_trial"]) <= 12 and out["per_trial"]
    for row in out["per_trial"]:
        assert {"file", "slope_deg", "verdict", "steps", "reason"} <= set(row)
        assert row["verdict"] in ("sustained", "decaying", "undetermined") and row["reason"]
    truth = load_truth()
    crit = truth["dataset"]["critical_slope_deg"]
    assert abs(out["critical_slope_deg"] - crit) < 0.1
    # The Table 1 ER wheel loses less energy than the truth model (c = 8 against 10 N s/m, no guide friction), so
    # its critical slope lies below the truth's, and above the rigid wheel's order of magnitude.
    er = out["model_critical_slope_deg"]["er"]
    assert 1.0 < er < crit
    # Regression snapshot: 1.263 deg is `rimless sim critical-slope --model er` (Algorithm 1 continuation,
    # Table 1) at commit ebb1b78; tests/sim checks the continuation itself.
    assert er == pytest.approx(1.263, abs=0.01)
    # no verdict contradicts the truth model
    by_file = {f"{name}.csv": t for name, t in truth["trials"].items()}
    for row in out["per_trial"]:
        t = by_file[row["file"].split("/")[-1]]
        if row["verdict"] == "sustained":
            assert t["sustained"], row
        if row["verdict"] == "decaying":
            assert not t["sustained"], row


def test_critical_slope_errors():
    res = runner.invoke(root_app, ["trials", "critical-slope", "nope.csv"])
    assert res.exit_code == 2 and "error:" in res.output and "nope.csv: no such file" in res.output
    res = runner.invoke(root_app, ["trials", "critical-slope", str(data_files()[0]), "--model", "xx"])
    assert res.exit_code == 2 and "--model" in res.output
    res = runner.invoke(root_app, ["trials", "calibrate", str(data_files()[0]), "--fit", "c,zz"])
    assert res.exit_code == 2 and "--fit" in res.output


def test_critical_slope_table_fits_80_columns():
    res = runner.invoke(
        root_app, ["trials", "critical-slope", *[str(p) for p in data_files()[6:]]], env={"COLUMNS": "80"}
    )
    assert res.exit_code in (0, 1), res.output
    for line in res.stdout.splitlines():
        assert len(line) <= 80, line
