"""`rimless trials coverage --of calibrate`: the calibration's per-parameter coverage through the importer; the
machinery checked on one series (its figures come from the long run in docs/trials.md)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from rimless.analysis.validation.calibrate_coverage import C_RANGE, K_RANGE

runner = CliRunner()


def test_one_series_is_drawn_away_from_table1_imported_and_fitted() -> None:
    from rimless.cli import app

    r = runner.invoke(app, ["trials", "coverage", "--of", "calibrate", "--series", "1", "--seed", "5", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["fit"] == ["c", "k"] and out["series"] == 1
    (row,) = out["per_series"]
    assert C_RANGE[0] <= row["truth"]["c"] <= C_RANGE[1] and K_RANGE[0] <= row["truth"]["k"] <= K_RANGE[1]
    assert abs(row["truth"]["k"] - 2700) > 1 and abs(row["truth"]["c"] - 8) > 1e-6  # not Table 1's wheel
    assert row["trials"] == out["imports"]["trials"] == 4 and out["imports"]["refused"] == 0
    for name in ("c", "k"):
        p = row["params"][name]
        lo, hi = p["ci95"]
        assert p["covered"] == (lo <= row["truth"][name] <= hi)
        assert abs(p["value"] / row["truth"][name] - 1) < 0.1  # the simulator's own model: close to its truth
        d = out["parameters"][name]
        assert d["fitted"] == 1 and d["covered"] == int(p["covered"])
        # the se's parts: the imported slopes' (stated sd > 0) is carried, and the se is at least the data's with it
        assert p["se_slope"] > 0 and p["se"] >= (p["se_model"] ** 2 + p["se_slope"] ** 2) ** 0.5 * (1 - 1e-12)
        assert d["rms_z"] == pytest.approx(abs(p["value"] - row["truth"][name]) / p["se"], rel=1e-9)
    assert sum(out["optimizer_status"].values()) == 1
    r = runner.invoke(app, ["trials", "coverage", "--of", "nothing"])
    assert r.exit_code == 2 and "--of" in r.output
