"""The report's progress count never passes its total (before: `rimless demo --json` off a terminal printed
``rimless: compared critical slope [22/18]``: the stages after the comparisons, the critical slope and the held
parameters' runs, were counted as inputs and named "compared ...")."""

from __future__ import annotations

import re

from rimless.analysis.examples.bundled import data_files
from rimless.analysis.report.batch import run_report

COUNT = re.compile(r"^rimless: (.*) \[(\d+)/(\d+)\] \(\d+ s\)$")


def test_progress_counts_the_inputs_only(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RIMLESS_PROGRESS_EVERY_S", "0")  # a plain line at every update (stderr is not a terminal)
    files = data_files()[:2]
    run_report(files, tmp_path / "rep", json_out=True, import_kwargs={"max_gap_s": 0.05}, model="er", slope_bin_deg=0.5)
    lines = [m.groups() for ln in capsys.readouterr().err.splitlines() if (m := COUNT.match(ln))]
    assert lines, "no progress line"
    assert all(int(done) <= int(total) == len(files) for _, done, total in lines), lines
    assert max(int(done) for _, done, _ in lines) == len(files), lines
    names = {f.name for f in files}
    assert all(text.removeprefix("compared ") in names for text, *_ in lines if text.startswith("compared ")), lines
