"""`rimless paper` writing every figure, CSV and the headline table (on a coarse k grid), checked against the
quantities that define its rows (a gait's own stance force at the end of its valid k range)."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.cli import app
from tests.support.simcli_truth import stance_force_n


def test_rimless_paper_writes_every_figure_csv_and_headline_row(tmp_path):
    out = tmp_path / "paper"
    res = CliRunner().invoke(
        app,
        [
            "paper",
            "--out",
            str(out),
            "--k",
            "2500,2700",
            "--scheduler",
            "sync",
            "--cache-dir",
            str(tmp_path / "cache"),
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    for stem in (
        "fig1_typical_gaits",
        "fig2_ground_reaction_forces",
        "fig3_energy_ratio",
        "fig4_eigenvalue_map",
        "fig5_cot",
    ):
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
    for needle in (
        "rigid wheel critical slope",
        "VE critical slope",
        "ER energy ratio",
        "VE energy ratio",
        "ER max |eig|",
        "CoT reduction",
    ):
        assert needle in quantities
    rigid = next(r for r in data["table"] if r["quantity"].startswith("rigid wheel critical slope"))
    assert rigid["ours"] == "2.799"
    reduction = next(r for r in data["table"] if r["quantity"].startswith("ER CoT reduction vs VE at k = 2500"))
    assert "fast" in reduction["ours"] and "medium" in reduction["ours"]  # which branch reproduces 16.13 %
    assert "valid" in reduction["ours"]
    # the VE fast gait's valid range in k ends where its single-support stance force falls through 0
    fast = next(r for r in data["table"] if r["quantity"].startswith("VE fast gait stable and contact-valid"))
    assert "(stance-force)" in fast["ours"]
    import pandas as pd

    ranges = pd.read_csv(out / "table6_valid_k_ranges.csv")
    vr = ranges[(ranges.model == "VE") & (ranges.branch_label == "fast")].iloc[0]
    assert vr.k_high_reason == "stance-force"
    assert float(fast["ours"].split(" to ")[1].split(" ")[0]) == pytest.approx(vr.k_high, abs=0.05)
    # independently: the fast gait's own stance force (fixed point and recorded step, the foot held) is
    # positive just below the located end and negative just above it
    sweep_rows = pd.read_csv(out / "sweep.csv")
    start = sweep_rows[
        (sweep_rows.model == "VE") & (sweep_rows.branch_label == "fast") & (sweep_rows.k == vr.from_k)
    ].iloc[0]
    z = np.array([start.theta_plus_rad, start.theta_dot_plus_rad_s])
    assert (
        stance_force_n("ve", vr.k_high - 10.0, vr.slope_rad, z)
        > 0
        > stance_force_n("ve", vr.k_high + 10.0, vr.slope_rad, z)
    )
    # which VE branch reproduces 16.13 %, with its validity and valid k range
    rep = next(r for r in data["table"] if r["quantity"].startswith("VE branch that reproduces"))
    assert rep["ours"].startswith("VE fast") and "contact-valid" in rep["ours"] and "(stance-force)" in rep["ours"]
    # figure 5: the k = 2700 fast gait is invalid at the start slope; the end of its valid part lower down is
    # drawn apart from the branches valid at the start

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
