"""The leg-test fit is public API (`rimless.analysis.leg_fit`, `read_leg_log`, `LegFitResult`), and
``rimless trials leg-fit --json`` is its `to_dict()`: the same numbers from Python and from the command, on logs of
the independent truth model of the leg (tests/support/leg_truth.py), whose k, c and F_c the intervals hold."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import rimless.analysis as analysis
from rimless.cli import app as root_app
from rimless.errors import InputFileError, ParameterError
from tests.support.leg_truth import LegTruth, write_log

runner = CliRunner()


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("legs")
    truth = LegTruth(k_n_per_m=3100.0, c_n_s_per_m=6.0, friction_n=0.3, mass_kg=0.041)  # away from Table 1
    paths = []
    for s in (0, 1, 2):  # three releases at 1.5-2.5 mm compression
        paths.append(folder / f"l{s}.jsonl")
        write_log(paths[-1], truth, compression_m=(1.5 + 0.5 * s) / 1e3, seed=s)
    return truth, paths


def test_the_api_fit_is_the_commands_json(logs):
    truth, paths = logs
    fit = analysis.leg_fit(paths, moving_mass_kg=truth.mass_kg)
    assert isinstance(fit, analysis.LegFitResult)
    res = runner.invoke(
        root_app, ["trials", "leg-fit", *map(str, paths), "--moving-mass-kg", repr(truth.mass_kg), "--json"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == json.loads(json.dumps(fit.to_dict()))
    out = fit.to_dict()
    for key, true in (("k_n_per_m", truth.k_n_per_m), ("c_n_s_per_m", truth.c_n_s_per_m)):
        lo, hi = out[key + "_ci"]
        assert lo < true < hi, (key, lo, true, hi)


def test_logs_read_first_give_the_same_fit(logs):
    truth, paths = logs
    read = [analysis.read_leg_log(p) for p in paths]
    assert all(isinstance(r, analysis.LegLog) for r in read)
    a = analysis.leg_fit(read, moving_mass_kg=truth.mass_kg).to_dict()
    b = analysis.leg_fit([str(p) for p in paths], moving_mass_kg=truth.mass_kg).to_dict()
    assert a["k_n_per_m"] == b["k_n_per_m"] and a["guide_friction_n_ci"] == b["guide_friction_n_ci"]


def test_bad_inputs_are_named(tmp_path, logs):
    with pytest.raises(ParameterError, match="none given"):
        analysis.leg_fit([])
    with pytest.raises(ParameterError, match="expected paths or LegLog objects, got int"):
        analysis.leg_fit([3])
    with pytest.raises(InputFileError, match="no such file"):
        analysis.leg_fit(tmp_path / "missing.jsonl")
    with pytest.raises(ParameterError, match="counts_per_m"):
        analysis.leg_fit([analysis.read_leg_log(logs[1][0])], counts_per_m=1e5)


def test_leg_fit_json_lists_what_it_held(logs):
    """`parameters`, as every other command lists its wheel (issue 31; the audit of session 21 found none): the
    moving mass with its source and how it was carried, each log's sensor scale from its header or the option."""
    truth, paths = logs
    rows = analysis.leg_fit(paths[:1], moving_mass_kg=truth.mass_kg).to_dict()["parameters"]
    assert rows[0] | {"basis": None} == {
        "name": "leg_mass_kg",
        "symbol": "m",
        "value": truth.mass_kg,
        "sd": 0.0,
        "unit": "kg",
        "source": "given",
        "basis": None,
        "carried_as": "exact",
    }
    assert "not in the intervals" in rows[0]["basis"]
    header = json.loads(paths[0].read_text().splitlines()[0])
    assert [(r["name"], r["value"], r["source"]) for r in rows[1:]] == [("counts_per_m", header["counts_per_m"], "log")]
    res = runner.invoke(
        root_app,
        ["trials", "leg-fit", str(paths[0]), "--moving-mass-sd-kg", "0.001", "--counts-per-m", "50000", "--json"],
    )
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)["parameters"]
    assert (rows[0]["source"], rows[0]["value"], rows[0]["sd"], rows[0]["carried_as"]) == (
        "table1",
        analysis.leg_fit.__kwdefaults__["moving_mass_kg"],
        0.001,
        "normal",
    )
    assert (rows[1]["value"], rows[1]["source"]) == (50000.0, "given")
