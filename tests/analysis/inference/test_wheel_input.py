"""The wheel is an input; what is held, is carried (issue 31).

Truth: a rigid wheel with a large inertia ratio, I_hub / (M L0^2) = 3 (Table 1: about 0.43), written apart from
rimless (tests/support/analysis_rigid_truth.py); its critical slope is Coleman's closed form. Its trials, read
with Table 1 held, give an interval that misses the truth; without a wheel file the trials' own inertia (from
their step periods) gives one that covers it, and so does a wheel file stating the inertia with an honest sd;
the true inertia, exact, a narrower one that covers it too.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.inference.critical_slope import estimate_critical_slope
from rimless.analysis.inference.held import carry_critical, combine, sensitivities
from rimless.analysis.inference.sustained import trial_verdicts
from rimless.cli import app
from rimless.errors import ParameterError
from rimless.sim.model.params import WheelParams, load_params
from rimless.sim.model.uncertain import (
    DEFAULT_SD,
    UNCERTAIN_FIELDS,
    default_wheel_input,
    read_wheel_input,
    wheel_input_from,
)
from tests.support.analysis_rigid_truth import RigidTruth, duck_trial

runner = CliRunner()
TRUTH = RigidTruth(mass_kg=2.0, inertia_hub_kg_m2=3 * 2.0 * 0.237**2)  # I_hub / (M L0^2) = 3
EXACT = {n: 0.0 for n in ("m_H", "m", "I_c", "L0", "k", "c", "F_c")}


# ------------------------------------------------------------------------------------------------ parsing


def test_defaults_are_table1_with_stated_uncertainties():
    win = default_wheel_input()
    rows = {r["name"]: r for r in win.parameters()}
    assert list(rows) == list(UNCERTAIN_FIELDS)
    t1 = WheelParams()
    for n, r in rows.items():
        assert r["value"] == getattr(t1, n) and r["source"] == "table1" and r["unit"]
        assert r["basis"] == DEFAULT_SD[n][2]
        assert "assumed, not measured" in r["basis"] or n == "gravity_m_s2"
    assert rows["hub_mass_kg"]["sd"] == pytest.approx(0.02 * 1.892)
    assert rows["inertia_kg_m2"]["sd"] == pytest.approx(0.0036)
    assert rows["leg_length_m"]["sd"] == 0.001
    assert rows["stiffness_n_per_m"]["sd"] == pytest.approx(270.0)
    assert rows["damping_ns_per_m"]["sd"] == pytest.approx(4.0)
    assert rows["guide_friction_n"] == {**rows["guide_friction_n"], "value": 0.0, "sd": 0.2}
    assert rows["gravity_m_s2"]["sd"] == 0.0


def test_wheel_file_forms(tmp_path):
    f = tmp_path / "wheel.toml"
    f.write_text(
        '[wheel]\nm_H = 1.9\nk = {value = 2500, sd = 300}\nc = "fit"\nL0 = {sd = 0.002}\nF_c = {value = 0.1}\n'
        "[wheel.inertia_kg_m2]\nvalue = 0.04\nsd = 0.004\n",
        encoding="utf-8",
    )
    win = read_wheel_input(f)
    e = win.entries
    assert (e["hub_mass_kg"].value, e["hub_mass_kg"].sd, e["hub_mass_kg"].source) == (1.9, 0.0, "wheel_file")
    assert (e["stiffness_n_per_m"].value, e["stiffness_n_per_m"].sd) == (2500, 300)
    assert (e["inertia_kg_m2"].value, e["inertia_kg_m2"].sd) == (0.04, 0.004)
    assert (e["leg_length_m"].value, e["leg_length_m"].sd) == (0.237, 0.002)  # sd alone: Table 1's value
    assert (e["guide_friction_n"].value, e["guide_friction_n"].sd) == (0.1, 0.2)  # value alone: default sd
    assert win.fit == ("damping_ns_per_m",)
    assert e["leg_mass_kg"].source == "table1" and e["leg_mass_kg"].sd == pytest.approx(0.02 * 0.0378)
    assert win.params == WheelParams(hub_mass_kg=1.9, stiffness_n_per_m=2500, inertia_kg_m2=0.04, guide_friction_n=0.1)
    assert load_params(f) == win.params  # the simulator reads the same values (sd ignored)


def test_plain_number_file_is_exact_and_keeps_its_meaning(tmp_path):
    f = tmp_path / "plain.toml"
    f.write_text("k = 2600\nI_c = 0.05\n", encoding="utf-8")
    win = read_wheel_input(f)
    assert win.params == load_params(f)
    assert win.entries["stiffness_n_per_m"].sd == 0 and win.entries["inertia_kg_m2"].sd == 0
    assert win.entries["damping_ns_per_m"].sd == pytest.approx(4.0)  # not named: Table 1 with its default


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("k = {value = 2700, sd = -3}", "k"),
        ("k = {value = 2700, sdd = 3}", "k"),
        ('I_c = "soft"', "I_c"),
        ('g = "fit"', "g"),
        ("c = {value = 8, sd = nan}", "c"),
        ("k = {}", "k"),
    ],
)
def test_bad_wheel_file_is_one_error_naming_file_and_key(tmp_path, text, key):
    f = tmp_path / "bad.toml"
    f.write_text(f"[wheel]\n{text}\n", encoding="utf-8")
    with pytest.raises(ParameterError, match=f"{f}: key '{key}'"):
        read_wheel_input(f)
    trial = tmp_path / "t.parquet"
    trial.write_bytes(b"")  # never read: the wheel file is refused first
    res = runner.invoke(app, ["trials", "critical-slope", str(trial), "--params", str(f)])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(f) in lines[0] and key in lines[0]


def test_fit_outside_calibrate_is_refused(tmp_path):
    f = tmp_path / "fitk.toml"
    f.write_text('k = "fit"\n', encoding="utf-8")
    trial = tmp_path / "t.parquet"
    trial.write_bytes(b"")
    res = runner.invoke(app, ["trials", "critical-slope", str(trial), "--params", str(f)])
    assert res.exit_code == 2 and "error: " in res.output and str(f) in res.output and "k" in res.output


def test_api_wheel_carries_uncertainty(tmp_path):
    from rimless.sim import Wheel

    f = tmp_path / "w.toml"
    f.write_text("I_c = {value = 0.04, sd = 0.005}\n", encoding="utf-8")
    w = Wheel(f)
    assert w.params.inertia_kg_m2 == 0.04 and w.uncertainty["inertia_kg_m2"] == 0.005
    assert w.with_params(slope_rad=0.03).uncertainty["inertia_kg_m2"] == 0.005
    assert w.with_model("ve").input.entries["inertia_kg_m2"].source == "wheel_file"
    w2 = Wheel(uncertainty={"k": 100.0}, damping_ns_per_m=6.0)
    assert w2.uncertainty["stiffness_n_per_m"] == 100.0
    assert w2.input.entries["damping_ns_per_m"].source == "wheel" and w2.uncertainty["damping_ns_per_m"] == 3.0
    with pytest.raises(ParameterError, match="uncertainty of 'q'"):
        Wheel(uncertainty={"q": 1.0})


def test_a_value_the_caller_states_reads_as_the_callers_even_at_table1():
    """F_c stated exactly 0 through the API (Table 1's value): its row read source "table1" (session 22); the
    statement is the caller's, as a wheel file's ``{sd = ...}`` is the file's. Defaults keep "table1", and an
    inertia the caller states is then kept and compared, not replaced by the trials' (stance_inertia)."""
    from rimless.sim import Wheel

    rows = {r["name"]: r for r in Wheel(WheelParams(), uncertainty={"F_c": 0}).input.parameters()}
    assert (rows["guide_friction_n"]["source"], rows["guide_friction_n"]["sd"]) == ("wheel", 0.0)
    assert rows["guide_friction_n"]["basis"] == "exact: given" and rows["guide_friction_n"]["carried_as"] == "exact"
    assert {r["source"] for n, r in rows.items() if n != "guide_friction_n"} == {"table1"}
    assert {r["source"] for r in Wheel().input.parameters()} == {"table1"}
    # a value given as a change, at Table 1's value: the caller's, with the default sd (none was stated)
    given = Wheel(inertia_kg_m2=WheelParams().inertia_kg_m2).input.entries["inertia_kg_m2"]
    assert (given.source, given.sd) == ("wheel", pytest.approx(0.0036))
    assert Wheel().with_params(guide_friction_n=0.0).input.entries["guide_friction_n"].source == "wheel"
    assert wheel_input_from(None, {"I_c": 0.004}).entries["inertia_kg_m2"].source == "wheel"


# ------------------------------------------------------------------------------------------- propagation


def test_sensitivities_of_a_linear_function_are_exact():
    """f = 3 I_c + 5 L0 + 2 F_c: the contributions are |df/dp| sd (F_c one-sided at its bound 0)."""
    win = wheel_input_from(None, {"m_H": 0, "m": 0, "k": 0, "c": 0})

    def f(p):
        return 3 * p.inertia_kg_m2 + 5 * p.leg_length_m + 2 * p.guide_friction_n

    base, rows = sensitivities(f, win)
    by = {r["symbol"]: r for r in rows}
    assert base == pytest.approx(f(WheelParams()))
    assert by["I_c"]["contribution_deg"] == pytest.approx(3 * 0.0036)
    assert by["L0"]["contribution_deg"] == pytest.approx(5 * 0.001)
    assert by["F_c"]["contribution_deg"] == pytest.approx(2 * 0.2) and by["F_c"]["note"] == "one-sided"
    se, complete = combine(rows)
    assert complete and se == pytest.approx(math.sqrt((3 * 0.0036) ** 2 + 0.005**2 + 0.4**2))


@pytest.fixture(scope="module")
def truth_series():
    """Trials at 0.5 deg (stalled) and 1.0-1.6 deg (sustained) of the inertia-ratio-3 wheel."""
    rng = np.random.default_rng(1)
    trials = [
        duck_trial(TRUTH, s, w, rng, name=f"ratio3_{s}deg_{w}rad_s_{k}", ramp_steps=20)
        for s in (0.5, 1.0, 1.2, 1.4, 1.6)
        for w in (1.6, 2.2)
        for k in range(2)
    ]
    assert {t.meta.outcome for t in trials if t.meta.slope_deg < 0.7} == {"stalled"}
    assert {t.meta.outcome for t in trials if t.meta.slope_deg > 0.7} == {"walked"}
    return trials, [t.meta.source_file for t in trials]


def _interval(trials, files, win, **kw):
    res = estimate_critical_slope(trial_verdicts(trials, win.params), files)
    res.model = {"critical_slope_deg": {}}
    held = carry_critical(res, trials, files, win, **kw)
    return res, held["trials"]


def test_held_inertia_is_carried_into_the_critical_slope(truth_series, tmp_path):
    trials, files = truth_series
    truth = TRUTH.critical_slope_deg()  # Coleman: 0.866 deg
    assert truth == pytest.approx(0.8662, abs=1e-4)
    true_params = TRUTH.wheel_params()

    # Table 1 held (with its default uncertainties; the behaviour before the trials' inertia): a confident
    # interval that misses the truth
    res_t1, t1 = _interval(trials, files, default_wheel_input(), estimate_inertia=False)
    assert not t1["ci_deg"][0] <= truth <= t1["ci_deg"][1], t1
    assert t1["se_parameters_deg"] > 0

    # the default input (no wheel file): the inertia comes from the trials' step periods, and the interval covers
    res_d, d = _interval(trials, files, default_wheel_input())
    assert d["ci_deg"][0] <= truth <= d["ci_deg"][1], d
    rows_d = {r["symbol"]: r for r in res_d.parameters}
    assert rows_d["I_c"]["source"] == "trials" and rows_d["I_c"]["sd"] > 0 and res_d.warnings == []

    # a wheel file: masses and leg length known, the inertia 0.27 +- 0.07 kg m^2 (truth 0.337: 1 sd off)
    f = tmp_path / "ratio3.toml"
    f.write_text(
        f"[wheel]\nm_H = {true_params.hub_mass_kg!r}\nm = {true_params.leg_mass_kg!r}\nL0 = 0.237\n"
        "I_c = {value = 0.27, sd = 0.07}\n",
        encoding="utf-8",
    )
    honest = read_wheel_input(f)
    res_h, h = _interval(trials, files, honest)
    assert h["ci_deg"][0] <= truth <= h["ci_deg"][1], h
    assert [r["symbol"] for r in h["contributions"] if r["contribution_deg"] > 0] == ["I_c"]
    assert h["ci_deg"][0] < res_h.chosen.ci_deg[0] and h["ci_deg"][1] > res_h.chosen.ci_deg[1]  # wider than data
    assert res_h.warnings == [] and res_h.inertia["comparison"]["source"] == "wheel_file"  # 1 sd off: no warning

    # the true inertia, exact: the interval covers the truth and is narrower than with the inertia's sd
    exact = wheel_input_from(true_params, EXACT)
    res_x, x = _interval(trials, files, exact)
    assert x["ci_deg"][0] <= truth <= x["ci_deg"][1], x
    assert x["se_parameters_deg"] == 0 and x["ci_deg"] == list(res_x.chosen.ci_deg)
    assert x["ci_deg"][1] - x["ci_deg"][0] < h["ci_deg"][1] - h["ci_deg"][0]
    summary = res_x.summary()
    assert summary["ci_with_parameters_deg"] == x["ci_deg"] and len(summary["parameters"]) == len(UNCERTAIN_FIELDS)
    new = {k: summary[k] for k in ("parameters", "ci_with_parameters_deg", "parameter_uncertainty")}
    json.dumps(new, allow_nan=False)  # the new keys carry no NaN


# ------------------------------------------------------------------------------------------------ commands

CRITICAL_FILES = sorted((Path(__file__).resolve().parents[3] / "analysis" / "data" / "critical").glob("*.csv"))


def test_critical_slope_command_lists_and_carries_the_parameters(tmp_path):
    f = tmp_path / "wheel.toml"
    f.write_text("[wheel]\nI_c = {value = 0.036, sd = 0.004}\nk = 2700\n", encoding="utf-8")
    res = runner.invoke(app, ["trials", "critical-slope", *map(str, CRITICAL_FILES), "--params", str(f), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    rows = {r["symbol"]: r for r in out["parameters"]}
    assert set(rows) == {"m_H", "m", "I_c", "L0", "k", "c", "F_c", "g"}
    assert (rows["I_c"]["sd"], rows["I_c"]["source"]) == (0.004, "wheel_file")
    assert (rows["k"]["sd"], rows["k"]["source"]) == (0.0, "wheel_file")
    assert (rows["c"]["sd"], rows["c"]["source"]) == (4.0, "table1")
    held = out["parameter_uncertainty"]
    lo, hi = out["ci_with_parameters_deg"]
    assert lo <= out["ci_deg"][0] and hi >= out["ci_deg"][1]  # the data's interval, widened
    er = held["models"]["er"]
    assert er["critical_slope_deg"] == out["model_critical_slope_deg"]["er"]
    by = {r["symbol"]: r for r in er["contributions"]}
    assert "k" not in by and by["c"]["contribution_deg"] > by["I_c"]["contribution_deg"] > 0  # c +-50 % dominates
    assert by["F_c"]["note"] == "one-sided"
    assert er["ci_deg"][0] < er["critical_slope_deg"] < er["ci_deg"][1]
    json.dumps({k: out[k] for k in ("parameters", "parameter_uncertainty", "ci_with_parameters_deg")}, allow_nan=False)


@pytest.mark.slow
def test_calibrate_command_lists_fitted_and_held_with_se_held(tmp_path):
    f = tmp_path / "wheel.toml"
    f.write_text(
        '[wheel]\nm_H = 1.892\nm = 0.0378\nL0 = 0.237\nk = 2700\nF_c = 0\nI_c = {sd = 0.0036}\nc = "fit"\n',
        encoding="utf-8",
    )
    files = [p for p in CRITICAL_FILES if "slope1.90" in p.name or "slope2.05" in p.name]
    res = runner.invoke(app, ["trials", "calibrate", *map(str, files), "--params", str(f), "--json", "--no-critical"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    rows = {r["symbol"]: r for r in out["parameters"]}
    (c,) = out["params"]
    assert rows["c"]["source"] == "fitted" and rows["c"]["value"] == c["estimate"] and rows["c"]["sd"] == c["se"]
    assert (rows["I_c"]["value"], rows["I_c"]["sd"], rows["I_c"]["source"]) == (0.036, 0.0036, "wheel_file")
    assert set(c["held_contributions"]) == {"inertia_kg_m2"}  # the only held parameter with an sd
    assert c["se_held"] > 0 and c["se_with_held"] == pytest.approx(math.hypot(c["se"], c["se_held"]))
    assert c["ci95_with_held"][0] < c["ci95"][0] and c["ci95_with_held"][1] > c["ci95"][1]
