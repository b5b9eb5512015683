"""A bad value in a wheel file reads the same in `rimless sim --params` and in the trials commands (one wording,
`rimless.sim.model.params.in_source`), and a bad ``slope_deg`` is shown in degrees, the unit it was written in
(the expected lines are written here by hand from the files' contents)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from rimless.analysis.examples.bundled import data_files
from rimless.cli import app as root_app

runner = CliRunner()

FILES = {
    "neg.toml": ("m_H = -1.0\n", "error: parameter m_H must be > 0, got -1.0 in neg.toml"),
    "negsd.toml": (
        "[wheel]\nm_H = {value = -1.0, sd = 0.1}\n",
        "error: parameter m_H must be > 0, got -1.0 in negsd.toml",
    ),
    "steep.toml": (
        "slope_deg = 30\n",
        "error: parameter slope_deg must satisfy 0 <= slope < alpha/2 = 22.5 deg, got 30 deg in steep.toml",
    ),
}


def _error_line(args: list[str]) -> str:
    res = runner.invoke(root_app, args)
    assert res.exit_code == 2, res.output
    (line,) = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    return line


@pytest.mark.parametrize("name", sorted(FILES))
def test_one_wording_for_sim_and_trials(tmp_path, monkeypatch, name):
    text, expected = FILES[name]
    monkeypatch.chdir(tmp_path)
    (tmp_path / name).write_text(text, encoding="utf-8")
    trial = str(data_files()[0])
    for args in (
        ["sim", "gait", "--params", name],
        ["trials", "import", trial, "--out", "imp", "--params", name],
        ["trials", "critical-slope", trial, "--params", name],
    ):
        assert _error_line(args) == expected, args
