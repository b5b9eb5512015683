"""`rimless trials import` names what it held (issue 31: every output lists each parameter with its value and
source): ``parameters`` in every JSON row and one ``held parameters`` line in the text, with and without a wheel
file (``--params``). Expectations are the wheel file's own numbers, the issue's 45 ms bound and sqrt(M / k)
computed here by hand (M = m_H + 8 m, E[M / k] to second order in k's relative sd)."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from rimless.analysis.examples.critical_series import DATA_DIR as CRIT_DIR
from rimless.cli import app as root_app

runner = CliRunner()
SHORT = CRIT_DIR / "SYNTHETIC_crit_slope1.45deg_release1.9.csv"
OTHER = CRIT_DIR / "SYNTHETIC_crit_slope1.30deg_release1.9.csv"
# a wheel away from Table 1 (m_H 1.892 kg, m 0.0378 kg, k 2700 N/m)
WHEEL_TOML = "[wheel]\nm_H = {value = 2.5, sd = 0.05}\nm = {value = 0.05, sd = 0.001}\nk = {value = 4000, sd = 200}\n"


def _import(tmp_path, *extra: str) -> list[dict]:
    res = runner.invoke(
        root_app, ["trials", "import", str(SHORT), str(OTHER), "--out", str(tmp_path), "--json", *extra]
    )
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_without_a_wheel_the_rows_name_the_45_ms_bound(tmp_path):
    rows = _import(tmp_path)
    assert len(rows) == 2
    for r in rows:
        (p,) = r["parameters"]
        assert p["name"] == "leg_drift_time_s" and p["unit"] == "s"
        assert p["value"] == pytest.approx(0.045) and p["sd"] is None
        assert p["source"] == "assumed_bound" and "not given" in p["basis"]
        assert r["slope_ci_deg"] is not None  # the interval those parameters widen


def test_with_a_wheel_file_the_rows_list_its_masses_and_k(tmp_path):
    wheel = tmp_path / "wheel.toml"
    wheel.write_text(WHEEL_TOML, encoding="utf-8")
    rows = _import(tmp_path, "--params", str(wheel))
    expected = {"hub_mass_kg": (2.5, 0.05), "leg_mass_kg": (0.05, 0.001), "stiffness_n_per_m": (4000.0, 200.0)}
    drift = math.sqrt((2.5 + 8 * 0.05) / 4000.0 * (1 + (200.0 / 4000.0) ** 2))
    for r in rows:
        by_name = {p["name"]: p for p in r["parameters"]}
        assert set(by_name) == {*expected, "leg_drift_time_s"}
        for name, (value, sd) in expected.items():
            p = by_name[name]
            assert (p["value"], p["sd"], p["source"]) == (pytest.approx(value), pytest.approx(sd), "wheel_file")
            assert set(p) == {"name", "symbol", "value", "sd", "unit", "source", "basis", "carried_as"}
        d = by_name["leg_drift_time_s"]
        assert d["value"] == pytest.approx(drift, rel=1e-9) and d["source"] == "derived"


def test_rigid_legs_and_a_given_leg_length_are_listed(tmp_path):
    rows = _import(tmp_path, "--rigid-legs", "--leg-length-m", "0.31")
    by_name = {p["name"]: p for p in rows[0]["parameters"]}
    assert by_name["leg_drift_time_s"]["value"] == 0.0 and by_name["leg_drift_time_s"]["source"] == "rigid_legs"
    assert by_name["leg_length_m"]["value"] == pytest.approx(0.31) and by_name["leg_length_m"]["sd"] == 0.0
    assert by_name["leg_length_m"]["source"] == "given"


def test_the_text_output_has_one_held_parameters_line(tmp_path):
    wheel = tmp_path / "wheel.toml"
    wheel.write_text(WHEEL_TOML, encoding="utf-8")
    told = runner.invoke(root_app, ["trials", "import", str(SHORT), "--out", str(tmp_path), "--params", str(wheel)])
    assert told.exit_code == 0, told.output
    (line,) = [ln for ln in told.output.splitlines() if ln.startswith("held parameters")]
    assert "k = 4000 ± 200 N/m [wheel_file]" in line and "m_H = 2.5 ± 0.05 kg [wheel_file]" in line
    untold = runner.invoke(root_app, ["trials", "import", str(SHORT), "--out", str(tmp_path)])
    (line,) = [ln for ln in untold.output.splitlines() if ln.startswith("held parameters")]
    assert "0.045 s (bound) [assumed_bound]" in line
