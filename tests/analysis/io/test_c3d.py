"""C3D import (ezc3d) against the same truth trial written as Tracker CSV."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.kinematics.build import TrialRefused, import_trial
from rimless.errors import InputFileError
from tests.support import analysis_truth_wheel as tw

ezc3d = pytest.importorskip("ezc3d")


def write_c3d_with_ezc3d(path, rate, markers_m, *, occluded_zero=None):
    """A C3D written directly with ezc3d (mm, float32), as Nexus would; ``occluded_zero``: (frame, marker) mask
    written Vicon-style as zeros with a negative residual."""
    names = list(markers_m)
    arr = np.stack([markers_m[k] for k in names], axis=1) * 1e3  # (n, k, 3) mm
    pts = np.ones((4, len(names), arr.shape[0]))
    pts[:3] = arr.transpose(2, 1, 0)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    if occluded_zero is not None:
        pts[:3, occluded_zero.T] = 0.0
        pts[3, occluded_zero.T] = 0.0
    c["data"]["points"] = pts
    c.write(str(path))
    return path


def test_c3d_round_trip_equals_tracker_csv(tmp_path):
    truth = tw.make_truth(ending="caught", slope_deg=2.2)
    pts = tw.noisy(tw.body_points(truth, tw.UNEVEN_MARKERS), 0.3e-3, 4)
    pts = tw.blank(pts, truth, 2.0, 2.03)  # a short occlusion
    mk = {f"wheel:M{i}": pts[:, i] for i in range(4)}
    csv = import_trial(tw.write(tmp_path / "t.csv", tw.markers_section(mk)))
    c3d = import_trial(write_c3d_with_ezc3d(tmp_path / "t.c3d", 100.0, mk))
    a, b = csv.meta, c3d.meta
    assert (a.outcome, a.markers, a.n_frames, a.rate_hz, a.n_gap_frames) == (
        b.outcome,
        b.markers,
        b.n_frames,
        b.rate_hz,
        b.n_gap_frames,
    )
    # C3D stores float32 mm (0.1 um at 1 m), the CSV 6 decimals of mm: the same trial within that
    np.testing.assert_allclose(c3d.series["hub"], csv.series["hub"], atol=2e-6, equal_nan=True)
    np.testing.assert_allclose(c3d.impact_time_s, csv.impact_time_s, atol=1e-4)
    np.testing.assert_allclose(c3d.step_period_s, csv.step_period_s, atol=1e-4)
    assert abs(a.slope_deg - b.slope_deg) < 1e-3 and abs(a.slope_deg - 2.2) < 0.05
    assert c3d.meta.outcome == truth.outcome


def test_c3d_vicon_occlusions_zeros_with_negative_residual(tmp_path):
    truth = tw.make_truth(ending="walked")
    pts = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), 0.3e-3, 5)
    occ = np.zeros((truth.time_s.size, 4), bool)
    occ[150:160, 2] = True
    occ[200:203] = True
    trial = import_trial(
        write_c3d_with_ezc3d(tmp_path / "o.c3d", 100.0, {f"w:M{i}": pts[:, i] for i in range(4)}, occluded_zero=occ)
    )
    assert trial.meta.n_interpolated_frames == 3  # the frames with every marker lost, bridged
    hub = trial.series["hub"]
    assert np.nanmax(np.linalg.norm(np.diff(hub, axis=0), axis=1)) < 0.02  # no jump to the origin


def test_c3d_errors(tmp_path):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"not a c3d file at all" * 10)
    with pytest.raises(InputFileError, match="bad.c3d"):
        import_trial(bad)
    truth = tw.make_truth()
    pts = tw.body_points(truth, tw.EVEN_MARKERS)
    p = write_c3d_with_ezc3d(tmp_path / "rate.c3d", 20000.0, {f"w:M{i}": pts[:, i] for i in range(4)})
    with pytest.raises(InputFileError, match="POINT:RATE"):
        import_trial(p)
    static = write_c3d_with_ezc3d(
        tmp_path / "static.c3d", 100.0, {f"w:M{i}": pts[:1].repeat(500, 0)[:, i] for i in range(4)}
    )
    with pytest.raises(TrialRefused, match="nothing moves like the wheel"):
        import_trial(static)
