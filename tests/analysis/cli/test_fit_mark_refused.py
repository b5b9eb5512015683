"""A wheel file's ``"fit"`` mark is "fitted by `trials calibrate` (added to --fit); refused elsewhere"
(docs/trials.md). `rimless demo` and `trials report` took it silently: they held c at Table 1's 8 +- 4 N s/m
and listed it as "table1: to be fitted", carrying its +-4 into the model's critical slope (exit 0). Now both
refuse it before any work: one `error:` line naming the file and the key, exit 2, with `--json` too."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from rimless.cli import app
from tests.support.cli_lines import stderr_lines

runner = CliRunner()


@pytest.mark.parametrize("command", [["demo"], ["trials", "report", "TRIAL"]])
@pytest.mark.parametrize("json_out", [False, True])
def test_a_fit_mark_is_refused_before_any_work(tmp_path, command, json_out):
    wheel = tmp_path / "wheel.toml"
    wheel.write_text('[wheel]\nm_H = 2.1\nc = "fit"\n', encoding="utf-8")
    trial = tmp_path / "t.csv"
    trial.write_bytes(b"")  # never read: the wheel file is refused first
    out = tmp_path / "out"
    args = [str(trial) if a == "TRIAL" else a for a in command]
    res = runner.invoke(app, [*args, "--out", str(out), "--params", str(wheel), *(["--json"] if json_out else [])])
    assert res.exit_code == 2, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1 and lines[0].startswith(f"error: {wheel}: key c"), lines
    assert res.stdout == "" and not out.exists()


@pytest.mark.parametrize(("mark", "calibrated"), [("c", False), ("k", False), ("k", True)])
def test_critical_slope_fit_mark_says_what_to_do(tmp_path, mark, calibrated):
    """`trials critical-slope` refusing a "fit" mark says where "fit" is taken and that it fits c with
    --calibrated; before, with ``c = "fit"`` it said "fits only c (--calibrated)" while refusing c."""
    wheel = tmp_path / "wheel.toml"
    wheel.write_text(f'[wheel]\n{mark} = "fit"\n', encoding="utf-8")
    trial = tmp_path / "t.csv"
    trial.write_bytes(b"")  # never read: the wheel file is refused first
    extra = ["--calibrated"] if calibrated else []
    res = runner.invoke(app, ["trials", "critical-slope", str(trial), "--params", str(wheel), *extra])
    assert res.exit_code == 2, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f'error: {wheel}: key {mark} = "fit": "fit" is taken only by `trials calibrate`; '), (
        lines
    )
    assert "trials critical-slope fits c with --calibrated" in lines[0], lines
    assert "fits only c" not in lines[0], lines


def test_critical_slope_calibrated_takes_a_c_fit_mark(tmp_path):
    """With --calibrated, ``c = "fit"`` is what the command does: the wheel file passes (the trial is read next)."""
    wheel = tmp_path / "wheel.toml"
    wheel.write_text('[wheel]\nc = "fit"\n', encoding="utf-8")
    res = runner.invoke(
        app, ["trials", "critical-slope", str(tmp_path / "none.csv"), "--params", str(wheel), "--calibrated"]
    )
    assert res.exit_code == 2, res.output
    assert "fit" not in res.stderr and "none.csv" in res.stderr, res.stderr
