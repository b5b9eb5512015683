"""A leg fit that knows its limits (issue 31), against the independent truth model of the leg
(tests/support/leg_truth.py: event-located integration, never the fit's closed form):

- one release whose motion nearly sticks after its second half cycle: the segmentation (half cycles before
  the stick) is chosen by the data and the intervals span the ones it allows; the output says what one release
  cannot do;
- a log read too slowly (800 reads a second, about 10 in a half cycle) is refused, never a number;
- `trials calibrate --prior` refuses a leg fit that failed its checks;
- a leg without friction gets an upper bound of F_c, never a relative precision of about zero;
- `trials leg-fit-coverage` tells the fit the leg mass as a user knows it, never the truth's.
"""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rimless.errors import InputFileError
from tests.support.leg_truth import LegTruth, write_log

ROOT = Path(__file__).resolve().parents[3]
# a leg (not Table 1's) whose one release from 2 mm sticks after two half cycles at 0.9 of the friction band's
# edge: a third half cycle of a fraction of a count is nearly as good a fit. Seed found by a seeded study of
# one-release truths (k 2000-3500 N/m, c 3-10 N s/m, F_c 0-0.5 N): the fit before model selection took three
# half cycles there and missed c (+2.8 %) and F_c (-7 %) while saying "precision goal met with 1 release".
NEAR_STICK = LegTruth(k_n_per_m=3000.0, c_n_s_per_m=5.1, friction_n=0.437)
NEAR_STICK_SEED = 199408321


def _cli(*args: str, cwd: Path, command: str = "leg-fit") -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "rimless", "trials", command, *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "COLUMNS": "200"},
    )


def _error_line(res: subprocess.CompletedProcess[str]) -> str:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert "Traceback" not in res.stderr
    return lines[0]


@pytest.mark.slow
def test_one_release_near_a_stick_covers_and_says_what_one_release_cannot(tmp_path: Path) -> None:
    write_log(tmp_path / "one.jsonl", NEAR_STICK, compression_m=2e-3, seed=NEAR_STICK_SEED)
    res = _cli("one.jsonl", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    for key, true in (("k_n_per_m", 3000.0), ("c_n_s_per_m", 5.1), ("guide_friction_n", 0.437)):
        lo, hi = out[key + "_ci"]
        assert lo <= true <= hi, (key, out[key], out[key + "_ci"])
    seg = out["segmentation"]
    assert [c["half_cycles"] for c in seg["candidates"] if c["plausible"]] and len(seg["candidates"]) >= 2
    assert all(c["delta_chi2"] >= 0 for c in seg["candidates"])
    assert "one release" in out["one_release"]
    assert not out["goal"]["met"]  # intervals that span both segmentations do not reach 2 % on c
    text = _cli("one.jsonl", cwd=tmp_path)
    assert text.returncode == 0, text.stderr
    assert "half cycles chosen by the data" in text.stdout and "one release:" in text.stdout
    assert "met with 1 release" not in text.stdout, text.stdout


@pytest.mark.slow
def test_one_release_intervals_cover_over_seeded_truths() -> None:
    """Six seeded one-release leg tests of random legs (and masses, told as weighed): every interval of k, c
    and F_c holds its truth but at most one of the 18 (a nominal 95 % misses none in six with probability
    0.74 per parameter, at most one of 18 with probability 0.77; the large-N figure is in docs/trials.md)."""
    from rimless.analysis.validation.leg_fit_coverage import run_leg_fit_coverage

    out = run_leg_fit_coverage(6, releases=1, seed=11).summary()
    per = out["per_parameter"]
    assert out["fitted"] + out["failures"] == 6 and out["fitted"] >= 5
    missed = sum(d["fitted"] - d["covered"] for d in per.values())
    assert missed <= 1, per


@pytest.mark.slow
def test_a_log_read_too_slowly_is_refused(tmp_path: Path) -> None:
    """800 reads a second: about 10 in a half cycle of the paper's leg (12.8 ms). Refused, exit 1, one line
    naming the samples per half cycle and the sample rate; never a number."""
    names = []
    for s, mm in enumerate((1.5, 2.0, 2.5)):
        write_log(tmp_path / f"slow{s}.jsonl", LegTruth(rate_hz=800.0), compression_m=mm / 1e3, seed=s)
        names.append(f"slow{s}.jsonl")
    res = _cli(*names, "--json", cwd=tmp_path)
    assert res.returncode == 1, res.stdout + res.stderr
    assert res.stdout == ""
    line = _error_line(res)
    assert "samples per half cycle" in line and "sample rate cannot resolve the leg" in line, line
    assert "slow" in line and ".jsonl" in line


def _fit_json(tmp_path: Path) -> dict:
    truth = LegTruth()
    for s in (0, 1, 2):
        write_log(tmp_path / f"l{s}.jsonl", truth, compression_m=(1.5 + 0.5 * s) / 1e3, seed=s)
    res = _cli("l0.jsonl", "l1.jsonl", "l2.jsonl", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


@pytest.mark.slow
def test_prior_refuses_a_leg_fit_that_failed_its_checks(tmp_path: Path) -> None:
    from rimless.analysis.inference.priors import read_priors

    good = _fit_json(tmp_path)
    assert good["checks"]["passed"] is True
    (tmp_path / "good.json").write_text(json.dumps(good))
    assert {p.key for p in read_priors(tmp_path / "good.json").priors} == {
        "k_n_per_m",
        "c_n_s_per_m",
        "guide_friction_n",
    }
    failed = {**good, "converged": False}
    failed["checks"] = {**good["checks"], "converged": {"passed": False, "found": "max_nfev"}, "passed": False}
    (tmp_path / "failed.json").write_text(json.dumps(failed))
    with pytest.raises(InputFileError, match=r"failed.json: the leg fit failed its check\(s\) converged"):
        read_priors(tmp_path / "failed.json")
    # what the chain printed for a starved log before the refusal: k = 1.6e6 N/m, its interval below zero
    starved = {**good, "k_n_per_m": 1.6e6, "k_n_per_m_ci": [-2.0e6, 5.2e6]}
    starved.pop("checks")
    (tmp_path / "starved.json").write_text(json.dumps(starved))
    with pytest.raises(InputFileError, match="starved.json: the leg fit failed its check 'intervals_positive'"):
        read_priors(tmp_path / "starved.json")
    # through the command: one line naming the file and the check, exit 2, before any walk is simulated
    res = _cli(
        str(ROOT / "analysis/data/SYNTHETIC_er_slope2.0deg_run1.csv"),
        "--fit",
        "c,k",
        "--prior",
        "failed.json",
        "--no-critical",
        cwd=tmp_path,
        command="calibrate",
    )
    assert res.returncode == 2, res.stdout + res.stderr
    line = _error_line(res)
    assert "failed.json" in line and "converged" in line, line


@pytest.mark.slow
def test_no_friction_gets_an_upper_bound_not_a_percentage(tmp_path: Path) -> None:
    truth = LegTruth(friction_n=0.0)
    for s in (0, 1, 2):
        write_log(tmp_path / f"z{s}.jsonl", truth, compression_m=(1.5 + 0.5 * s) / 1e3, seed=s)
    res = _cli("z0.jsonl", "z1.jsonl", "z2.jsonl", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["friction_resolved"] is False
    assert 0.0 < out["guide_friction_n_upper_95"] < 0.05  # N: a bound near zero
    fc = out["goal"]["per_parameter"]["guide_friction_n"]
    assert fc["rel_half_width"] is None and fc["consistent_with_zero"] and fc["met"] is None
    for key, true in (("k_n_per_m", 2700.0), ("c_n_s_per_m", 8.0)):
        lo, hi = out[key + "_ci"]
        assert lo <= true <= hi, (key, out[key + "_ci"])
    text = _cli("z0.jsonl", "z1.jsonl", "z2.jsonl", cwd=tmp_path)
    assert text.returncode == 0, text.stderr
    line = next(ln for ln in text.stdout.splitlines() if ln.startswith("F_c"))
    assert line.startswith("F_c < ") and "upper bound" in line, line
    goal = next(ln for ln in text.stdout.splitlines() if "precision goal" in ln)
    assert "F_c consistent with zero (< " in goal and "F_c ±" not in goal, goal
    assert not re.search(r"\de\+\d|\binf\b|\bnan\b", text.stdout, re.IGNORECASE), text.stdout


def test_coverage_never_hands_the_fit_the_true_leg_mass(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fit is told a stated mass with its uncertainty, never the mass the truth model simulated."""
    from rimless.analysis.validation import leg_fit_coverage as cov
    from rimless.errors import RunFailure

    simulated: list[float] = []
    told: list[tuple[float, float]] = []
    real_write = cov.write_log

    def write(path: Path, truth: LegTruth, **kw: object) -> dict:
        simulated.append(truth.mass_kg)
        return real_write(path, truth, **kw)

    def fit(logs: list, *, moving_mass_kg: float = -1.0, moving_mass_sd_kg: float = 0.0) -> None:
        told.append((moving_mass_kg, moving_mass_sd_kg))
        raise RunFailure("not fitted in this test")

    monkeypatch.setattr(cov, "write_log", write)
    monkeypatch.setattr(cov, "fit_leg", fit)
    out = cov.run_leg_fit_coverage(3, releases=1, seed=2).summary()
    assert out["failures"] == 3 and len(told) == 3 and len(simulated) == 3
    for m_true, (m_told, sd) in zip(simulated, told):
        assert m_told != m_true and sd > 0
        assert abs(m_told - m_true) < 5 * sd  # a weighing, not a guess
    assert len(set(simulated)) == 3  # the mass is drawn, not Table 1's every time
    assert "stated_moving_mass" in out["truth_model"]


def test_truth_model_shares_no_code_with_the_fit() -> None:
    """leg_truth imports neither the fit nor the firmware's fake leg (written apart from both)."""
    tree = ast.parse((ROOT / "analysis/validation/leg_truth.py").read_text())
    imported = {
        node.module if isinstance(node, ast.ImportFrom) else alias.name
        for node in ast.walk(tree)
        if isinstance(node, (ast.Import, ast.ImportFrom))
        for alias in node.names
    }
    assert not {m for m in imported if m and ("leg_fit" in m or "fake_leg" in m or m.startswith("rimless"))}
