"""`import_trial` from Python names what it held, as `rimless trials import --json` does (issue 31): the trial's
``to_dict()["parameters"]`` equals the CLI row's ``parameters`` for the same wheel (none, a wheel file given as a
`Wheel` or as a path, rigid legs with a given leg length), and the written trial keeps them. Expectations: the CLI's
rows, and the wheel file's own numbers with sqrt(M / k) computed here by hand (M = m_H + 8 m)."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from rimless.analysis import import_trial, read_trial
from rimless.analysis.examples.critical_series import DATA_DIR as CRIT_DIR
from rimless.cli import app as root_app
from rimless.sim import Wheel

runner = CliRunner()
SHORT = CRIT_DIR / "SYNTHETIC_crit_slope1.45deg_release1.9.csv"
# a wheel away from Table 1 (m_H 1.892 kg, m 0.0378 kg, k 2700 N/m)
WHEEL_TOML = "[wheel]\nm_H = {value = 2.5, sd = 0.05}\nm = {value = 0.05, sd = 0.001}\nk = {value = 4000, sd = 200}\n"


def _cli_parameters(tmp_path, *extra: str) -> list[dict]:
    res = runner.invoke(root_app, ["trials", "import", str(SHORT), "--out", str(tmp_path / "cli"), "--json", *extra])
    assert res.exit_code == 0, res.output
    (row,) = json.loads(res.stdout)
    return row["parameters"]


@pytest.fixture
def wheel_file(tmp_path):
    path = tmp_path / "wheel.toml"
    path.write_text(WHEEL_TOML, encoding="utf-8")
    return path


def test_a_wheel_file_gives_the_cli_rows_parameters(tmp_path, wheel_file):
    cli = _cli_parameters(tmp_path, "--params", str(wheel_file))
    by_wheel = import_trial(SHORT, wheel=Wheel(wheel_file)).to_dict()["parameters"]
    by_path = import_trial(SHORT, wheel=wheel_file).to_dict()["parameters"]
    assert by_wheel == cli and by_path == cli
    drift = next(p for p in by_wheel if p["name"] == "leg_drift_time_s")
    assert drift["value"] == pytest.approx(math.sqrt((2.5 + 8 * 0.05) / 4000.0 * (1 + 0.05**2)), rel=1e-9)
    k = next(p for p in by_wheel if p["name"] == "stiffness_n_per_m")
    assert (k["value"], k["sd"], k["source"]) == (4000.0, 200.0, "wheel_file")


def test_without_a_wheel_the_bound_and_a_given_leg_length_as_the_cli(tmp_path):
    trial = import_trial(SHORT, leg_length_m=0.31)
    assert trial.to_dict()["parameters"] == _cli_parameters(tmp_path, "--leg-length-m", "0.31")
    by_name = {p["name"]: p for p in trial.to_dict()["parameters"]}
    assert by_name["leg_drift_time_s"]["source"] == "assumed_bound" and by_name["leg_drift_time_s"]["sd"] is None
    assert (by_name["leg_length_m"]["value"], by_name["leg_length_m"]["sd"]) == (0.31, 0.0)
    assert trial.to_dict() == trial.summary()


def test_rigid_legs_as_the_cli_and_kept_in_the_written_trial(tmp_path):
    trial = import_trial(SHORT, wheel=Wheel(model="rigid"))
    assert trial.to_dict()["parameters"] == _cli_parameters(tmp_path, "--rigid-legs")
    back = read_trial(trial.to_parquet(tmp_path / "t.trial.parquet"))
    assert back.to_dict()["parameters"] == trial.to_dict()["parameters"]
    assert back.to_dict()["parameters"][0]["source"] == "rigid_legs"


def test_a_missing_wheel_file_is_refused_by_name(tmp_path):
    from rimless.errors import UserError

    with pytest.raises(UserError, match="nope.toml: no such wheel file"):
        import_trial(SHORT, wheel=tmp_path / "nope.toml")
