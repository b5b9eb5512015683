"""The truth model of the critical-slope coverage (`rimless.analysis.validation.critical_truth`) against checks
written apart from it: Coleman's closed form for the rigid wheel (tests/support/analysis_rigid_truth.py, scipy's
solve_ivp and its own bisection), energy conservation over a stance, long walks on either side of the critical
slope; and its recordings through the importer in every lab it draws."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.validation.critical_truth import GUIDE_TRAVEL_M, Lab, LossyWheel, record, walk
from tests.support.analysis_rigid_truth import RigidTruth

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize("ratio", [0.3, 0.43, 1.0, 3.0])
def test_without_loss_the_critical_slope_is_colemans(ratio: float) -> None:
    mass, leg = 2.4, 0.23
    wheel = LossyWheel(mass_kg=mass, inertia_hub_kg_m2=ratio * mass * leg**2, leg_m=leg)
    coleman = RigidTruth(mass_kg=mass, inertia_hub_kg_m2=ratio * mass * leg**2, leg_m=leg).critical_slope_deg()
    assert wheel.critical_slope_deg() == pytest.approx(coleman, abs=1e-9)
    assert wheel.inertia_ratio == pytest.approx(ratio)


def test_friction_loss_raises_the_critical_slope_and_the_walks_agree() -> None:
    """The bisection is on the map; long walks integrated stance by stance must sustain just above it and
    stall just below it (released at the gait's speed)."""
    wheel = LossyWheel(mass_kg=2.0, inertia_hub_kg_m2=0.1, leg_m=0.24, friction_n=0.5)
    frictionless = LossyWheel(mass_kg=2.0, inertia_hub_kg_m2=0.1, leg_m=0.24)
    crit = wheel.critical_slope_deg()
    assert wheel.loss_j == pytest.approx(0.5 * GUIDE_TRAVEL_M)
    assert crit > frictionless.critical_slope_deg() + 0.05
    above, below = crit + 0.05, crit - 0.05
    w_above = math.sqrt(wheel.fixed_point_w(math.radians(above)))
    long_walk = walk(wheel, above, w_above, 40)
    assert not long_walk.stalled and long_walk.impacts.size == 40
    start = math.sqrt(1.3 * wheel.top_threshold(math.radians(below)))
    short = walk(wheel, below, start, 200)
    assert short.stalled and short.impacts.size < 200


def test_a_stance_keeps_the_energy_and_an_impact_takes_beta_and_the_loss() -> None:
    """Energy conservation over the stance (closed form) and the impact map, against the integrated walk."""
    wheel = LossyWheel(mass_kg=2.6, inertia_hub_kg_m2=0.3, leg_m=0.22, friction_n=0.3)
    phi = math.radians(3.0)
    w0 = 2.0 * wheel.top_threshold(phi)
    wk = walk(wheel, 3.0, math.sqrt(w0), 5)
    w = w0
    for speed in wk.post_impact_speed:
        w = wheel.beta**2 * (w + 4 * wheel.k * math.sin(phi) * math.sin(math.pi / 8)) - 2 * wheel.loss_j / (
            wheel.inertia_hub_kg_m2 + wheel.mass_kg * wheel.leg_m**2
        )
        assert speed**2 == pytest.approx(w, rel=1e-7)
    assert wk.post_impact_speed[0] ** 2 == pytest.approx(wheel.next_w(w0, phi), rel=1e-7)


@pytest.mark.parametrize(
    "lab",
    [Lab("z", 25.0, False), Lab("y", 210.0, False), Lab("z", 120.0, True), Lab("y", 300.0, True)],
    ids=lambda lab: lab.describe(),
)
def test_recordings_in_every_lab_import_with_their_slope_and_impacts(lab: Lab, tmp_path: Path) -> None:
    """Y-up and Z-up, any heading, an object or four markers: the importer finds the slope within 0.1 deg (or
    inside its own interval) and every impact within two frames (the truth's times, hold included)."""
    from rimless.analysis import import_trial

    rng = np.random.default_rng(3)
    wheel = LossyWheel(mass_kg=2.2, inertia_hub_kg_m2=0.15, leg_m=0.24, friction_n=0.2)
    slope = wheel.critical_slope_deg() + 0.3
    wk = walk(wheel, slope, 1.5 * math.sqrt(wheel.top_threshold(math.radians(slope))), 11)
    trial = import_trial(record(wk, tmp_path / "trial.csv", rng, lab))
    m = trial.meta
    lo, hi = (math.degrees(v) for v in m.slope_ci_rad) if m.slope_ci_rad else (math.nan, math.nan)
    assert abs(m.slope_deg - slope) < 0.1 or lo <= slope <= hi, (m.slope_deg, slope, lo, hi)
    assert m.outcome == "walked"
    found = np.asarray(trial.impact_time_s)
    truth = 0.4 + wk.impacts  # the recording's hold
    assert found.size >= truth.size - 1
    offsets = [np.min(np.abs(truth - t)) for t in found]
    assert max(offsets) < 2.0 / lab.rate_hz, offsets


def test_a_stall_is_recorded_as_a_stall(tmp_path: Path) -> None:
    from rimless.analysis import import_trial

    wheel = LossyWheel(mass_kg=2.2, inertia_hub_kg_m2=0.15, leg_m=0.24, friction_n=0.4)
    slope = wheel.critical_slope_deg() - 0.4
    wk = walk(wheel, slope, 1.4 * math.sqrt(wheel.top_threshold(math.radians(slope))), 11)
    assert wk.stalled
    trial = import_trial(record(wk, tmp_path / "stall.csv", np.random.default_rng(1), Lab("y", 75.0, True)))
    assert trial.meta.outcome == "stalled"


def test_the_truth_modules_are_written_apart_from_the_methods() -> None:
    """The truth models and the writer import nothing from the trial methods or the importer."""
    for name in ("critical_truth.py", "floquet_truth.py", "vicon_writer.py", "leg_truth.py"):
        tree = ast.parse((ROOT / "analysis/validation" / name).read_text())
        mods = [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
        mods += [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        bad = [m for m in mods if m.startswith(("rimless.analysis.inference", "rimless.analysis.kinematics"))]
        bad += [m for m in mods if m.startswith(("rimless.analysis.io", "tests"))]
        assert not bad, (name, bad)
