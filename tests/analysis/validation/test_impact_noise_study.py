"""`rimless.analysis.validation.impact_noise_study`: the adequacy check's impact-time noise against the importer's
actual impact-time error on Vicon exports of the simulator's ER wheel (truth: the walk's own impact times)."""

from __future__ import annotations

import math

import pytest

from rimless.analysis.validation.impact_noise_study import impact_noise_study, main


@pytest.mark.slow
@pytest.mark.parametrize("markers", [False, True])
def test_the_estimate_matches_the_importers_scatter_against_the_truth(markers: bool) -> None:
    """Two series of four walks: the imported impacts scatter about the true ones by a fraction of a 10 ms frame
    (0.1-1 ms: the importer places impacts to well within a frame, docs/trials.md), and the check's estimate from
    the periods is that scatter within a factor of 1.6 (20 degrees of freedom a series: about 16 % scatter)."""
    out = impact_noise_study(2, 3, markers)
    rows = [r for r in out["per_series"] if r.get("estimate_ms") is not None]
    assert len(rows) == 2
    for r in rows:
        assert r["trials"] >= 3 and r["estimate_dof"] >= 15
        assert 0.1 < r["truth_scatter_ms"] < 1.0, r
        assert 1 / 1.6 < r["estimate_ms"] / r["truth_scatter_ms"] < 1.6, r
        assert r["lab"]["markers"] is markers and math.isfinite(r["angle_noise_ms"])


def test_a_bad_series_count_is_one_error_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--series", "0"]) == 2
    assert capsys.readouterr().err.strip() == "error: --series takes 1 or more"
