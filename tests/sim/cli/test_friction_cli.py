"""--guide-friction-n on the simulator commands: it acts (friction work in the JSON, a slower gait), 0 changes
nothing, and the commands that do not model guide friction refuse it with a one-line error (exit 2)."""

import json

import pytest
from typer.testing import CliRunner

from rimless.cli import app

RUN = CliRunner()


def _json(args):
    res = RUN.invoke(app, args)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_fixed_point_reports_the_friction_work_and_the_stuck_time():
    base = _json(["sim", "fixed-point", "--model", "er", "--json"])
    assert base["friction_work_per_step_j"] == 0.0 and base["guide_friction_n"] == 0.0
    zero = _json(["sim", "fixed-point", "--model", "er", "--guide-friction-n", "0", "--json"])
    assert (
        zero["theta_plus_rad"] == base["theta_plus_rad"]
        and zero["theta_dot_plus_rad_s"] == base["theta_dot_plus_rad_s"]
    )
    out = _json(["sim", "fixed-point", "--model", "er", "--guide-friction-n", "0.5", "--json"])
    assert out["guide_friction_n"] == 0.5
    assert out["friction_work_per_step_j"] > 0.005
    assert out["stick_time_s"]["trailing"] > 0.1  # the lifted leg sticks long before touchdown
    assert out["theta_dot_plus_rad_s"] < base["theta_dot_plus_rad_s"]  # friction slows the gait
    assert out["jacobian_method"] == "variational"  # exact through the stick/slip phases (rimless.sim.fast.friction)


@pytest.mark.parametrize(
    "args",
    [
        ["sim", "fixed-point", "--guide-friction-n", "-1"],
        ["sim", "fixed-point", "--guide-friction-n", "nan"],
        ["sim", "critical-slope", "--model", "rigid", "--guide-friction-n", "1"],
        ["sim", "gait", "--clutch", "firmware", "--guide-friction-n", "1"],
    ],
)
def test_bad_or_unmodelled_friction_is_refused_in_one_line(args):
    res = RUN.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "friction" in res.output and "Traceback" not in res.output


def test_commands_without_guide_friction_refuse_it_from_a_params_file(tmp_path):
    f = tmp_path / "wheel.toml"
    f.write_text("guide_friction_n = 1.0\n")
    res = RUN.invoke(app, ["sim", "sweep", "--params", str(f), "--k", "2500"])
    assert res.exit_code == 2, res.output
    assert "guide_friction_n" in res.output
    res = RUN.invoke(app, ["sim", "sweep", "--guide-friction-n", "1"])
    assert res.exit_code == 2  # no such option there


def test_gait_reports_the_friction_work_of_every_step():
    out = _json(["sim", "gait", "--model", "ve", "--steps", "2", "--guide-friction-n", "1", "--json"])
    assert out["guide_friction_n"] == 1.0
    assert len(out["friction_work_per_step_j"]) == out["steps_done"] == 2
    assert all(w > 0 for w in out["friction_work_per_step_j"])
    base = _json(["sim", "gait", "--model", "ve", "--steps", "2", "--json"])
    assert base["friction_work_per_step_j"] == [0.0, 0.0]
