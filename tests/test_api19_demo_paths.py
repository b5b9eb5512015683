"""`rimless demo` run outside the repository names the bundled trials relative to the data folder
(``SYNTHETIC_er_...csv``, ``critical/SYNTHETIC_crit_...csv``) in its JSON and in its printed lines, as the report
and its provenance do: the install's absolute path never appears (it did in the JSON's ``file`` keys and the
stderr lines of suspect trials). The demo's own slope bins never pool trials whose slopes differ beyond their
intervals, and it says what each series' verdicts mean (issue 31: "the output never contradicts itself")."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from rimless.analysis.examples.bundled import DATA_DIR
from rimless.analysis.examples.bundled import data_files as er_files
from rimless.analysis.examples.critical_series import data_files as critical_files
from rimless.analysis.report import batch

#: the demo's trials the Python run reads: one of each series; two SYNTHETIC_crit trials 0.15 deg apart that
#: the demo's 0.5-deg bins pooled (a warning about its own binning), both compared with Table 1's wheel
DEMO_SUBSET = (
    "SYNTHETIC_er_slope1.5deg_run1.csv",
    "SYNTHETIC_crit_slope1.45deg_release2.5.csv",
    "SYNTHETIC_crit_slope1.60deg_release2.5.csv",  # suspect, with "(see above)": the time shift at its limit
)


@pytest.fixture(scope="module")
def demo_py(tmp_path_factory):
    """One `run_demo` from Python on `DEMO_SUBSET` (no critical slope nor calibration, for time), run outside the
    repository, shared by the tests that only read what it returned and wrote."""
    files = [f for f in (*er_files(), *critical_files()) if f.name in DEMO_SUBSET]
    assert len(files) == len(DEMO_SUBSET)
    folder = tmp_path_factory.mktemp("demo_py")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(folder)  # outside the repository: the paths are not below the working folder
        mp.setattr(batch, "demo_inputs", lambda: files)
        mp.setattr(batch, "critical_data_files", lambda: [])  # no critical slope nor calibration (time)
        res = batch.run_demo(Path("demo"), json_out=True)
    return folder, files, res


def test_run_demo_json_names_the_bundled_trials_relative_to_the_data_folder(demo_py):
    folder, files, res = demo_py
    text = json.dumps(res.summary())
    assert str(DATA_DIR) not in text
    expected = [f.name if f.parent == DATA_DIR else f"critical/{f.name}" for f in files]
    assert [r["file"] for r in res.summary()["inputs"]] == expected
    assert [r["file"] for r in res.summary()["trials"]] == expected
    crit = files[-1]
    assert res.shown(crit) == f"critical/{crit.name}"
    # the page and its provenance name them by file name (unchanged)
    assert str(DATA_DIR) not in (folder / "demo" / "report.html").read_text()


def test_the_demo_never_pools_trials_whose_slopes_differ_beyond_their_intervals(demo_py):
    """The demo's own binning (default: by the slopes' intervals, per series) raises no pooled-slope warning about
    itself: every step-period bin's trials share a slope inside all their 95 % intervals (checked from the JSON)."""
    folder, _, res = demo_py
    out = res.summary()
    assert out["warnings"] == []
    ci = {Path(r["file"]).name: r["slope_ci_deg"] for r in out["inputs"]}
    bins: dict[tuple[str, float], set[str]] = {}
    for g in res.groups:
        bins.setdefault((g.series, g.slope_deg), set()).update(g.trials)
    assert sorted(t for trials in bins.values() for t in trials) == sorted(DEMO_SUBSET)
    # the trials the 0.5-deg bins pooled: their intervals do not overlap, and they are apart
    low, high = DEMO_SUBSET[1], DEMO_SUBSET[2]
    assert max(ci[low]) < min(ci[high])
    assert not any({low, high} <= trials for trials in bins.values())
    for trials in bins.values():
        assert max(min(ci[t]) for t in trials) <= min(max(ci[t]) for t in trials), trials
    page = (folder / res.report_html).read_text()
    assert "bins of overlapping slope intervals" in page and "rounded to" not in page


def test_the_demo_says_what_its_verdicts_mean_for_each_series(demo_py):
    """SYNTHETIC_er (this simulator at Table 1): all ok, and said to agree; SYNTHETIC_crit (a lossier truth):
    suspect against Table 1, said to be expected, with the truth's c and travel force read from its truth file."""
    from rimless.analysis.examples.critical_series import load_truth

    _, _, res = demo_py
    statuses = {c.name: c.status for c in res.comparisons}
    verdicts = {v["series"]: v for v in res.summary()["verdicts"]}
    assert set(verdicts) == {"SYNTHETIC_er", "SYNTHETIC_crit"}
    er, crit = verdicts["SYNTHETIC_er"], verdicts["SYNTHETIC_crit"]
    assert statuses[DEMO_SUBSET[0]] == "ok" and (er["ok"], er["suspect"], er["not_compared"]) == (1, 0, 0)
    assert "agree with it, as they should" in er["meaning"]
    n_suspect = sum(statuses[n] == "suspect" for n in DEMO_SUBSET[1:])
    assert n_suspect >= 1 and crit["suspect"] == n_suspect and crit["ok"] + crit["suspect"] == 2
    truth = load_truth()["dataset"]
    assert "Expected" in crit["meaning"] and "against Table 1's wheel (c = 8 N s/m)" in crit["meaning"]
    assert (
        f"c = {truth['damping_ns_per_m']:g} N s/m and a constant {truth['guide_friction_n']:g} N force"
        in (crit["meaning"])
    )


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
    """A warning or hint the demo prints (e.g. the SYNTHETIC_crit verdicts' "`rimless trials report` with `--params`") names only
    options `rimless demo` has: the demo has no options of `trials report` it does not take."""
    from typer.testing import CliRunner

    from rimless.cli import app

    assert demo_run.returncode == 0, demo_run.stderr[-3000:]
    suggested = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]+", demo_run.stdout + demo_run.stderr))
    assert suggested, "the demo printed no option: nothing to check"
    help_text = CliRunner().invoke(app, ["demo", "--help"], env={"COLUMNS": "200", "TERM": "dumb"}).output
    assert {o for o in suggested if o not in help_text} == set(), help_text


def test_a_printed_suspect_line_points_at_nothing_unprinted(demo_py, capsys):
    """A suspect trial's "(see above)" names the comparison's own warnings where they are not printed."""
    from rimless.analysis.cli import _print_report

    folder, _, res = demo_py
    stalled = next(c for c in res.comparisons if c.name == DEMO_SUBSET[2])
    assert stalled.status == "suspect" and "(see above)" in stalled.message and stalled.warnings, stalled.message
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(folder)
        _print_report(res, "er", False)
    err = capsys.readouterr().err
    assert "(see above)" not in err
    line = next(ln for ln in err.splitlines() if DEMO_SUBSET[2] in ln)
    assert all(w in line for w in stalled.warnings), err


def test_the_verdicts_claim_no_expectation_against_a_wheel_the_user_gave():
    """Against a wheel file (`--params`) the verdicts are counted, never called expected; an SYNTHETIC_er trial
    that does not agree with Table 1 is called a fault (it was made there)."""
    from types import SimpleNamespace

    from rimless.analysis.report.sections import TrialSection

    def section(name: str, series: str, status: str | None) -> TrialSection:
        comp = None if status is None else SimpleNamespace(status=status)
        return TrialSection(name, name, series, None, comparison=comp)

    sections = [
        section("e1", "SYNTHETIC_er", "ok"),
        section("e2", "SYNTHETIC_er", "suspect"),
        section("c1", "SYNTHETIC_crit", "suspect"),
        section("c2", "SYNTHETIC_crit", None),
    ]
    c = {"name": "damping_ns_per_m", "value": 8.0, "source": "table1"}
    table1 = SimpleNamespace(sections=sections, parameters=[c], calibration=None)
    er, crit = batch.demo_verdicts(table1)  # type: ignore[arg-type]
    assert (er["ok"], er["suspect"], er["not_compared"]) == (1, 1, 0) and "a fault to report" in er["meaning"]
    assert (crit["ok"], crit["suspect"], crit["not_compared"]) == (0, 1, 1) and "Expected" in crit["meaning"]
    given = SimpleNamespace(
        sections=sections, parameters=[c | {"value": 13.0, "source": "wheel_file"}], calibration=None
    )
    for v in batch.demo_verdicts(given):  # type: ignore[arg-type]
        assert "against the wheel given (--params)" in v["meaning"]
        assert "Expected" not in v["meaning"] and "as they should" not in v["meaning"] and "fault" not in v["meaning"]
