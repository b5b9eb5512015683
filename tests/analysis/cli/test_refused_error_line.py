"""A refused input is one ``error:`` line naming its file and line, with or without ``--json`` (docs/cli.md; issue
31: "`--json` refusals also print the `error:` line"), in every `trials` command that reads exports as
`trials import` does. Before: `trials report`, `trials floquet`, `trials critical-slope` and `trials calibrate`
printed ``refused: ...`` (no ``error:``), and `trials floquet` and `trials calibrate` with every input refused
added a summary line."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rimless.analysis.cli import _print_report, app
from rimless.analysis.examples.bundled import data_files
from rimless.analysis.report.html import build_report
from tests.support.cli_lines import stderr_lines

runner = CliRunner()


def _broken_copy(folder: Path, name: str = "broken_line.csv") -> Path:
    """A bundled export with a letter in one cell of line 30 (a hand-edited or corrupted export)."""
    src = data_files()[0].read_text().splitlines(keepends=True)
    cells = src[29].split(",")
    cells[3] = "abc"
    src[29] = ",".join(cells)
    bad = folder / name
    bad.write_text("".join(src))
    return bad


@pytest.mark.parametrize("json_out", [False, True])
def test_floquet_every_input_refused_is_one_error_line(tmp_path, json_out):
    bad = _broken_copy(tmp_path)
    res = runner.invoke(app, ["floquet", str(bad), *(["--json"] if json_out else [])])
    assert res.exit_code == 2, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: {bad}, line 30"), lines


def test_report_refused_input_prints_an_error_line(tmp_path, capsys):
    good = Path(shutil.copy(data_files()[1], tmp_path / data_files()[1].name))
    bad = _broken_copy(tmp_path)
    rep = build_report([good, bad], tmp_path / "rep", import_kwargs={"max_gap_s": 0.05}, critical=False)
    assert [Path(r.file).name for r in rep.refused] == [bad.name]
    for json_out in (False, True):  # with --json too: stdout the JSON, the refusal on stderr
        _print_report(rep, "er", json_out=json_out)
        err = capsys.readouterr().err.splitlines()
        refusals = [ln for ln in err if bad.name in ln]
        assert len(refusals) == 1 and refusals[0].startswith("error: ") and "line 30" in refusals[0], (json_out, err)


@pytest.mark.parametrize("command", ["critical-slope", "calibrate", "floquet"])
@pytest.mark.parametrize("json_out", [False, True])
def test_every_input_refused_is_one_error_line_per_file(tmp_path, command, json_out):
    """Two unreadable inputs: exactly two lines, each ``error: <file>, line 30, ...``, exit 2 (no summary line)."""
    bad = [_broken_copy(tmp_path, "broken_a.csv"), _broken_copy(tmp_path, "broken_b.csv")]
    res = runner.invoke(app, [command, *map(str, bad), *(["--json"] if json_out else [])])
    assert res.exit_code == 2, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 2, lines
    for b, line in zip(bad, lines, strict=True):
        assert line.startswith(f"error: {b}, line 30, column "), lines
    assert res.stdout == "", res.stdout


def test_critical_slope_refused_input_beside_a_read_one_prints_an_error_line(tmp_path):
    """One good export and one broken one: the estimate is printed (JSON on stdout), the broken file has its one
    ``error:`` line on stderr, and the exit is 2."""
    good = Path(shutil.copy(data_files()[1], tmp_path / data_files()[1].name))
    bad = _broken_copy(tmp_path)
    res = runner.invoke(app, ["critical-slope", str(good), str(bad), "--json"])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in stderr_lines(res.stderr) if bad.name in ln]
    assert len(lines) == 1 and lines[0].startswith(f"error: {bad}, line 30, column "), res.stderr
    assert not any(ln.startswith("refused:") for ln in res.stderr.splitlines()), res.stderr
    assert '"refused"' in res.stdout
