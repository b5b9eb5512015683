"""`rimless paper` on k grids where a wheel has no gait (issue 33: `--k 100:200:100` ended in KeyError 'model',
`--k 100:2600:2500` in KeyError 'max_abs_eigenvalue'): the k without a gait is a row of the table, never a
traceback. Legs on k = 100 N/m sag by m_H g / k = 0.2 m under the hub's weight alone: no period-1 gait."""

import json
import math

from typer.testing import CliRunner

from rimless.cli import app
from rimless.sim.model.params import WheelParams


def test_rimless_paper_on_a_grid_without_any_gait_writes_its_table(tmp_path):
    out = tmp_path / "p"
    res = CliRunner().invoke(
        app, ["paper", "--k", "100:200:100", "--out", str(out), "--scheduler", "sync", "--no-cache", "--json"]
    )
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output
    data = json.loads(res.stdout)
    rows = {r["quantity"]: r["ours"] for r in data["table"]}
    for k in (100, 200):
        for model in ("ER", "VE"):
            assert rows[f"{model} gaits at k = {k} N/m"] == "no period-1 gait"
    assert (out / "fig4_eigenvalue_map.png").exists() and (out / "table6_headline.md").exists()


def _no_gait(model: str, k: float) -> dict:
    return {
        "model": model,
        "k": k,
        "c": 8.0,
        "mass_model": "paper",
        "start_slope_rad": 0.05,
        "branch": "",
        "branch_label": "",
        "reason": "no-gait",
        "detail": "no period-1 gait found at the start slope",
        "critical_slope_rad": math.nan,
        "critical_slope_deg": math.nan,
        "cot": math.nan,
        "stable_at_start": False,
        "contact_valid_at_start": False,
    }


def test_headline_table_with_an_er_row_without_gait_beside_one_with_a_gait():
    """The `--k 100:2600:2500` case: ER has no gait at one k and a gait at the other."""
    from rimless.sim.studies.paper import headline_table

    gait = {
        **_no_gait("ER", 2600.0),
        "branch": "er-1-er",
        "branch_label": "er",
        "reason": "stall",
        "critical_slope_rad": 0.0222,
        "critical_slope_deg": math.degrees(0.0222),
        "cot": math.tan(0.0222),
        "stable_at_start": True,
        "contact_valid_at_start": True,
        "energy_ratio": 0.85,
        "max_abs_eigenvalue": 0.77,
    }
    table = headline_table([_no_gait("ER", 100.0), _no_gait("VE", 100.0), gait], [], WheelParams())
    rows = {r["quantity"]: r["ours"] for r in table}
    assert rows["ER max |eig|"] == "0.770-0.770"
    assert rows["ER gaits at k = 100 N/m"] == "no period-1 gait"
    assert rows["VE gaits at k = 100 N/m"] == "no period-1 gait"
