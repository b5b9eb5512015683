"""`trials import`'s progress (`rimless.analysis.report.batch.import_files`) follows the one rule of
`rimless.progress` whatever the number of files: a transient bar on a terminal; where stderr is not one, plain lines
with `--json` only. One file is work of seconds too (1.5 s of CPU, 4.9 s at load 11 for the smallest bundled
trial), so a researcher sees which file is being read and that it goes on. Before, a one-file import passed
`json_out=True` to hide its bar, which stopped hiding it on a terminal in session 17 and, off one, printed the
`--json` progress lines of a command not given `--json`."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import pytest

from rimless import progress
from rimless.analysis.report.batch import import_files

DATA = Path(__file__).resolve().parents[3] / "analysis" / "data"
TRIALS = [DATA / "SYNTHETIC_er_slope2.0deg_run1.csv", DATA / "SYNTHETIC_er_slope2.0deg_run2.csv"]


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("json_out", [False, True])
@pytest.mark.parametrize("count", [1, 2])
def test_off_a_terminal_progress_lines_come_with_json_only_for_one_file_as_for_two(
    tmp_path, monkeypatch, capsys, count, json_out
) -> None:
    """RIMLESS_PROGRESS_EVERY_S=0: a plain line at every update where lines are due. Fails on main for one file
    without --json (its lines were printed)."""
    monkeypatch.setenv(progress.PLAIN_EVERY_ENV, "0")
    monkeypatch.setattr(sys, "argv", ["rimless", "trials", "import"])  # no --json on the command line
    rows = import_files(TRIALS[:count], tmp_path / "out", {}, json_out=json_out)
    assert [r["status"] for r in rows] == ["imported"] * count, rows
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("rimless: importing")]
    if json_out:
        assert any(TRIALS[count - 1].name in ln for ln in lines), lines
    else:
        assert lines == []


def test_on_a_terminal_one_file_shows_the_bar_naming_it(tmp_path, monkeypatch) -> None:
    """The bar, transient, says which file is read: for one file as for several (with or without --json)."""
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    import_files(TRIALS[:1], tmp_path / "out", {}, json_out=False)
    assert f"importing {TRIALS[0].name}" in term.getvalue(), repr(term.getvalue())
