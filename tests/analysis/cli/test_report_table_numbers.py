"""The table `rimless trials report` and `rimless demo` print never wraps inside a number (issue 31): at 80 and
120 columns every number of each trial's metrics row (the JSON's values, formatted as the table does) is whole
on that trial's line, each trial name is whole once its lines are joined and is broken after a ``_`` or ``-``
only (before: ``SYNTHETIC_crit_slope1.30deg_release1.`` / ``9`` at 80 columns), and no line is wider than
the terminal."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from rimless.analysis.cli import _print_report
from rimless.analysis.examples.bundled import data_files
from rimless.analysis.examples.critical_series import data_files as critical_files
from rimless.analysis.report.html import build_report
from tests.support.printed_table import name_lines, parse_table

GAP = {"max_gap_s": 0.05}
FORMATS = (
    ("slope_deg", ".3f"),
    ("steps", "d"),
    ("rms_com_error_mm", ".2f"),
    ("mean_abs_period_error_ms", ".1f"),
    ("theta_dot_plus_rad_s", ".3f"),
)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The demo's two series (its longest names, numbers inside them) and a long name without a series."""
    folder = tmp_path_factory.mktemp("names")
    files = [shutil.copy(f, folder / f.name) for f in (*critical_files()[:2], *critical_files()[10:], data_files()[0])]
    files.append(shutil.copy(data_files()[1], folder / "a_much_longer_trial_name_of_wheel-7_at_slope_1.53deg_r2.csv"))
    # longer than the name column at 120 columns, and mostly numbers: a fold anywhere would split one
    numbers = "_".join(f"{10 + i}.{3 * i % 10}{7 * i % 10}" for i in range(16))
    files.append(shutil.copy(data_files()[2], folder / f"w_{numbers}.csv"))
    return build_report([Path(f) for f in files], folder / "rep", import_kwargs=GAP, critical=False)


@pytest.mark.parametrize("columns", [80, 120])
def test_no_number_is_split_across_lines(report, columns, monkeypatch, capsys):
    monkeypatch.setenv("COLUMNS", str(columns))
    _print_report(report, "er", json_out=False)
    text = capsys.readouterr().out
    assert "…" not in text, text
    table = [ln for ln in text.splitlines() if "│" in ln or "┃" in ln or "━" in ln]
    assert table and all(len(ln) <= columns for ln in table), text
    rows, prefix = parse_table(text)
    metrics = report.metrics()
    assert len(rows) == len(metrics)
    for (name, cells), m in zip(rows, metrics):
        stem = Path(m["trial"]).name.removesuffix(".csv")
        assert (prefix or "") + name == stem, (name, stem)
        for key, fmt in FORMATS:
            if m[key] is not None and m[key] == m[key]:  # NaN: an empty cell
                assert format(m[key], fmt) in cells, (key, m[key], cells)
    for lines, m in zip(name_lines(text), metrics):
        for line in lines[:-1]:
            assert line[-1] in "_-", lines  # broken after a separator only
        stem = Path(m["trial"]).name.removesuffix(".csv")
        for number in re.findall(r"\d+(?:\.\d+)?", stem):  # every number in the name whole on one line
            assert any(number in line for line in lines), (number, lines)
