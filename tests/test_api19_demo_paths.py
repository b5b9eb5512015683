"""`rimless demo` run outside the repository names the bundled trials relative to the data folder
(``SYNTHETIC_er_...csv``, ``critical/SYNTHETIC_crit_...csv``) in its JSON and in its printed lines, as the report
and its provenance do: the install's absolute path never appears (it did in the JSON's ``file`` keys and the
stderr lines of suspect trials)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from rimless.analysis.examples.bundled import DATA_DIR
from rimless.analysis.examples.bundled import data_files as er_files
from rimless.analysis.examples.critical_series import data_files as critical_files
from rimless.analysis.report import batch


def test_run_demo_json_names_the_bundled_trials_relative_to_the_data_folder(tmp_path, monkeypatch):
    er, crit = er_files()[0], critical_files()[0]
    monkeypatch.chdir(tmp_path)  # outside the repository: the paths are not below the working folder
    monkeypatch.setattr(batch, "demo_inputs", lambda: [er, crit])  # two of the bundled trials, for time
    monkeypatch.setattr(batch, "critical_data_files", lambda: [])  # no critical slope nor calibration (time)
    res = batch.run_demo(Path("demo"), json_out=True)
    text = json.dumps(res.summary())
    assert str(DATA_DIR) not in text
    expected = [er.name, f"critical/{crit.name}"]
    assert [r["file"] for r in res.summary()["inputs"]] == expected
    assert [r["file"] for r in res.summary()["trials"]] == expected
    assert res.shown(crit) == f"critical/{crit.name}"
    # the page and its provenance name them by file name (unchanged)
    assert str(DATA_DIR) not in (tmp_path / "demo" / "report.html").read_text()


def test_bundled_relative_leaves_other_paths_alone(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    other = str(tmp_path / "data" / "x.csv")
    assert batch.bundled_relative({"file": other, "n": 1, "l": [f"{DATA_DIR}/a.csv: bad"]}) == {
        "file": other,
        "n": 1,
        "l": ["a.csv: bad"],
    }


@pytest.mark.xdist_group("demo")  # one worker reads the demo; the other never waits on its lock
@pytest.mark.slow
def test_the_readme_demo_prints_no_absolute_data_path(demo_run):
    assert demo_run.returncode == 0, demo_run.stderr[-3000:]
    assert str(DATA_DIR) not in demo_run.stdout + demo_run.stderr


@pytest.mark.xdist_group("demo")
@pytest.mark.slow
def test_every_option_the_demo_suggests_is_one_it_takes(demo_run):
    """A warning or hint the demo prints (e.g. the pooled slope bins' "give a smaller --slope-bin-deg") names only
    options `rimless demo` has: the demo has no options of `trials report` it does not take."""
    from typer.testing import CliRunner

    from rimless.cli import app

    assert demo_run.returncode == 0, demo_run.stderr[-3000:]
    suggested = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]+", demo_run.stdout + demo_run.stderr))
    assert suggested, "the demo printed no option: nothing to check"
    help_text = CliRunner().invoke(app, ["demo", "--help"], env={"COLUMNS": "200", "TERM": "dumb"}).output
    assert {o for o in suggested if o not in help_text} == set(), help_text
