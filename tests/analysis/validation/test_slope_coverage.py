"""`rimless trials slope-coverage`: the importer's slope interval against the rigid and ER truths, per evidence and
lab. The machinery checked on a small run (every row recomputed from the draws), and the intervals' honesty on a
fixed set of draws (the figures of the long run are in docs/trials.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.validation.slope_coverage import KINDS, Z95, draw_trial, run_slope_coverage
from rimless.cli import app

runner = CliRunner()


def test_draws_are_walks_away_from_table1_in_every_kind_of_lab() -> None:
    labs, hidden, er_k = set(), 0, []
    for i in range(12):
        for truth in ("rigid", "er"):
            # the simulator's ER walks (fast): the draws are the same under er_truth (the walks draw alike)
            d = draw_trial(np.random.default_rng([7, 0 if truth == "rigid" else 1, i]), truth, truth_model="simulator")
            assert d.walk.impacts.size >= 4 and d.walk.slope_deg > 0.2
            labs.add((d.lab.up, d.lab.markers))
            hidden += bool(d.gaps)
            if truth == "er":
                er_k.append(d.wheel["k_n_per_m"])
                assert 0.8 <= d.wheel["release_factor"] <= 1.4
            else:
                assert 0.3 <= d.wheel["inertia_ratio"] <= 3.0
    assert labs == {("z", False), ("z", True), ("y", False), ("y", True)}
    assert 0 < hidden < 24 and min(er_k) >= 1500 and max(er_k) <= 4000 and np.ptp(er_k) > 1000


def test_cli_small_run_counts_what_its_draws_say() -> None:
    args = ["trials", "slope-coverage", "--series", "2", "--seed", "3", "--json", "--truth-model", "simulator"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["truth"] == "simulator" and "er: the simulator's ER wheel" in out["truth_model"]
    assert out["draws"] == 4 and out["refused"] == 0 and len(out["per_draw"]) == 4
    assert [d["truth"] for d in out["per_draw"]] == ["rigid", "er", "rigid", "er"]
    for d in out["per_draw"]:
        assert d["used"] is not None and d["evidence"]
        for row in d["evidence"]:  # an evidence's interval is symmetric about its slope
            assert row["error_deg"] == pytest.approx(row["slope_deg"] - d["slope_deg"], abs=1e-9)
            assert row["covered"] == (abs(row["error_deg"]) <= row["half_width_deg"])
            assert row["z"] == pytest.approx(row["error_deg"] / (row["half_width_deg"] / Z95))
    for truth in ("rigid", "er"):
        mine = [d for d in out["per_draw"] if d["truth"] == truth]
        used = out["truths"][truth]["evidence"]["used"]
        assert used["n"] == 2 and used["covered"] == sum(d["used"]["covered"] for d in mine)
        z = [d["used"]["z"] for d in mine]
        assert used["rms_z"] == pytest.approx(math.sqrt(np.mean(np.square(z))))
        assert used["median_abs_error_deg"] == pytest.approx(np.median([abs(d["used"]["error_deg"]) for d in mine]))
        labs = out["truths"][truth]["labs"]
        assert labs["hidden stances"]["n"] + labs["all stances seen"]["n"] == 2
        lo, hi = used["coverage_ci95"]
        assert 0 <= lo <= used["coverage"] <= hi <= 1
    assert set(out["truths"]["rigid"]["evidence"]) == set(KINDS)
    for d in out["per_draw"]:  # imported again, told the wheel: rigid legs carry no drift, compliant ones do
        told = d["wheel_given"]
        assert told["used"] is not None and sorted(r["kind"] for r in told["evidence"]) == sorted(
            r["kind"] for r in d["evidence"]
        )  # (the same estimates; their order, narrowest first, may differ)
        for row in told["evidence"]:
            assert ("impact speed change" if d["truth"] == "rigid" else "rigid legs") not in row["method"]
    given = out["wheel_given"]["truths"]["er"]["evidence"]["used"]
    assert given["n"] == 2 and given["covered"] == sum(
        d["wheel_given"]["used"]["covered"] for d in out["per_draw"][1::2]
    )
    table = runner.invoke(app, ["trials", "slope-coverage", "--series", "1", "--truth-model", "simulator"])
    assert table.exit_code == 0 and "slope used" in table.stdout and "hidden stances" in table.stdout
    assert max(len(line) for line in table.stdout.splitlines()) <= 80


def test_the_er_truth_is_er_truths_walk_by_default_and_draws_as_the_simulators() -> None:
    """One series from the command line with no --truth-model: the ER walk is er_truth's (named in the JSON and
    per draw), on the same drawn wheel, slope and release as the simulator's walk of that draw (the two walkers
    draw alike), and its impacts meet the simulator's walk's to 1e-6 s (the step-map test's agreement)."""
    from rimless.analysis.validation.slope_coverage import TRUTHS, draw_trial

    r = runner.invoke(app, ["trials", "slope-coverage", "--series", "1", "--seed", "3", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["truth"] == "independent" and "er: er_truth" in out["truth_model"]
    er = [d for d in out["per_draw"] if d["truth"] == "er"]
    assert len(er) == 1 and er[0]["truth_model"] == "independent"
    sim = draw_trial(np.random.default_rng([3, TRUTHS.index("er"), 0]), "er", truth_model="simulator")
    assert er[0]["wheel"] == sim.wheel and er[0]["slope_deg"] == sim.walk.slope_deg
    assert er[0]["impacts"] == sim.walk.impacts.size


def test_a_bad_er_truth_model_is_one_error_line() -> None:
    r = runner.invoke(app, ["trials", "slope-coverage", "--truth-model", "exact"])
    assert r.exit_code == 2
    assert [ln for ln in r.output.splitlines() if ln.strip()] == [
        "error: --truth-model must be independent or simulator, got 'exact'"
    ], r.output


@pytest.mark.slow
def test_rigid_walks_with_hidden_stances_are_covered_and_z_is_near_one() -> None:
    """40 rigid walks (seed 0). Before the hub's standard error was carried (4411fb4), two walks with most stances
    hidden missed by 0.22 and 0.24 deg (z -8.7 and +3.9: the line through six impacts read the turning hub error
    as slope) and the hidden-stance walks' rms z was 2.8; the contact line's rms z was 0.40 (its stated errors
    were the spread within a stance, not the error of its median)."""
    res = run_slope_coverage(40, 0, truths=("rigid",))
    # told the wheel is rigid (no leg drift): not told, the importer bounds a compliant leg's drift and over-covers
    used = res.rows("used", wheel_given=True)
    assert len(used) == 40 and sum(r["covered"] for r in used) >= 38
    hidden = res.rows("used", wheel_given=True, hidden=True)
    assert len(hidden) >= 8
    assert all(abs(r["z"]) < 2.5 for r in hidden)
    rms = math.sqrt(np.mean([r["z"] ** 2 for r in hidden]))
    assert 0.5 <= rms <= 1.5
    contacts = [r["z"] for r in res.rows("contacts", wheel_given=True)]
    assert len(contacts) >= 30 and 0.5 <= math.sqrt(np.mean(np.square(contacts))) <= 1.5
