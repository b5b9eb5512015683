"""Any lab (issue 31): a recording in a Y-up lab with any ramp heading, a 4-marker recording, refusals that name
the option that would import. Expected values come from the independent truth model
(`tests.support.analysis_trial_truth`, a compliant ER wheel), never from the code under test."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.kinematics.build import TrialRefused, import_trial
from tests.support.analysis_trial_truth import Y_UP_FROM_Z_UP, in_lab, simulate, write_csv, write_markers_csv
from tests.support.analysis_truth_wheel import UNEVEN_MARKERS, markers_section, write

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def walk():
    """11 steps down a 2 deg ramp heading 30 deg off the lab's X axis (truth: walks all 11)."""
    tr = simulate(2.0, 2.5, max_steps=11, ending="walked", seed=3, yaw_deg=30.0)
    assert tr.steps == 11 and not tr.stalled
    return tr


def _check(trial, tr, *, frames: float = 1.0):
    m = trial.meta
    lo, hi = (math.degrees(v) for v in m.slope_ci_rad)
    assert abs(m.slope_deg - tr.slope_deg) <= 0.1 or lo <= tr.slope_deg <= hi, (m.slope_deg, lo, hi)
    assert m.outcome == "walked"
    assert trial.impact_time_s.size == tr.steps
    err = trial.impact_time_s - tr.impact_time_s
    assert np.max(np.abs(err)) <= frames / m.rate_hz, err


@pytest.mark.parametrize("kind", ["object", "markers"])
@pytest.mark.parametrize("given", [None, "y"])
def test_y_up_lab_with_a_ramp_heading_imports_all_steps(walk, tmp_path, kind, given):
    lab = in_lab(walk, Y_UP_FROM_Z_UP)
    p = (
        write_csv(tmp_path / "y.csv", lab)
        if kind == "object"
        else write_markers_csv(tmp_path / "y.csv", lab, UNEVEN_MARKERS)
    )
    trial = import_trial(p, up_axis=given)
    assert trial.meta.up_axis == "y"
    _check(trial, walk, frames=1.0)


def test_y_up_lab_forced_z_up_is_refused(walk, tmp_path):
    """Forcing the wrong vertical gives no silent nonsense: the walk read Z up is refused."""
    lab = in_lab(walk, Y_UP_FROM_Z_UP)
    p = write_csv(tmp_path / "y.csv", lab)
    with pytest.raises(TrialRefused):
        import_trial(p, up_axis="z")


def test_z_up_recording_still_finds_z(walk, tmp_path):
    trial = import_trial(write_csv(tmp_path / "z.csv", walk))
    assert trial.meta.up_axis == "z"
    _check(trial, walk)


def test_undecidable_vertical_names_up_axis(walk, tmp_path):
    """One marker (no rotation) whose path runs along world Z: Z cannot be the vertical and nothing says which
    axis is; the refusal names --up-axis."""
    lab = in_lab(walk, Y_UP_FROM_Z_UP)  # heading 30 deg from X: the path rises 30 deg along the lab's Z
    hub = lab.hub_world.copy()
    hub[np.isnan(lab.pose).any(axis=1)] = np.nan
    p = write(tmp_path / "one.csv", markers_section({"wheel:Hub": hub}))
    with pytest.raises(TrialRefused, match="--up-axis"):
        import_trial(p)


def test_unlabelled_wheel_markers_refusal_names_markers(walk, tmp_path):
    pts = walk.hub_world[:, None, :] + np.einsum("nij,kj->nki", walk.rot.as_matrix(), UNEVEN_MARKERS)
    p = write(tmp_path / "u.csv", markers_section({f"*{i}": pts[:, i] for i in range(4)}))
    with pytest.raises(TrialRefused, match=r"--markers \*0,\*1,\*2,\*3"):
        import_trial(p)
    trial = import_trial(p, markers=["*0", "*1", "*2", "*3"])  # and the option it names imports it
    assert trial.impact_time_s.size == walk.steps


def test_json_refusal_prints_error_line(walk, tmp_path):
    from rimless.cli import app

    pts = walk.hub_world[:, None, :] + np.einsum("nij,kj->nki", walk.rot.as_matrix(), UNEVEN_MARKERS)
    p = write(tmp_path / "u.csv", markers_section({f"*{i}": pts[:, i] for i in range(4)}))
    res = CliRunner().invoke(app, ["trials", "import", p, "--out", str(tmp_path), "--json"])
    assert res.exit_code == 2
    rows = json.loads(res.stdout)
    assert rows[0]["status"] == "refused" and "--markers" in rows[0]["reason"]
    assert any(line.startswith("error: ") and "--markers" in line for line in res.stderr.splitlines())


def test_up_axis_option_on_import(walk, tmp_path):
    from rimless.cli import app

    p = write_csv(tmp_path / "y.csv", in_lab(walk, Y_UP_FROM_Z_UP))
    res = CliRunner().invoke(app, ["trials", "import", p, "--out", str(tmp_path), "--json", "--up-axis", "y"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)[0]
    assert row["up_axis"] == "y" and abs(row["slope_deg"] - 2.0) <= 0.1 and len(row["impact_times_s"]) == 11
    res = CliRunner().invoke(app, ["trials", "import", p, "--out", str(tmp_path), "--up-axis", "w"])
    assert res.exit_code == 2 and "--up-axis" in res.output


@pytest.mark.parametrize(
    "command", [["critical-slope"], ["floquet"], ["calibrate", "--no-critical", "--max-simulations", "1"]]
)
def test_every_importing_command_takes_the_markers_its_refusal_names(walk, tmp_path, command):
    """The refusal of unlabelled markers names ``--markers``: each command that imports raw files takes it (the
    audit of session 21 found `critical-slope`, `calibrate` and `floquet` answering "no such option")."""
    from rimless.cli import app

    pts = walk.hub_world[:, None, :] + np.einsum("nij,kj->nki", walk.rot.as_matrix(), UNEVEN_MARKERS)
    p = write(tmp_path / "u.csv", markers_section({f"*{i}": pts[:, i] for i in range(4)}))
    runner = CliRunner()
    refused = runner.invoke(app, ["trials", *command, p])
    assert refused.exit_code == 2 and "--markers *0,*1,*2,*3" in refused.stderr
    res = runner.invoke(app, ["trials", *command, p, "--markers", "*0,*1,*2,*3"])
    assert "no such option" not in res.stderr and "u.csv:" not in res.stderr, res.stderr
    assert res.exit_code in (0, 1), res.stderr  # imported; a single trial may give no estimate (exit 1)
    assert "Traceback" not in res.output
