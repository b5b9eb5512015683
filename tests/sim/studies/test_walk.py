"""`walk_gait` (what `rimless sim gait` runs with the ideal clutch): from the fixed point every step repeats
(the invariant of a period-1 gait), the trajectory and figure are written, outputs are checked first."""

import pytest

from rimless.errors import OutputFileError, ParameterError
from rimless.sim.model.params import WheelParams
from rimless.sim.studies.walk import walk_gait


def test_from_the_fixed_point_every_step_repeats(tmp_path):
    out = walk_gait(WheelParams(), "er", steps=3, out=tmp_path / "t.csv", backend="fast")
    assert out["start"] == "fixed point" and out["steps_done"] == 3 and out["failure"] is None
    periods, ratios = out["step_periods_s"], out["energy_ratios"]
    assert max(periods) - min(periods) < 1e-7 and max(ratios) - min(ratios) < 1e-7
    assert (tmp_path / "t.csv").stat().st_size > 0 and out["out"] == str(tmp_path / "t.csv")


def test_a_given_start_is_reported_as_given():
    out = walk_gait(WheelParams(), "er", steps=1, theta_dot=2.6, backend="fast")
    assert out["start"] == "given" and out["theta_dot_plus_rad_s"] == 2.6


def test_outputs_are_refused_before_the_work(tmp_path):
    with pytest.raises(ParameterError, match="traj.txt"):
        walk_gait(WheelParams(), "er", out=tmp_path / "traj.txt")
    with pytest.raises(OutputFileError, match="--out"):
        walk_gait(WheelParams(), "er", out=__import__("pathlib").Path("/proc/rimless-nope/t.csv"))
    with pytest.raises(ParameterError, match="--theta-dot"):
        walk_gait(WheelParams(), "er", theta_dot=-1.0)
