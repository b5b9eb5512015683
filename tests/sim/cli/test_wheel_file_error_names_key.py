"""An invalid value in a wheel file is named by the file's key as written (``k``, ``stiffness_n_per_m``), not
by a `rimless sim` option: the `trials` commands have no ``--k``, and the value did not come from one. Before,
every path said ``parameter stiffness_n_per_m [--k] must be > 0``. A value given as ``rimless sim --k`` still
names ``--k``."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from rimless.cli import app
from rimless.errors import ParameterError
from rimless.sim.model.params import WheelParams, load_params
from rimless.sim.model.uncertain import read_wheel_input
from tests.support.cli_lines import stderr_lines

runner = CliRunner()


@pytest.mark.parametrize(
    ("line", "key"),
    [("k = -1", "k"), ("stiffness_n_per_m = {value = -1, sd = 10}", "stiffness_n_per_m"), ("L0 = 0", "L0")],
)
@pytest.mark.parametrize("command", ["critical-slope", "calibrate", "floquet"])
def test_trials_wheel_file_error_names_the_files_key(tmp_path, line, key, command):
    wheel = tmp_path / "neg.toml"
    wheel.write_text(f"[wheel]\n{line}\n", encoding="utf-8")
    trial = tmp_path / "t.csv"
    trial.write_bytes(b"")  # never read: the wheel file is refused first
    res = runner.invoke(app, ["trials", command, str(trial), "--params", str(wheel)])
    assert res.exit_code == 2, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: parameter {key} must be > 0, got "), lines
    assert "[--" not in lines[0] and str(wheel) in lines[0], lines


def test_python_readers_name_the_files_key(tmp_path):
    wheel = tmp_path / "w.toml"
    wheel.write_text("m_H = -2.0\n", encoding="utf-8")
    for read in (load_params, read_wheel_input):
        with pytest.raises(ParameterError, match=r"^parameter m_H must be > 0, got -2\.0") as err:
            read(wheel)
        assert "--hub-mass-kg" not in str(err.value)


def test_sim_params_file_names_the_key_and_sim_option_names_the_option(tmp_path):
    wheel = tmp_path / "wheel.toml"
    wheel.write_text("k = -5\n", encoding="utf-8")
    res = runner.invoke(app, ["sim", "fixed-point", "--params", str(wheel)])
    assert res.exit_code == 2, res.output
    assert stderr_lines(res.stderr) == [f"error: parameter k must be > 0, got -5 in {wheel}"]
    res = runner.invoke(app, ["sim", "fixed-point", "--k", "-1"])  # the option given: named
    assert res.exit_code == 2, res.output
    (only,) = stderr_lines(res.stderr)
    assert only.startswith("error: parameter stiffness_n_per_m [--k] must be > 0, got -1"), only
    with pytest.raises(ParameterError, match=r"\[--k\]"):  # the dataclass itself: as before
        WheelParams(stiffness_n_per_m=-1.0)
