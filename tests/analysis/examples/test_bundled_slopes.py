"""The bundled SYNTHETIC recordings: each trial's slope within 0.1 deg of its file's nominal slope (the truth
files written by the generators), its interval around it, and the endings the truth files state."""

from __future__ import annotations

import math
import tomllib

import pytest

from rimless.analysis.examples.bundled import data_files
from rimless.analysis.examples.critical_series import DATA_DIR as CRIT_DIR
from rimless.analysis.examples.critical_series import data_files as crit_files
from rimless.analysis.kinematics.build import import_trial

BUNDLED_TRUTH = data_files()[0].parent / "SYNTHETIC_truth.toml"


def _nominal(path) -> float:  # the slope in the file's name, deg
    name = path.name
    return float(name.split("slope")[1].split("deg")[0])


@pytest.mark.parametrize("path", data_files() + crit_files(), ids=lambda p: p.name)
def test_slope_within_0p1_deg_of_nominal(path):
    m = import_trial(path).meta
    assert abs(m.slope_deg - _nominal(path)) <= 0.1, (m.slope_deg, m.slope_source, m.slope_method)
    lo, hi = (math.degrees(v) for v in m.slope_ci_rad)
    assert lo <= m.slope_deg <= hi
    assert m.slope_source in ("ramp", "estimated")


@pytest.mark.parametrize("path", crit_files(), ids=lambda p: p.name)
def test_critical_series_endings_match_the_truth(path):
    with open(CRIT_DIR / "SYNTHETIC_crit_truth.toml", "rb") as f:
        truth = tomllib.load(f)["trials"][path.stem]
    m = import_trial(path).meta
    assert m.outcome == truth["outcome"], m.outcome_reason  # recordings that stop while walking are "walked"


def test_the_ramp_trial_takes_the_ramp_slope():
    path = next(p for p in data_files() if "2.5deg_run1" in p.name)
    m = import_trial(path).meta
    assert m.slope_source == "ramp" and m.slope_deg == pytest.approx(m.ramp_slope_deg)
    assert m.slope_estimated_deg is not None and abs(m.slope_estimated_deg - 2.5) <= 0.1


def test_the_short_trials_of_the_issue_are_fixed():
    """Before: 1.45 deg read -8.48 deg and 1.30 deg read 7.08 deg (the hub offset ran away on two steps)."""
    for name, slope in (
        ("SYNTHETIC_crit_slope1.45deg_release1.9.csv", 1.45),
        ("SYNTHETIC_crit_slope1.30deg_release1.9.csv", 1.30),
    ):
        m = import_trial(CRIT_DIR / name).meta
        assert abs(m.slope_deg - slope) <= 0.1
        assert m.outcome == "stalled"
