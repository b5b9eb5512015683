"""`rimless trials coverage` through the importer: the machinery of the study (truths, draws, imports, counts)
checked on a small run; the figures themselves come from the long run in docs/trials.md."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import rimless.analysis as ra
from rimless.analysis.validation.critical_truth import LossyWheel
from rimless.analysis.validation.importer_coverage import (
    draw_lab,
    draw_wheel,
    run_importer_coverage,
    summarise_input,
    summarise_parts,
    truth_input,
    write_series,
)
from tests.support.analysis_rigid_truth import RigidTruth

runner = CliRunner()


def test_draws_are_away_from_table1_and_straddle_their_own_critical_slope(tmp_path) -> None:
    rng = np.random.default_rng(4)
    ratios, frictions = [], []
    for _ in range(30):
        wheel, crit = draw_wheel(rng)
        assert crit == pytest.approx(wheel.critical_slope_deg()) and 0.5 < crit < 4.0
        assert 0.3 <= wheel.inertia_ratio <= 3.0 and 0.0 <= wheel.friction_n <= 0.6
        ratios.append(wheel.inertia_ratio)
        frictions.append(wheel.friction_n)
    assert min(ratios) < 0.6 and max(ratios) > 1.5 and max(frictions) > 0.3  # the ranges are used
    labs = [draw_lab(rng) for _ in range(20)]
    assert {lab.up for lab in labs} == {"y", "z"} and {lab.markers for lab in labs} == {True, False}
    wheel, crit = draw_wheel(rng)
    trials = write_series(rng, wheel, crit, labs[0], tmp_path, ramp_steps=8)
    slopes = [t.slope_deg for t in trials]
    assert min(slopes) < crit < max(slopes)
    for t in trials:  # a walk below the critical slope stalls or is cut by the ramp's end; above it never stalls
        assert t.path.is_file()
        if t.slope_deg > crit:
            assert not t.stalled and t.impacts == 8


def test_the_truth_input_is_the_wheel_a_user_would_write() -> None:
    wheel = LossyWheel(mass_kg=2.5, inertia_hub_kg_m2=0.2, leg_m=0.22, friction_n=0.3)
    params, sd = truth_input(wheel)
    assert params.hub_mass_kg + 8 * params.leg_mass_kg == pytest.approx(2.5)
    assert params.inertia_kg_m2 + 8 * params.leg_mass_kg * 0.22**2 == pytest.approx(0.2)
    assert sd["inertia_kg_m2"] == pytest.approx(0.1 * params.inertia_kg_m2) and sd["leg_length_m"] == 0.001


def test_a_small_study_through_the_importer_counts_what_it_saw() -> None:
    """Two series, both inputs: the truths are Coleman's where there is no loss and the map's otherwise, every
    trial goes through the importer, the counts add up, and with the truth's parameters each estimate lands near
    its own truth."""
    stages: list[str] = []
    res = run_importer_coverage(2, 7, ra.critical_slope, progress=lambda i, what: stages.append(what))
    assert {"importing", "critical slope, table1 wheel", "critical slope, truth wheel", "done"} <= set(stages)
    out = res.summary()
    assert out["truth"] == "importer" and out["input"] == "table1" and out["series"] == 2
    assert set(out["inputs"]) == {"table1", "truth"}
    assert out["imports"]["trials"] == sum(s.trials for s in res.series) >= 20
    for s in res.series:
        w = s.wheel
        lossless = LossyWheel(mass_kg=w.mass_kg, inertia_hub_kg_m2=w.inertia_hub_kg_m2, leg_m=w.leg_m)
        coleman = RigidTruth(w.mass_kg, w.inertia_hub_kg_m2, w.leg_m).critical_slope_deg()
        assert lossless.critical_slope_deg() == pytest.approx(coleman, abs=1e-9)
        assert s.truth_deg >= coleman  # a loss per step never lowers it
        row = s.results["truth"]
        assert row["estimated"], row
        assert abs(row["error_deg"]) < 0.25 and row["critical_slope_deg"] - s.truth_deg == pytest.approx(
            row["error_deg"]
        )
        assert row["covered"] == (row["ci_deg"][0] <= s.truth_deg <= row["ci_deg"][1])
    for name in ("table1", "truth"):
        d = out["inputs"][name]
        rows = [s.results[name] for s in res.series]
        assert d["estimated"] == sum(r["estimated"] for r in rows)
        assert d["covered"] == sum(bool(r.get("covered")) for r in rows)
        if d["estimated"]:
            lo, hi = d["coverage_ci95"]
            assert lo <= d["coverage"] <= hi
    assert summarise_input(res.series, "table1")["median_error_deg"] == out["median_error_deg"]
    assert math.isfinite(out["cpu_s"]) and out["wall_s"] > 0
    # the inertia ratio's own coverage: per series against the truth's r, counted per input
    for name in ("table1", "truth"):
        rows = [s.results[name]["inertia_from_trials"] for s in res.series]
        ir = out["inputs"][name]["inertia_ratio_from_trials"]
        assert ir["of"] == ir["estimated"] == sum(r["estimated"] for r in rows)
        assert ir["covered"] == sum(r["covered"] for r in rows if r["estimated"])
        for s, r in zip(res.series, rows, strict=True):
            assert r["truth_inertia_ratio"] == pytest.approx(s.wheel.inertia_ratio)
            if r["estimated"]:
                assert r["covered"] == (
                    abs(r["inertia_ratio"] - r["truth_inertia_ratio"]) <= 1.96 * r["inertia_ratio_se"]
                )
                assert r["error_pct"] == pytest.approx(100 * (r["inertia_ratio"] / s.wheel.inertia_ratio - 1))
                assert "L0" in r["assumption"]
    assert out["inertia_ratio_from_trials"] == out["inputs"]["table1"]["inertia_ratio_from_trials"]
    # the half width's parts: they add in quadrature to the intervals the rows report
    for s in res.series:
        for row in s.results.values():
            if not row["estimated"]:
                continue
            p = row["half_width_parts_deg"]
            assert p["data"] == pytest.approx(0.5 * (row["ci_deg"][1] - row["ci_deg"][0]))
            lo, hi = row["ci_with_parameters_deg"]
            assert p["total"] == pytest.approx(0.5 * (hi - lo), rel=1e-6)
            assert math.hypot(p["data"], p["parameters"]) == pytest.approx(p["total"])
            if row["method"] == "fixed-point-extrapolation":
                assert math.hypot(p["fixed_points"], p["slopes"]) == pytest.approx(p["data"], rel=1e-6)
    for name in ("table1", "truth"):
        assert out["inputs"][name]["median_half_width_parts_deg"]["total"] > 0


def test_a_lossless_truth_on_request() -> None:
    """The friction knob: (0, 0) draws lossless wheels (Coleman's critical slope), the default range is kept."""
    rng = np.random.default_rng(5)
    for _ in range(5):
        wheel, crit = draw_wheel(rng, (0.0, 0.0))
        coleman = RigidTruth(wheel.mass_kg, wheel.inertia_hub_kg_m2, wheel.leg_m).critical_slope_deg()
        assert wheel.friction_n == 0.0 and wheel.loss_j == 0.0 and crit == pytest.approx(coleman, abs=1e-9)


def test_coverage_command_defaults_to_the_importer_and_keeps_the_pendulum() -> None:
    from rimless.cli import app

    r = runner.invoke(app, ["trials", "coverage", "--series", "1", "--seed", "2", "--inputs", "truth", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["truth"] == "importer" and out["input"] == "truth" and list(out["inputs"]) == ["truth"]
    for key in ("series", "coverage", "coverage_ci95", "median_abs_error_deg", "median_error_deg", "per_method"):
        assert key in out
    r = runner.invoke(app, ["trials", "coverage", "--series", "1", "--seed", "2", "--inputs", "truth"])
    assert r.exit_code == 0, r.output
    assert "truth: rigid rimless wheel" in r.stdout and "wheel input: the truth's parameters" in r.stdout
    assert "inertia ratio from trials: 95 % interval holds the truth's in" in r.stdout
    r = runner.invoke(app, ["trials", "coverage", "--truth", "pendulum", "--series", "2", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["truth"] == "pendulum"
    for bad in (["--truth", "vicon"], ["--inputs", "table2"], ["--series", "0"]):
        r = runner.invoke(app, ["trials", "coverage", *bad])
        assert r.exit_code == 2 and "error:" in r.output, (bad, r.output)


def test_floquet_coverage_command() -> None:
    from rimless.cli import app

    r = runner.invoke(app, ["trials", "floquet-coverage", "--series", "1", "--seed", "3", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["kind"] == "rigid" and out["truth_multiplier"] == pytest.approx(LossyWheel(2.6, 0.05, 0.21).beta ** 2)
    assert out["corrected"]["of"] == out["estimated"] <= 1
    r = runner.invoke(app, ["trials", "floquet-coverage", "--kind", "soft"])
    assert r.exit_code == 2 and "--kind" in r.output
    r = runner.invoke(app, ["trials", "floquet-coverage", "--labs", "nowhere"])
    assert r.exit_code == 2 and "--labs" in r.output


def test_floquet_coverage_in_drawn_labs_imports_every_trial() -> None:
    """Y-up and Z-up labs, objects and markers: the floquet study's trials import (none refused) and estimate."""
    from rimless.analysis.validation.floquet_coverage import run

    out = run("rigid", 4, 3, 15, 0.8, 1, labs="drawn")
    assert out["labs"] == "drawn" and out["drawn_labs"]["y_up"] >= 1 and out["drawn_labs"]["markers"] >= 1
    assert not any(k.startswith("refused") for k in out["flagged_trials"]), out["flagged_trials"]
    assert out["estimated"] == out["corrected"]["of"] >= 3
    assert out["import_legs"].startswith("rigid legs"), out["import_legs"]  # the importer told the rigid wheel


def test_floquet_coverage_tells_the_importer_the_er_truths_legs() -> None:
    """The ER truth's wheel as the example's wheel.toml states it (k 2000 +- 100 N/m): the importer sizes the legs'
    drift on that stated k (sqrt(m / k), a second-order term above it for k's and m's spread), not on the unknown
    wheel's 45 ms bound."""
    import math

    from rimless.analysis.kinematics.slope_evidence import leg_compliance
    from rimless.analysis.validation.floquet_coverage import told_wheel, truth_of

    wheel = told_wheel("er", truth_of("er")[0])
    legs = leg_compliance(wheel)
    p = wheel.params
    leg_time_s = math.sqrt((p.hub_mass_kg + 8 * p.leg_mass_kg) / 2000.0)
    assert "k = 2000 +- 100 N/m" in legs.source, legs
    assert leg_time_s <= legs.time_s <= 1.02 * leg_time_s < 0.045, (legs, leg_time_s)


def test_half_width_parts_summary_by_hand() -> None:
    """Two hand-made rows: medians of the parts, rms z of the data's and the carried interval, and the rms z
    the carried interval would show were the data's honest and the parameters exact (sqrt(mean(data^2 /
    total^2)), by hand: data 0.03 and 0.04 of totals 0.05 and 0.05 -> sqrt((0.36 + 0.64) / 2))."""
    z95 = 1.959963984540054
    rows = [
        {
            "error_deg": 0.01,
            "half_width_parts_deg": {
                "data": 0.03,
                "parameters": 0.04,
                "total": 0.05,
                "parameters_by_name": {"inertia_kg_m2": 0.04},
            },
        },
        {
            "error_deg": -0.02,
            "half_width_parts_deg": {
                "data": 0.04,
                "parameters": 0.03,
                "total": 0.05,
                "parameters_by_name": {"inertia_kg_m2": 0.03},
            },
        },
    ]
    out = summarise_parts(rows)
    med = out["median_half_width_parts_deg"]
    assert med["data"] == pytest.approx(0.035) and med["parameters"] == pytest.approx(0.035)
    assert med["parameters_by_name"] == {"inertia_kg_m2": pytest.approx(0.035)}
    assert med["fixed_points"] is None  # not an extrapolation: no split
    assert out["rms_z_data"] == pytest.approx(math.sqrt(((0.01 / 0.03) ** 2 + (0.02 / 0.04) ** 2) / 2) * z95)
    assert out["rms_z_with_parameters"] == pytest.approx(math.sqrt((0.01**2 + 0.02**2) / 2) / 0.05 * z95)
    assert out["rms_z_expected_with_parameters"] == pytest.approx(math.sqrt(0.5))
    assert out["rms_error_deg"] == pytest.approx(math.sqrt((0.01**2 + 0.02**2) / 2))
