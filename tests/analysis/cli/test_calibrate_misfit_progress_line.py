"""The misfit statement on `rimless trials calibrate`'s progress line, end to end (issue 31; session 21 tested
`SimulationBudget.on_stage` alone). Trials the model cannot fit: walks of the independent compliant truth
(`tests.support.analysis_trial_truth`, c 12 N s/m, k 2200 N/m) written as Vicon exports and imported, then their
impacts moved so the step periods alternate short and long (as in `test_calibrate_misfit_start.py`), are written
as trial files (`Trial.to_parquet`) and calibrated by the command in a
subprocess with `--json`, stderr a pipe and `RIMLESS_PROGRESS_EVERY_S=0` (a plain progress line at every update,
`rimless.progress`). The test reads the finished stderr line by line: no timing, no clock."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import tests.support.analysis_trial_truth as tt


def _limping(trial, factors=(0.6, 1.4)):
    """The imported trial with its impacts moved so that its step periods alternate short and long (a limp the
    model cannot walk); as many impacts as before, so the import's step numbering still holds."""
    from rimless.analysis.io.timeseries import Event
    from rimless.analysis.io.trial import Trial

    t = trial.impact_time_s
    p = np.diff(t) * np.resize(np.array(factors), t.size - 1)
    moved = t[0] + np.concatenate([[0.0], np.cumsum(p)])
    events = tuple(e for e in trial.series.events if e.name != "impact") + tuple(
        Event(float(x), "impact") for x in moved
    )
    return Trial(replace(trial.series, events=events), trial.meta)


@pytest.mark.slow
def test_the_command_progress_line_carries_the_misfit_statement(tmp_path):
    from rimless.analysis.kinematics.build import import_trial

    files = []
    for i, (s, w) in enumerate(((1.8, 1.9), (2.4, 2.4))):
        truth = tt.simulate_wheel(s, w, c_ns_per_m=12.0, k_n_per_m=2200.0, max_steps=9, ending="walked", seed=i)
        trial = import_trial(tt.write_csv(tmp_path / f"er_{s}.csv", truth), slope_deg=s)
        assert trial.impact_time_s.size >= 5
        files.append(str(_limping(trial).to_parquet(tmp_path / f"limp_{s}.trial.parquet")))
    env = {**os.environ, "RIMLESS_PROGRESS_EVERY_S": "0", "COLUMNS": "200"}
    env.pop("RIMLESS_TEST_STAGE_FILE", None)
    cmd = [sys.executable, "-m", "rimless", "trials", "calibrate", *files, "--json", "--no-critical"]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout)  # stdout stays the result
    m = out["optimizer"]["misfit"]
    assert m is not None and m["stage"] == "start"
    brief = (
        f"[the model does not fit: step frequencies miss by {m['frequency_miss_rms']:.0%} RMS "
        f"(limit {m['limit']:.0%}); effective only, search capped at {out['budget']['search_cap']} simulations]"
    )
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("rimless: calibrating")]
    assert lines, res.stderr[-2000:]
    with_brief = [i for i, ln in enumerate(lines) if brief in ln]
    assert with_brief, (brief, lines[-5:])
    # from its first showing on, every calibrating line says it; none before
    first = with_brief[0]
    assert all(brief in ln for ln in lines[first:]) and not any("does not fit" in ln for ln in lines[:first])
    assert lines[first].startswith("rimless: calibrating: start")  # stated at the start, before the least squares
    assert any("least squares" in ln for ln in lines[first:])
    assert all(not p["identifiable"] for p in out["params"])
