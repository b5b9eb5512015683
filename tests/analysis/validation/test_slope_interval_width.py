"""The importer's slope interval on a compliant wheel it is told about is as wide as its error (issue 31).

Truth: the simulator's ER wheel (`floquet_truth.er_walk`: k 1500-4000 N/m, c 2-20 N s/m, 1.3-3 deg, released at
0.8-1.4 times its gait's speed, 11 impacts), recorded as a Vicon export in drawn labs (Z-up or Y-up, any
heading, a Tracker object or four markers, 0.3 mm and 1 mrad of noise, the middle of most stances hidden in
some) by the slope-coverage study's own writer, and imported told the wheel (its k with Table 1's stated 10 %).
Neither the walk nor the recording uses the importer's code. The 30 walks are the study's first (`rimless trials
slope-coverage --series 40 --seed 0`, its ``wheel_given`` block for the ER truth).

On today's main (31eb6f0) these walks give the contact line rms z 0.66 (21 walks), the impact line 0.80 (28),
pooled 0.75, and the slope used 0.72 with every interval holding the truth (after: 0.85, 0.88, 0.87; 0.82 with
28 of 30 held): the contact line's stated errors
were scaled down by at most half (their scatter says 2-20 times in variance), and the legs' drift was sized on
k's 95 % low end, the contacts' as far as the minima's. An honest interval has rms z near 1 (0.98 with Student t
on nine degrees of freedom); the measured figures after, and on the other truths, are in docs/trials.md.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.validation.slope_coverage import TRUTHS, Z95, captured_evidence, draw_trial, record, told_wheel

#: the slope-coverage study's first ER walks (seed 0): the same draws and recordings as
#: ``rimless trials slope-coverage --series 30 --seed 0`` (its ``wheel_given`` block)
WALKS = 30
SEED = 0


@pytest.fixture(scope="module")
def z_scores(tmp_path_factory) -> dict[str, list[float]]:
    from rimless.analysis.kinematics.build import import_trial

    folder: Path = tmp_path_factory.mktemp("er_slope")
    out: dict[str, list[float]] = {"contacts": [], "impact line": [], "used": [], "held": []}
    for i in range(WALKS):
        rng = np.random.default_rng([SEED, TRUTHS.index("er"), i])
        draw = draw_trial(rng, "er", truth_model="simulator")  # this file's truth: the simulator's walks
        truth = math.radians(draw.walk.slope_deg)
        path = folder / f"er{i}.csv"
        record(draw, path, rng)
        with captured_evidence() as seen:
            trial = import_trial(path, wheel=told_wheel(draw))
        for e in seen["evidence"]:
            if e.source == "estimated" and e.kind in ("contacts", "impact line"):
                out[e.kind].append((e.slope_rad - truth) / (e.half_rad / Z95))
        lo, hi = trial.meta.slope_ci_rad
        out["used"].append((math.radians(trial.meta.slope_deg) - truth) / ((hi - lo) / 2 / Z95))
        out["held"].append(float(lo <= truth <= hi))
    return out


def _rms(z: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(z))))


def test_the_walks_are_compliant_and_show_both_lines(z_scores) -> None:
    assert len(z_scores["used"]) == WALKS
    assert len(z_scores["contacts"]) >= 10 and len(z_scores["impact line"]) >= 20


def test_slope_z_scores_are_near_one_not_half(z_scores) -> None:
    """Pooled over the contact and impact lines' estimates, rms z 0.82-1.25 (today's main: 0.75); the slope used
    holds the truth in 90 % of the walks or more with rms z 0.78-1.25 (today's main: 0.72). (With 30 walks the
    rms z of an honest interval scatters by about 0.1: the bounds guard against much too wide or too narrow.)"""
    pooled = z_scores["contacts"] + z_scores["impact line"]
    assert 0.82 <= _rms(pooled) <= 1.25, (_rms(z_scores["contacts"]), _rms(z_scores["impact line"]))
    assert 0.78 <= _rms(z_scores["used"]) <= 1.25
    assert np.mean(z_scores["held"]) >= 0.9
