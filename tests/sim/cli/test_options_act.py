"""Every option of the sim commands acts or is refused, and a valid input without a result exits 1 with one
`error:` line on stderr (nothing on stdout)."""

import json
import math

import pytest
from typer.testing import CliRunner

from rimless.cli import app
from tests.support.cli_lines import stderr_lines

RUN = CliRunner()


def _one_error(res, code: int, *words: str) -> str:
    assert res.exit_code == code, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    for w in words:
        assert w in lines[0], lines[0]
    assert "Traceback" not in res.output
    return lines[0]


# ------------------------------------------------------------------------ options that were ignored


def test_critical_slope_starts_on_the_slope_given(monkeypatch):
    """`sim critical-slope --slope-deg 2` starts the continuation at 2 deg, not Table 1's 0.05 rad."""
    import rimless.sim.studies.gaits as gaits

    seen = {}

    def fake(params, model, **kw):
        seen.update(kw, slope=params.slope_rad)
        return {"fake": True}

    monkeypatch.setattr(gaits, "critical_slope_study", fake)
    res = RUN.invoke(app, ["sim", "critical-slope", "--slope-deg", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert seen["start_slope_rad"] == pytest.approx(math.radians(2.0), rel=1e-12)
    res = RUN.invoke(app, ["sim", "critical-slope", "--json"])  # default: Table 1's slope
    assert seen["start_slope_rad"] == pytest.approx(0.05, rel=1e-12)
    res = RUN.invoke(app, ["sim", "critical-slope", "--start-slope-rad", "0.04", "--json"])
    assert res.exit_code == 0 and seen["start_slope_rad"] == pytest.approx(0.04)
    _one_error(
        RUN.invoke(app, ["sim", "critical-slope", "--slope-deg", "2", "--start-slope-rad", "0.04"]),
        2,
        "--slope-deg",
        "--start-slope-rad",
    )
    _one_error(RUN.invoke(app, ["sim", "critical-slope", "--model", "rigid", "--slope-deg", "2"]), 2, "--slope-deg")


def test_sweep_searches_on_the_slope_given(monkeypatch, tmp_path):
    import rimless.sim.studies.sweep as sweep

    seen = {}

    def fake(params, *, options, **kw):
        seen["start"] = options.start_slope_rad
        return {"rows": [], "files": [], "computed": 0, "cached": 0, "seconds": 0.0, "workers": 1}

    monkeypatch.setattr(sweep, "branch_sweep", fake)
    res = RUN.invoke(
        app,
        [
            "sim",
            "sweep",
            "--k",
            "2700",
            "--slope-deg",
            "2",
            "--scheduler",
            "sync",
            "--no-cache",
            "--out",
            str(tmp_path / "s"),
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    assert seen["start"] == pytest.approx(math.radians(2.0), rel=1e-12)
    _one_error(RUN.invoke(app, ["sim", "sweep", "--slope-deg", "0", "--scheduler", "sync"]), 2, "--slope-deg")


def test_stress_refuses_the_options_its_grid_replaces():
    for option in ("--k", "--c", "--slope-deg", "--leg-mass-kg"):
        _one_error(RUN.invoke(app, ["sim", "stress", option, "1"]), 2, option)


def test_gait_refuses_what_the_chosen_clutch_does_not_use():
    for args, option in (
        (["--bench"], "--bench"),
        (["--rate-hz", "1000"], "--rate-hz"),
        (["--clutch-delay-ms", "3"], "--clutch-delay-ms"),
        (["--seed", "3"], "--seed"),
    ):
        _one_error(RUN.invoke(app, ["sim", "gait", *args]), 2, option, "--clutch firmware")
    _one_error(RUN.invoke(app, ["sim", "gait", "--clutch", "firmware", "--forces"]), 2, "--forces")


# ------------------------------------------------------------------------ no result: exit 1, one line


def test_gait_with_the_firmware_walks_the_steps_asked_for():
    """`--steps 4` walks 4 steps (it used to walk 6); too short to fit the map, which the output says."""
    res = RUN.invoke(app, ["sim", "gait", "--clutch", "firmware", "--steps", "4", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["steps_done"] == 4 and len(out["steps"]) == 4
    assert out["fixed_point"]["eigenvalues_fitted"][0][0] is None and out["fixed_point"]["stable_fitted"] is None
    res = RUN.invoke(app, ["sim", "gait", "--clutch", "firmware", "--steps", "4"], env={"COLUMNS": "80"})
    assert res.exit_code == 0 and "4 of 4" in res.stdout and "too short to fit the map" in res.stdout


def test_gait_that_completes_no_step_is_one_error_line(tmp_path):
    out = tmp_path / "traj.csv"
    res = RUN.invoke(app, ["sim", "gait", "--theta-dot", "0.5", "--out", str(out)])
    _one_error(res, 1, "no step completed", "stall")
    assert res.stdout.strip() == ""
    assert not out.exists()  # no half-written output


def test_gaits_without_a_gait_is_one_error_line():
    res = RUN.invoke(app, ["sim", "gaits", "--model", "er", "--slope-deg", "0.5", "--guesses", "3"])
    _one_error(res, 1, "no period-1 gait", "er")
    assert res.stdout.strip() == ""


# ------------------------------------------------------------------------ a fixed point wherever a gait exists


def _json(args):
    res = RUN.invoke(app, args)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def _residual_on_the_reference_map(model: str, z, **changes) -> float:
    """|P(z) - z| on the scipy reference integrator at tight tolerance (independent of the compiled map)."""
    import numpy as np

    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.poincare import PoincareMap

    pmap = PoincareMap(WheelParams().replace(**changes), model, ScipyIntegrator(rtol=1e-12, atol=1e-13))
    z = np.asarray(z, dtype=float)
    return float(np.max(np.abs(pmap(z) - z)))


@pytest.mark.parametrize(
    ("model", "option", "value", "change"),
    [
        ("ve", "--k", "2000", {"stiffness_n_per_m": 2000.0}),
        ("er", "--c", "0", {"damping_ns_per_m": 0.0}),
    ],
)
def test_fixed_point_falls_back_on_the_gaits_search(model, option, value, change):
    out = _json(["sim", "fixed-point", "--model", model, option, value, "--json"])
    assert out["found_by"] in ("newton", "gaits search")
    assert out["stable"] and out["contact_valid"]
    assert _residual_on_the_reference_map(model, [out["theta_plus_rad"], out["theta_dot_plus_rad_s"]], **change) < 1e-7


# ------------------------------------------------------------------------ 80 columns: names wrap, numbers never


@pytest.mark.parametrize(
    "args",
    [
        ["sim", "fixed-point", "--model", "er"],
        ["sim", "fixed-point", "--model", "ve"],
        ["sim", "gaits", "--model", "ve", "--guesses", "4"],
    ],
)
def test_tables_at_80_columns_cut_no_number(args):
    res = RUN.invoke(app, args, env={"COLUMNS": "80", "TERM": "dumb"})
    assert res.exit_code == 0, res.output
    assert "…" not in res.stdout, res.stdout
    assert all(len(line) <= 80 for line in res.stdout.splitlines())
    if args[1] == "fixed-point":  # every number of the JSON object is printed whole
        out = _json([*args, "--json"])
        assert f"{out['step_period_s']:.6g}" in res.stdout
        assert f"{out['trailing_foot_min_height_m'] * 1e3:.6g}" in res.stdout
        assert f"{out['energy_ratio']:.6g}" in res.stdout


def test_the_quantity_table_wraps_names_not_numbers():
    from rich.console import Console

    from rimless.sim.cli.output import table

    rows = [
        ("trailing foot lowest point (mm)", -8.41234567),
        ("eigenvalues", "0.12345-0.00000j, 0.54321+0.00000j"),
        ("min normal force b in DLSP (N)", 1.7123456),
    ]
    for width in (80, 40):
        con = Console(width=width, record=True, file=open("/dev/null", "w"))
        con.print(table("t", rows))
        text = con.export_text()
        for number in ("-8.41235", "1.71235", "0.12345-0.00000j", "0.54321+0.00000j"):
            assert number in text, text
        assert "…" not in text


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["sim", "sweep", "--steps", "8"], "--steps"),
        (["sim", "sweep", "--seed", "3"], "--seed"),
        (["sim", "sweep", "--critical-low-deg", "1"], "--critical-low-deg"),
        (["sim", "sweep", "--clutch", "firmware", "--guesses", "5"], "--guesses"),
        (["sim", "sweep", "--clutch", "firmware", "--start-slope-rad", "0.04"], "--start-slope-rad"),
        (["sim", "sweep", "--workers", "2", "--scheduler", "sync"], "--workers"),
        (["paper", "--workers", "2", "--scheduler", "sync"], "--workers"),
        (["paper", "--cache-dir", "c", "--no-cache"], "--cache-dir"),
        (["sim", "sweep", "--cache-dir", "c", "--no-cache"], "--cache-dir"),
    ],
)
def test_an_option_the_run_would_ignore_is_refused(args, option):
    _one_error(RUN.invoke(app, args), 2, option)
