"""The critical slope as a curve over k (two-parameter continuation) against one-parameter located ends, and
`rimless paper` writing every figure, CSV and the headline table (on a coarse k grid)."""

import json
import math

import pytest
from typer.testing import CliRunner

from rimless.cli import app
from rimless.sim.integrate.backend import make_map
from rimless.sim.continuation.boundary import BoundaryContinuation, solve_at, start_on_boundary
from rimless.sim.continuation.algorithm1 import critical_slope
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import WheelParams
from rimless.sim.step.poincare import default_guess


def _factory(model):
    return lambda q: make_map(q, model, backend="fast")


def test_fold_curve_passes_through_the_one_parameter_folds():
    """Traced from the fold at k = 2700, the VE medium fold curve meets the fold that the one-parameter
    continuation locates independently at k = 2500."""
    p = WheelParams()
    z, s0 = start_on_boundary(_factory("ve"), p, "ve", default_guess(p, "ve"), "fold")
    bc = BoundaryContinuation(_factory("ve"), p.replace(slope_rad=s0), "ve", "k", "fold", max_points=12)
    curve = bc.trace(z, s0, mu_min=2400, mu_max=2800)
    assert min(pt.mu for pt in curve.points) < 2500 < max(pt.mu for pt in curve.points)
    for pt in curve.points:
        assert min(abs(pt.eigenvalues - 1.0)) < 1e-6  # every point of the curve is a fold
    on_curve = solve_at(bc, curve, 2500.0)
    p2 = WheelParams(stiffness_n_per_m=2500.0)
    one = critical_slope(make_map(p2, "ve", backend="fast"), default_guess(p2, "ve"), method="arclength")
    assert one.reason == "fold"
    assert on_curve.slope_rad == pytest.approx(one.critical_slope_rad, abs=1e-6)


def test_er_stall_curve_is_the_stall_itself_point_by_point():
    """Every point of the ER stall curve is the stall at its k: it agrees with the stall that Algorithm 1 with
    bisection locates independently at that k (to 1e-6 rad), lies below its 1.6 s level-set point, and past
    it (slightly lower slope) no gait exists."""
    p = WheelParams()
    z, s0 = start_on_boundary(_factory("er"), p, "er", default_guess(p, "er"), "stall")
    bc = BoundaryContinuation(_factory("er"), p.replace(slope_rad=s0), "er", "k", "stall", max_points=3)
    curve = bc.trace(z, s0, mu_min=2650, mu_max=2750)
    assert len(curve.points) == len(curve.level_points) >= 3
    for stall, level in zip(curve.points, curve.level_points):
        assert stall.mu == level.mu and 0 < level.slope_rad - stall.slope_rad < math.radians(0.002)
    pt = next(pt for pt in curve.points if pt.mu != 2700.0)  # a point the continuation put at its own k
    q = WheelParams(stiffness_n_per_m=pt.mu)
    one = critical_slope(make_map(q, "er", backend="fast"), default_guess(q, "er"), method="bisection",
                         refine_tol_rad=1e-9)
    assert one.reason == "stall"
    assert pt.slope_rad == pytest.approx(one.critical_slope_rad, abs=1e-6)
    with pytest.raises(StepFailure):
        bc.fixed_point_at(pt.z, pt.slope_rad - 1e-7, pt.mu)


def test_rimless_paper_writes_every_figure_csv_and_headline_row(tmp_path):
    out = tmp_path / "paper"
    res = CliRunner().invoke(app, ["paper", "--out", str(out), "--k", "2500,2700", "--scheduler", "sync",
                                   "--cache-dir", str(tmp_path / "cache"), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    for stem in ("fig1_typical_gaits", "fig2_ground_reaction_forces", "fig3_energy_ratio", "fig4_eigenvalue_map",
                 "fig5_cot"):
        png = out / f"{stem}.png"
        assert png.exists() and (out / f"{stem}.csv").exists()
        from PIL import Image

        with Image.open(png) as im:
            dpi = im.info.get("dpi", (0, 0))[0]
        assert dpi >= 149
    assert (out / "table6_headline.csv").exists() and (out / "index.html").exists()
    index = (out / "index.html").read_text()
    assert all(f"fig{i}_" in index for i in range(1, 6))
    quantities = " | ".join(r["quantity"] for r in data["table"])
    for needle in ("rigid wheel critical slope", "VE critical slope", "ER energy ratio", "VE energy ratio",
                   "ER max |eig|", "CoT reduction"):
        assert needle in quantities
    rigid = next(r for r in data["table"] if r["quantity"].startswith("rigid wheel critical slope"))
    assert rigid["ours"] == "2.799"
    reduction = next(r for r in data["table"] if r["quantity"].startswith("ER CoT reduction vs VE at k = 2500"))
    assert "fast" in reduction["ours"] and "medium" in reduction["ours"]  # which branch reproduces 16.13 %
    assert "valid" in reduction["ours"]
    # the VE fast gait's valid range in k ends where its single-support stance force falls through 0
    fast = next(r for r in data["table"] if r["quantity"].startswith("VE fast gait stable and contact-valid"))
    assert "(stance-force)" in fast["ours"]
    k_end = float(fast["ours"].split(" to ")[1].split(" ")[0])
    assert k_end == pytest.approx(2551, abs=2)
    assert (out / "table6_valid_k_ranges.csv").exists()
    # which VE branch reproduces 16.13 %, with its validity and valid k range
    rep = next(r for r in data["table"] if r["quantity"].startswith("VE branch that reproduces"))
    assert rep["ours"].startswith("VE fast") and "contact-valid" in rep["ours"] and "(stance-force)" in rep["ours"]
    # figure 5: the k = 2700 fast gait is invalid at the start slope; the end of its valid part lower down is
    # drawn apart from the branches valid at the start
    import pandas as pd

    cot = pd.read_csv(out / "fig5_cot.csv")
    late = cot[cot.get("valid_part_only", pd.Series(False, index=cot.index)).fillna(False).astype(bool)]
    assert list(late.k) == [2700.0] and list(late.branch_label) == ["fast"] and list(late.reason) == ["fold"]
    assert (late.valid_from_slope_deg > late.critical_slope_deg).all()
    # figure 4 marks validity point by point: at k = 2700 the fast branch is invalid at the start slope
    from rimless.sim.studies.paper import figure_eigenvalues

    rows = pd.read_csv(out / "sweep.csv").to_dict("records")
    points = pd.read_csv(out / "sweep-points.csv").to_dict("records")
    figure_eigenvalues(points, rows, tmp_path, ks=(2700.0,))
    fig4 = pd.read_csv(tmp_path / "fig4_eigenvalue_map.csv")
    fast = fig4[(fig4.model == "VE") & (fig4.branch_label == "fast")]
    assert (~fast.contact_valid).any() and fast.contact_valid.any()  # invalid at 2.865 deg, valid lower down
    top = fast.sort_values("slope_rad").iloc[-1]
    assert not top.contact_valid
    assert fig4[fig4.branch_label == "medium"].contact_valid.all()
