"""The least system CoT along a branch and the break-even clutch power, against independent expectations: the
least lies strictly between the critical and the start slope and no independently solved gait nearby does better;
with no power it is tan(critical slope); at the break-even power ER's and VE's least system CoTs are equal, ER
wins below it and loses above it; the commands carry the JSON keys and reject bad powers with exit 2."""

import json
import math

import pytest
from typer.testing import CliRunner

from rimless.cli import app
from rimless.sim.continuation.algorithm1 import critical_slope
from rimless.sim.model.electrical import ClutchPower
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import jacobian_factory, make_map
from rimless.sim.step.poincare import default_guess, solve_fixed_point
from rimless.sim.studies.system_cot import break_even, critical_slope_branch
from tests.support.sim_cot_truth import clutched_and_period_s, truth_system_cot, world_travel

P = WheelParams()
RUN = CliRunner()


@pytest.fixture(scope="module")
def er_branch():
    pmap = make_map(P, "er", backend="fast")
    cs = critical_slope(
        pmap, default_guess(P, "er"), start_slope_rad=0.05, step_rad=0.001, jacobian_factory=jacobian_factory("fast")
    )
    return cs, critical_slope_branch(cs, P, "fast", 1e-10)


def _truth_cot_at(slope, z_guess, power):
    """System CoT of the ER gait at `slope`, solved anew and measured on the reference path's recorded step."""
    q = P.replace(slope_rad=slope)
    fast = make_map(q, "er", backend="fast")
    fp = solve_fixed_point(fast, z_guess, jacobian=jacobian_factory("fast")(fast), record=False)
    step = make_map(q, "er", backend="reference").step(fp.z, record_dt=1e-3)
    s_x, s_z = world_travel(step, slope)
    t_c, period = clutched_and_period_s(step)
    return truth_system_cot(
        P.total_mass_kg,
        P.gravity_m_s2,
        s_x,
        s_z,
        "er",
        t_c,
        period,
        power.hold_power_w,
        power.switch_energy_j,
        power.electronics_power_w,
        False,
    )[1]


def test_with_no_power_the_least_is_tan_of_the_critical_slope(er_branch):
    cs, br = er_branch
    r = br.minimise(ClutchPower())
    assert r["min_system_cot_slope_rad"] == cs.critical_slope_rad
    assert r["min_system_cot"] == pytest.approx(math.tan(cs.critical_slope_rad), rel=1e-12)
    assert r["min_system_cot_at_bound"] == "critical-slope"


def test_the_least_system_cot_lies_above_the_critical_slope_and_below_the_start(er_branch):
    cs, br = er_branch
    power = ClutchPower(hold_power_w=0.1)
    r = br.minimise(power)
    s = r["min_system_cot_slope_rad"]
    assert cs.critical_slope_rad + 1e-4 < s < 0.05 - 1e-4
    assert r["min_system_cot_at_bound"] == "" and r["min_system_cot_failed_evaluations"] == 0
    z = min(br.points, key=lambda pt: abs(pt[0] - s))[1]
    at = _truth_cot_at(s, z, power)
    assert r["min_system_cot"] == pytest.approx(at, rel=1e-5)
    # no gait 1e-3 rad either side does better (independently solved and measured)
    for ds in (-1e-3, 1e-3):
        assert _truth_cot_at(s + ds, z, power) > at
    # and it is a large saving over the gait at the critical slope, where the clutch holds for seconds
    assert br.system_cot(cs.critical_slope_rad, power) > 2 * r["min_system_cot"]


@pytest.mark.slow
def test_break_even_powers_equalise_the_least_system_cots():
    from rimless.sim.studies.paper_system_cot import branches_at_k

    brs = branches_at_k(WheelParams(stiffness_n_per_m=2500.0), 2500.0, "fast", 1e-10)
    fast = [b for b in brs["ve"] if b.label == "fast"]
    assert fast and brs["er"]
    for field in ("hold_power_w", "switch_energy_j"):
        be = break_even(brs["er"], fast, ClutchPower(), field)
        x = be["value"]
        assert x is not None and x > 0 and be["resolved"]
        base = ClutchPower(**{field: x})
        er_least = min(b.minimise(base)["min_system_cot"] for b in brs["er"])
        ve_least = fast[0].minimise(base)["min_system_cot"]
        assert ve_least == pytest.approx(math.tan(fast[0].lo_rad), rel=1e-12)  # VE draws nothing by default
        assert er_least == pytest.approx(ve_least, rel=1e-6)  # the root
        below = min(b.minimise(ClutchPower(**{field: 0.9 * x}))["min_system_cot"] for b in brs["er"])
        above = min(b.minimise(ClutchPower(**{field: 1.1 * x}))["min_system_cot"] for b in brs["er"])
        assert below < ve_least < above
    # against the least of all VE branches: a break-even exists only if ER's critical slope is the lower
    least = break_even(brs["er"], brs["ve"], ClutchPower(), "hold_power_w")
    er_mech = min(math.tan(b.lo_rad) for b in brs["er"])
    ve_mech = min(math.tan(b.lo_rad) for b in brs["ve"])
    assert (least["value"] is None) == (er_mech >= ve_mech)
    # with the electronics on both wheels both pay for every second of their step: the slow ER gaits near the
    # stall pay most; the verdict agrees with the two least system CoTs computed directly at zero holding power
    for pe in (0.002, 0.5):
        power = ClutchPower(electronics_power_w=pe, ve_electronics=True)
        both = break_even(brs["er"], fast, power, "hold_power_w")
        er0 = min(b.minimise(power)["min_system_cot"] for b in brs["er"])
        ve0 = fast[0].minimise(power)["min_system_cot"]
        assert ve0 > math.tan(fast[0].lo_rad)
        assert (both["value"] is None) == (er0 >= ve0)
        if both["value"] is not None:
            at = power.replace(hold_power_w=both["value"])
            assert min(b.minimise(at)["min_system_cot"] for b in brs["er"]) == pytest.approx(ve0, rel=1e-6)


def _json(args):
    res = RUN.invoke(app, args)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_fixed_point_reports_the_three_keys_and_defaults_change_nothing():
    plain = _json(["sim", "fixed-point", "--json"])
    assert plain["system_cot"] == plain["mechanical_cot"] == pytest.approx(math.tan(0.05), rel=1e-12)
    assert plain["electrical_energy_per_step_j"] == 0.0
    powered = _json(["sim", "fixed-point", "--json", "--clutch-hold-power-w", "0.5"])
    for key in ("theta_plus_rad", "theta_dot_plus_rad_s", "step_period_s", "eigenvalues", "energy_ratio"):
        assert powered[key] == plain[key]  # the mechanics does not see the electrical options
    assert powered["electrical_energy_per_step_j"] == pytest.approx(
        0.5 * powered["phase_durations_s"]["slsp_clutched"], rel=1e-12
    )
    ve = _json(
        [
            "sim",
            "fixed-point",
            "--model",
            "ve",
            "--json",
            "--clutch-hold-power-w",
            "0.5",
            "--electronics-power-w",
            "0.2",
        ]
    )
    assert ve["electrical_energy_per_step_j"] == 0.0  # no clutch, and by default no electronics on the VE wheel
    ve_on = _json(["sim", "fixed-point", "--model", "ve", "--json", "--electronics-power-w", "0.2", "--ve-electronics"])
    assert ve_on["electrical_energy_per_step_j"] == pytest.approx(0.2 * ve_on["step_period_s"], rel=1e-12)


def test_critical_slope_reports_the_least_system_cot():
    out = _json(["sim", "critical-slope", "--json", "--clutch-hold-power-w", "0.1"])
    assert out["critical_slope_rad"] < out["min_system_cot_slope_rad"] < 0.05
    assert out["min_system_cot_slope_deg"] == pytest.approx(math.degrees(out["min_system_cot_slope_rad"]))
    assert out["min_system_cot"] < out["system_cot"]  # the gait at the critical slope pays for its long clutched time
    assert out["mechanical_cot"] == pytest.approx(out["cot"], rel=1e-12)


@pytest.mark.parametrize("cmd", [["sim", "fixed-point"], ["sim", "critical-slope"], ["paper", "--out", "unused-dir"]])
def test_a_negative_power_is_a_one_line_error_with_exit_2(cmd, tmp_path):
    res = RUN.invoke(app, [*cmd, "--clutch-hold-power-w", "-1"])
    assert res.exit_code == 2
    assert "--clutch-hold-power-w" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "unused-dir").exists()


@pytest.mark.slow
def test_the_sweep_rows_carry_the_least_system_cot_of_their_branch():
    from rimless.sim.continuation.branches import trace_gait_branches
    from rimless.sim.studies.sweep import SweepOptions, compute_point, grid_points
    from rimless.sim.studies.system_cot import gait_branch_cot, sweep_system_cot

    options = SweepOptions(backend="fast")
    res = compute_point(grid_points(P, ["er"], {"k": [2500.0]}, ["eight-leg"])[0], options)
    power = ClutchPower(hold_power_w=0.1, switch_energy_j=0.002)
    rows = sweep_system_cot(res["rows"], res["points"], power, backend="fast", rtol=1e-10)
    plain = sweep_system_cot(res["rows"], res["points"], ClutchPower(), backend="fast", rtol=1e-10)
    er = next(r for r in rows if r["branch_label"] == "er")
    er0 = next(r for r in plain if r["branch_label"] == "er")
    # no power: closed forms, the paper's numbers untouched
    assert er0["min_system_cot"] == er0["cot"] and er0["system_cot"] == math.tan(0.05)
    assert all(er0[k] == v for k, v in res["rows"][0].items() if isinstance(v, (int, float, str)) and v == v)
    # with power: the same least as the branch traced and minimised directly
    gb = next(
        g for g in trace_gait_branches(P.replace(stiffness_n_per_m=2500.0), "er", backend="fast") if g.label == "er"
    )
    direct = gait_branch_cot(gb, "fast", 1e-10).minimise(power)
    assert er["min_system_cot"] == pytest.approx(direct["min_system_cot"], rel=1e-7)
    assert er["min_system_cot_slope_rad"] == pytest.approx(direct["min_system_cot_slope_rad"], abs=5e-6)
    assert er["critical_slope_rad"] < er["min_system_cot_slope_rad"] < 0.05
    assert er["system_cot"] > er["mechanical_cot"] == pytest.approx(math.tan(0.05), rel=1e-12)


def test_the_paper_figure_is_drawn_from_its_series(tmp_path):
    """figure_system_cot writes the PNG and the CSV of exactly the series it was given (no model run)."""
    import pandas as pd

    from rimless.sim.studies.paper_system_cot import FIGURE_CSV, FIGURE_PNG, figure_system_cot

    series = [
        {
            "model": m,
            "branch_label": b,
            "hold_power_w": p,
            "min_system_cot": v,
            "min_system_cot_slope_deg": 1.3,
            "min_system_cot_at_bound": bound,
        }
        for m, b, p, v, bound in [
            ("ER", "er", 0.0, 0.022, "critical-slope"),
            ("ER", "er", 0.1, 0.04, ""),
            ("ER", "er", 1.0, 0.11, "start-slope"),
            ("VE", "fast", 0.0, 0.027, "critical-slope"),
            ("VE", "fast", 1.0, 0.027, "critical-slope"),
        ]
    ]
    files = figure_system_cot(series, 2500.0, 0.018, tmp_path)
    assert files == [tmp_path / FIGURE_PNG, tmp_path / FIGURE_CSV]
    assert (tmp_path / FIGURE_PNG).stat().st_size > 1000
    back = pd.read_csv(tmp_path / FIGURE_CSV)
    assert list(back.min_system_cot) == [r["min_system_cot"] for r in series]
