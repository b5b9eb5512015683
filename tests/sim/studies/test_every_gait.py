"""Every gait at every slope (issue 33): a stable, contact-valid gait that walks below the other wheel's critical
slope but does not exist at the start slope is found by the search at lower slopes and enters the least CoT.

Independent expectations: issue 33's measurements with another implementation (k = 2000 N/m: a VE "medium" gait
at 0.0228 rad with max|eig| 0.572, its critical slope 0.0224143 rad, the ER stall at 0.02327 rad, ER 3.8 % dearer
than VE with no clutch power) and a fixed point solved apart from the search (tests/support/fixed_point_check:
scipy root on the reference integrator's map)."""

import math

import numpy as np
import pytest

from rimless.sim.continuation.branches import search_slopes
from rimless.sim.model.params import WheelParams
from rimless.sim.studies.sweep import SweepOptions, compute_point
from tests.support.fixed_point_check import check_gait

K = 2000.0
SLOPE = 0.0228  # rad, issue 33
ER_STALL = 0.02327  # rad, issue 33 (another implementation)
VE_MEDIUM_CRITICAL = 0.0224143  # rad, issue 33


def _point(model: str) -> dict:
    return {"model": model, "params": WheelParams(stiffness_n_per_m=K).to_dict()}


@pytest.fixture(scope="module")
def ve_swept():
    options = SweepOptions(backend="fast", start_slope_rad=0.05, search_slopes_rad=search_slopes(0.05))
    return compute_point(_point("ve"), options)


@pytest.fixture(scope="module")
def er_swept():
    options = SweepOptions(backend="fast", start_slope_rad=0.05, search_slopes_rad=search_slopes(0.05))
    return compute_point(_point("er"), options)


def test_the_ve_medium_gait_at_k_2000_is_real_and_the_sweep_lists_it(ve_swept):
    truth = check_gait("ve", K, SLOPE, (-0.45, 2.05))
    assert truth.residual < 1e-9
    assert truth.max_abs_eigenvalue == pytest.approx(0.572, abs=0.002)  # stable
    assert truth.min_stance_force_N > 0 and truth.min_impulse_N_s > 0  # contact-valid
    below = [
        r
        for r in ve_swept["rows"]
        if r["stable_at_start"] and r["contact_valid_at_start"] and r["critical_slope_rad"] < ER_STALL
    ]
    assert below, [(r["branch"], r["critical_slope_rad"]) for r in ve_swept["rows"]]
    row = min(below, key=lambda r: r["critical_slope_rad"])
    assert row["critical_slope_rad"] == pytest.approx(VE_MEDIUM_CRITICAL, abs=2e-7)
    assert row["found_by"] != "start-slope" and row["start_slope_rad"] < 0.05
    # the branch passes through the independently solved fixed point at 0.0228 rad
    pts = sorted(
        (p["slope_rad"], np.array([p["theta_plus_rad"], p["theta_dot_plus_rad_s"]]))
        for p in ve_swept["points"]
        if p["branch"] == row["branch"] and p["stable"]
    )
    lo = max((q for q in pts if q[0] <= SLOPE), key=lambda q: q[0])
    hi = min((q for q in pts if q[0] >= SLOPE), key=lambda q: q[0])
    w = 0.0 if hi[0] == lo[0] else (SLOPE - lo[0]) / (hi[0] - lo[0])
    assert np.max(np.abs(lo[1] + w * (hi[1] - lo[1]) - truth.z)) < 2e-3


def test_the_start_slope_alone_misses_it():
    """The old search (the start slope only): no VE gait below the ER stall, the miss issue 33 reports."""
    rows = compute_point(_point("ve"), SweepOptions(backend="fast", start_slope_rad=0.05))["rows"]
    crit = [r["critical_slope_rad"] for r in rows if r["critical_slope_rad"] == r["critical_slope_rad"]]
    assert crit and min(crit) > ER_STALL


def test_the_headline_table_lists_the_ve_gait_below_er(ve_swept, er_swept):
    from rimless.sim.studies.paper import headline_table

    table = headline_table(er_swept["rows"] + ve_swept["rows"], [], WheelParams())
    rows = {r["quantity"]: r["ours"] for r in table}
    below = rows["VE gaits that walk below ER's critical slope"]
    assert "k = 2000: VE medium (found at" in below
    assert f"down to {math.degrees(VE_MEDIUM_CRITICAL):.4f} deg" in below
    assert "k = 2000: +3.8% vs VE medium" in rows["ER CoT against the least stable, valid VE gait, per k"]


def test_the_system_cot_table_takes_the_lower_gait(ve_swept, er_swept):
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.studies.paper_system_cot import branches_from_sweep, k_rows

    er = er_swept
    rows, points = er["rows"] + ve_swept["rows"], er["points"] + ve_swept["points"]
    brs = branches_from_sweep(rows, points, K, "fast", 1e-10)
    assert min(b.lo_rad for b in brs["er"]) == pytest.approx(ER_STALL, abs=1e-5)
    row, _ = k_rows(K, brs, ClutchPower())
    assert row["ve_least_branch"] == "medium"
    # issue 33: ER 3.8 % dearer than VE with no clutch power, so there is no break-even at any power
    assert row["er_vs_ve_mechanical_cot_pct"] == pytest.approx(
        100 * (math.tan(ER_STALL) / math.tan(VE_MEDIUM_CRITICAL) - 1), abs=0.1
    )
    assert row["er_vs_ve_mechanical_cot_pct"] == pytest.approx(3.8, abs=0.1)
    assert row["break_even_hold_power_w"] is None and not row["break_even_tie"]
