"""Progress of long `--json` commands (`rimless.progress`): on stderr, never in stdout's JSON. A bar on a
terminal; where stderr is not one, a plain line every `PLAIN_EVERY_S` seconds (a virtual clock here, and
RIMLESS_PROGRESS_EVERY_S=0 for the command: a line at every update, so the test waits on lines and stages,
not on time)."""

from __future__ import annotations

import io
import json
import os
import sys
from pathlib import Path

import pytest

from rimless import progress
from tests.support.interrupt import Watched


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class _Clock:
    """A virtual clock for the plain lines: `now` advances only when the test says so."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_plain_lines_come_once_a_period_with_json_and_never_without(monkeypatch, capsys) -> None:
    clock = _Clock()
    monkeypatch.setattr(progress, "_clock", clock)
    monkeypatch.delenv(progress.PLAIN_EVERY_ENV, raising=False)
    with progress.progress_bar("coverage", total=20, json_out=True) as bar:
        for i in range(1, 21):  # one series every 10 s of the virtual clock: a line at 30, 60, 90, 120, 150, 180 s
            clock.now += 10.0
            bar.update(completed=i, description=f"series {i}/20")
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"rimless: series {i}/20 ({10 * i} s)" for i in (3, 6, 9, 12, 15, 18)], lines
    with progress.progress_bar("coverage", total=4, json_out=True) as bar:
        clock.now += 31.0
        bar.advance()  # the count, where the description does not say it
        clock.now += 1.0
        bar.advance()  # within the period: no line
    assert capsys.readouterr().err == "rimless: coverage [1/4] (31 s)\n"
    with progress.progress_bar("coverage", total=4) as bar:  # not --json: quiet as before
        clock.now += 100.0
        bar.update(completed=4, description="series 4/4")
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize(("value", "every"), [("0", 0.0), ("2.5", 2.5), ("-1", 30.0), ("nan", 30.0), ("x", 30.0)])
def test_the_period_from_the_environment(monkeypatch, value, every) -> None:
    monkeypatch.setenv(progress.PLAIN_EVERY_ENV, value)
    assert progress.plain_every_s() == every


def test_a_bar_on_a_terminal_with_json_leaves_stdout_to_the_json(monkeypatch, capsys) -> None:
    """rich redirects stdout into its display (on the stderr console) by default: with --json it must not."""
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with progress.progress_bar("coverage", total=2, json_out=True) as bar:
        bar.update(completed=1, description="series 1/2")
        print('{"coverage": 0.95}')
    assert capsys.readouterr().out == '{"coverage": 0.95}\n'
    assert "series 1/2" in term.getvalue() and '{"coverage"' not in term.getvalue(), repr(term.getvalue())


def test_a_long_json_command_in_a_pipe_prints_progress_lines_and_pure_json(tmp_path: Path) -> None:
    """`trials floquet-coverage --json` with stderr a pipe: its progress lines arrive on stderr while it runs
    (one per series with RIMLESS_PROGRESS_EVERY_S=0), its stages are reached, and stdout parses as one JSON
    object with the study's keys."""
    env = {**os.environ, "RIMLESS_PROGRESS_EVERY_S": "0"}  # the documented name (docs/cli.md)
    argv = [sys.executable, "-m", "rimless", "trials", "floquet-coverage", "--series", "2", "--trials", "1"]
    with Watched([*argv, "--json"], cwd=tmp_path, env=env) as cmd:
        cmd.wait_for(stage="series 1/2")
        line = cmd.wait_for(stderr="rimless: series 1/2")
        done = cmd.finish(timeout_s=600)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout)
    assert out["series"] == 2 and "corrected" in out and out["kind"] == "rigid"
    assert line.startswith("rimless: series 1/2 (") and "rimless: series 2/2 (" in done.stderr, done.stderr
    assert "floquet coverage" in done.stages and "series 2/2" in done.stages, done.stages
