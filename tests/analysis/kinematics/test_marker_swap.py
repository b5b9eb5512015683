"""A marker-label swap of a few frames is repaired by rigid-body consistency (never a units error), with the
truth wheel of `tests.support.analysis_truth_wheel` (markers written from its body points)."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.kinematics.build import import_trial
from tests.support.analysis_truth_wheel import (
    EVEN_MARKERS,
    UNEVEN_MARKERS,
    body_points,
    make_truth,
    markers_section,
    noisy,
    write,
)


def _write(path, pts):
    return write(path, markers_section({f"wheel:M{i}": pts[:, i] for i in range(pts.shape[1])}))


@pytest.mark.parametrize("layout", ["even", "uneven"])
@pytest.mark.parametrize("perm", [[1, 0, 2, 3], [2, 1, 0, 3], [1, 2, 0, 3], [3, 2, 1, 0]])
def test_swap_of_five_frames_is_repaired(tmp_path, layout, perm):
    truth = make_truth(slope_deg=2.0, ending="walked")
    body = EVEN_MARKERS if layout == "even" else UNEVEN_MARKERS
    pts = noisy(body_points(truth, body), 0.3e-3, seed=3)
    clean = import_trial(_write(tmp_path / "clean.csv", pts))
    a = 150
    pts[a : a + 5] = pts[a : a + 5][:, perm]
    swapped = import_trial(_write(tmp_path / "swap.csv", pts))  # a units error before
    assert any("swapped marker labels repaired" in w for w in swapped.meta.warnings)
    np.testing.assert_allclose(swapped.series["hub"], clean.series["hub"], atol=1e-9, equal_nan=True)
    assert swapped.meta.slope_deg == pytest.approx(clean.meta.slope_deg, abs=1e-9)
    np.testing.assert_array_equal(swapped.impact_time_s, clean.impact_time_s)


def test_a_ghost_marker_becomes_a_gap(tmp_path):
    truth = make_truth(slope_deg=2.0, ending="walked")
    pts = noisy(body_points(truth, UNEVEN_MARKERS), 0.3e-3, seed=4)
    pts[150:153, 0] += np.array([0.3, -0.2, 0.1])  # a reflection far from the wheel, labelled M0
    trial = import_trial(_write(tmp_path / "ghost.csv", pts))
    assert any("fit no rigid shape" in w and "gaps" in w for w in trial.meta.warnings)
    assert abs(trial.meta.slope_deg - 2.0) < 0.1
