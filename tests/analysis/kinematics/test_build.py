"""Building trials: synthetic rolling wheels with known slope, impacts and CoM path; the public exports."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from rimless.analysis.examples.synthetic import rolling_wheel
from rimless.analysis.io.tracker_csv import write_tracker_csv
from rimless.analysis.io.vicon_csv import read_vicon_csv
from rimless.analysis.kinematics.build import TrialRefused, build_trial, fill_short_gaps, import_trial
from tests.support.analysis_data import PUBLIC, public

NOISE_M = 0.3e-3


def write_markers(tmp_path, w, markers=None, name="m.csv"):
    pts = w.markers_m if markers is None else markers
    return write_tracker_csv(
        tmp_path / name, rate_hz=w.rate_hz, markers={f"wheel:M{i}": pts[:, i] for i in range(pts.shape[1])}
    )


def write_object(tmp_path, w, name="o.csv"):
    return write_tracker_csv(
        tmp_path / name, rate_hz=w.rate_hz, objects={"Wheel": np.hstack([w.object_rotvec_rad, w.object_trans_m])}
    )


def assert_periods_within_one_frame(trial, w):
    """Every detected impact matches a true one within one frame, and so does every period."""
    frame = 1 / w.rate_hz
    t = trial.impact_time_s
    assert t.size >= len(w.impact_time_s) - 1
    nearest = w.impact_time_s[np.argmin(np.abs(t[:, None] - w.impact_time_s[None]), axis=1)]
    assert np.all(np.abs(t - nearest) < frame)
    np.testing.assert_array_less(np.abs(np.diff(t) - np.diff(nearest)), frame)
    assert np.all(np.diff(nearest) > 0)  # one detected impact per true impact


@pytest.mark.parametrize("seed", [1, 2])
def test_four_markers_slope_steps_and_com(tmp_path, seed):
    w = rolling_wheel(seed=seed, slope_deg=2.0, noise_m=NOISE_M)
    trial = import_trial(write_markers(tmp_path, w), leg_length_m=w.leg_length_m)
    m = trial.meta
    assert abs(m.slope_deg - 2.0) < 0.05
    # the best conditioned estimate: the contact line or the line through the hub at the impacts
    assert m.slope_source == "estimated" and ("contact points" in m.slope_method or "minima" in m.slope_method)
    assert m.step_method == "rotation" and m.step_refused is None
    assert_periods_within_one_frame(trial, w)
    err = trial.series["com_height"] - w.com_height_m
    assert np.sqrt(np.mean(err**2)) < NOISE_M  # the 4-marker hub averages the noise down
    # the wheel turns 45 deg per step
    a = np.interp(trial.impact_time_s, trial.time_s, trial.series["wheel_angle"])
    np.testing.assert_allclose(np.diff(a), np.pi / 4, atol=np.radians(0.5))


def test_object_with_offset_origin_estimates_hub(tmp_path):
    w = rolling_wheel(seed=5, slope_deg=2.5, noise_m=NOISE_M)
    trial = import_trial(write_object(tmp_path, w), leg_length_m=w.leg_length_m)
    m = trial.meta
    assert "estimated offset" in m.hub_source
    # in-plane offset recovered; the component along the wheel axis is unobservable and set to 0
    np.testing.assert_allclose(m.hub_offset_m[:2], w.hub_offset_m[:2], atol=1e-3)
    assert m.hub_offset_m[2] == pytest.approx(0.0, abs=1e-9)
    assert abs(m.slope_deg - 2.5) < 0.05
    assert_periods_within_one_frame(trial, w)
    err = trial.series["com_height"] - w.com_height_m
    assert np.sqrt(np.mean(err**2)) < 1.5 * NOISE_M  # one noisy origin per frame, not averaged


def test_object_with_given_offset_and_slope(tmp_path):
    w = rolling_wheel(seed=6, slope_deg=1.0, noise_m=NOISE_M)
    trial = import_trial(
        write_object(tmp_path, w), leg_length_m=w.leg_length_m, slope_deg=1.0, hub_offset_m=w.hub_offset_m
    )
    assert trial.meta.slope_deg == pytest.approx(1.0, abs=1e-12)
    assert trial.meta.slope_source == "given" and "given offset" in trial.meta.hub_source
    np.testing.assert_allclose(trial.series["hub"], w.hub_m, atol=5 * NOISE_M)


def test_single_hub_marker_uses_com_minima(tmp_path):
    w = rolling_wheel(seed=7, slope_deg=2.0, noise_m=NOISE_M)
    hub = w.hub_m + np.random.default_rng(0).normal(0, NOISE_M, w.hub_m.shape)
    trial = import_trial(write_markers(tmp_path, w, hub[:, None, :]), leg_length_m=w.leg_length_m)
    assert trial.meta.step_method == "com-minima" and "wheel_angle" not in trial.series.data
    assert abs(trial.meta.slope_deg - 2.0) < 0.05
    assert_periods_within_one_frame(trial, w)


def test_noisy_trial_is_refused_not_guessed(tmp_path):
    w = rolling_wheel(seed=8, noise_m=NOISE_M)
    hub = w.hub_m + np.random.default_rng(1).normal(0, 8e-3, w.hub_m.shape)  # noise > the 3 mm bumps
    trial = import_trial(write_markers(tmp_path, w, hub[:, None, :]))
    assert trial.meta.step_method == "none" and trial.meta.step_refused
    assert trial.impact_time_s.size == 0


def test_short_gaps_filled_by_bounded_rule_long_gaps_refuse_steps(tmp_path):
    w = rolling_wheel(seed=9, noise_m=NOISE_M)
    mk = w.markers_m.copy()
    mk[50:52] = np.nan  # 2 frames: all markers lost
    p = write_markers(tmp_path, w, mk)
    t0 = import_trial(p, max_gap_s=0)
    assert t0.meta.n_gap_frames == 2 and t0.meta.n_interpolated_frames == 0
    t1 = import_trial(p, max_gap_s=0.02)
    assert t1.meta.n_gap_frames == 0 and t1.series["interpolated"][50:52].all()
    assert t1.series["interpolated"].sum() == 2
    mk[100:140] = np.nan  # 0.4 s: longer than a step
    t2 = import_trial(write_markers(tmp_path, w, mk, "gappy.csv"), max_gap_s=0.02)
    assert t2.meta.n_gap_frames == 40 and np.isnan(t2.series["hub"][100:140]).all()
    # the steps are kept on both sides of the long gap; no period spans it
    assert t2.meta.step_refused is None
    ti = t2.impact_time_s
    starts = ti[np.flatnonzero(np.isin(t2.impact_step, t2.period_step - 1))]
    for a, b in zip(starts, starts + t2.step_period_s):
        assert b < 1.0 or a > 1.39
    assert any("dropped" in w for w in t2.meta.warnings)


def test_one_occluded_marker_keeps_hub(tmp_path):
    w = rolling_wheel(seed=10, noise_m=0.0)
    mk = w.markers_m.copy()
    mk[30:60, 2] = np.nan
    trial = import_trial(write_markers(tmp_path, w, mk), hub_offset_m=(0, 0, 0))
    np.testing.assert_allclose(trial.series["hub"], w.hub_m, atol=1e-9)


def test_fill_short_gaps_by_hand():
    v = np.array([0.0, np.nan, 2.0, np.nan, np.nan, np.nan, 6.0, np.nan])
    out, filled = fill_short_gaps(v, 2)
    np.testing.assert_array_equal(out[:3], [0, 1, 2])
    assert np.isnan(out[3:6]).all() and np.isnan(out[7])
    assert filled.tolist() == [False, True] + [False] * 6


def test_missing_frame_rows_become_gaps(tmp_path):
    w = rolling_wheel(seed=11)
    p = write_markers(tmp_path, w)
    lines = p.read_text().split("\n")
    del lines[5 + 40 : 5 + 43]  # drop three data rows (frames 41-43)
    p.write_text("\n".join(lines))
    trial = import_trial(p, max_gap_s=0)
    assert trial.meta.n_frames == len(w.time_s) and trial.meta.n_gap_frames == 3
    assert trial.series["gap"][40:43].all()


# ------------------------------------------------------------------------------------ public exports


def test_public_tracker_object_imports():
    trial = import_trial(public("tracker_objects_vantage_tube8.csv"))
    m = trial.meta
    assert (m.section, m.object, m.n_frames, m.rate_hz, m.first_frame) == ("Objects", "DasKebab2", 547, 100.0, 1)
    assert m.file_units == {"RX": "rad", "RY": "rad", "RZ": "rad", "TX": "mm", "TY": "mm", "TZ": "mm"}
    # A tube carried along +Y, not a wheel: origin used as hub, no steps (refused with the reason).
    assert m.hub_source.startswith("object origin (it turns only")
    assert m.step_method == "none" and "fewer than two steps" in m.step_refused
    with open(PUBLIC / "tracker_objects_vantage_tube8.csv", newline="") as f:
        rows = [r for r in csv.reader(f)][5:]
    last = [r for r in rows if r][-1]
    np.testing.assert_array_equal(trial.series["hub"][-1], [float(c) / 1000 for c in last[5:8]])
    assert abs(trial.meta.slope_deg) < 0.5  # carried roughly level (TZ 410-430 mm over 9.5 m)
    assert abs(trial.meta.travel_direction[1]) > 0.99  # along +Y


@pytest.mark.parametrize(
    "name,phrases",
    [
        ("nexus_devices_pyomeca_analogs.csv", ["no usable trajectory", "only Devices (line 1"]),
        ("nexus_trajectories_pyomeca.csv", ["nothing moves like the wheel", "boite: 8", "Daphnee: 43", "--markers"]),
        ("nexus_multisection_wpi_walk.csv", ["nothing moves like the wheel", "subject_00: 64", "--markers"]),
    ],
)
def test_public_nexus_files_refused_with_reason(name, phrases):
    with pytest.raises(TrialRefused) as e:
        import_trial(public(name))
    for p in phrases:
        assert p in str(e.value)


def test_public_markers_chosen_by_name_hub_is_centroid():
    path = public("nexus_trajectories_pyomeca.csv")
    names = ["boite:gauche_ext", "boite:gauche_int", "boite:droite_int", "boite:droite_ext"]
    trial = build_trial(read_vicon_csv(path), markers=names, hub_offset_m=(0, 0, 0))
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    first = rows[5]
    exp = np.mean([[float(first[2 + 3 * k + j]) / 1000 for j in range(3)] for k in range(4)], axis=0)
    np.testing.assert_allclose(trial.series["hub"][0], exp, rtol=0, atol=1e-12)
    assert trial.meta.markers == tuple(names)
