"""`rimless trials floquet-coverage --truth-model`: the ER truth walked by er_truth (written apart from the
simulator, the default) or by the simulator; the truth and its multiplier named in the JSON. Small runs: the
machinery and the wiring (the coverage figures of the long runs are in docs/trials.md)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from rimless.analysis.validation import floquet_coverage as fc
from rimless.cli import app

runner = CliRunner()


def test_a_bad_truth_model_is_one_error_line() -> None:
    r = runner.invoke(app, ["trials", "floquet-coverage", "--kind", "er", "--truth-model", "sim"])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert lines == ["error: --truth-model must be independent or simulator, got 'sim'"], r.output


def test_the_cli_walks_the_er_truth_with_er_truth_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    """One series of two trials of 6 impacts from the command line: every walk is `er_truth.er_truth_walk`'s
    (counted), none the simulator's; the JSON names the truth and its multiplier is er_truth's own."""
    from rimless.analysis.validation import er_truth

    calls = {"er_truth": 0, "simulator": 0}
    truth_walk, sim_walk = er_truth.er_truth_walk, fc.er_walk

    def counted(name, f):
        def g(*a, **k):
            calls[name] += 1
            return f(*a, **k)

        return g

    monkeypatch.setattr(er_truth, "er_truth_walk", counted("er_truth", truth_walk))
    monkeypatch.setattr(fc, "er_walk", counted("simulator", sim_walk))
    args = ["trials", "floquet-coverage", "--kind", "er", "--series", "1", "--trials", "2", "--steps", "6"]
    r = runner.invoke(app, [*args, "--seed", "4", "--json"])
    assert r.exit_code in (0, 1), r.output  # 1: no estimate from so short a series (valid input, no result)
    out = json.loads(r.stdout)
    assert out["truth"] == "independent" and out["truth_model"].startswith("er_truth")
    assert calls == {"er_truth": 2, "simulator": 0}
    # er_truth.multiplier at k 2000, c 14, 2.5 deg: 0.7380677656 (regression snapshot of this tree's er_truth,
    # commit b89fb52); the simulator's eigenvalue there is 0.7380677652 (test_er_truth.py holds the two to 1e-6)
    assert out["truth_multiplier"] == pytest.approx(0.7380677656, abs=1e-9)
    assert set(out["corrected"]) >= {"covered", "of", "coverage", "coverage_ci95"}


def test_the_simulator_truth_is_still_there_and_counts_honestly() -> None:
    """``truth="simulator"``: the model's eigenvalue as the truth, as before (docs/trials.md's 0.738; er_truth's
    own multiplier, an independent source, is 0.73806777: test_er_truth.py); the Wilson interval from the counts;
    a bad truth model refused."""
    from rimless.analysis.validation.coverage import wilson_interval

    out = fc.run("er", 2, 3, 12, 0.6, 4, truth="simulator")
    assert out["truth"] == "simulator" and out["truth_model"].startswith("the simulator's ER wheel")
    assert out["truth_multiplier"] == pytest.approx(0.73806777, abs=1e-6)
    for name in ("corrected", "ols"):
        d = out[name]
        if d["of"]:
            assert d["coverage_wilson95"] == pytest.approx(list(wilson_interval(d["covered"], d["of"])))
            assert d["rms_z"] > 0
    with pytest.raises(ValueError, match="truth must be one of independent, simulator"):
        fc.run("er", 1, 1, 6, 0.6, 4, truth="sim")
