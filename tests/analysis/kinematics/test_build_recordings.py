"""Recordings made the way the prototype is really recorded, against the independent truth model in
tests/support/analysis_truth_wheel.py.

Each case: a hold before the release, the walk, an ending (walked, left the volume, caught 2 cm / 15 cm, fell,
stalled), and the mess of real files (gaps, zeros, a ramp, a pasted take, unlabelled or uneven markers, wrong
units, a lost cell, an absurd rate). Expectations come from the truth model, never from the code under test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.io.vicon_csv import ViconCsvError, parse_vicon_text
from rimless.analysis.kinematics.build import TrialRefused, import_trial
from tests.support import analysis_truth_wheel as tw
from tests.support.work_budget import call_budget

NOISE = 0.3e-3
FRAME = 0.01


def markers_file(path, truth, body=tw.UNEVEN_MARKERS, seed=1, edit=None, prefix="wheel:M"):
    pts = tw.noisy(tw.body_points(truth, body), NOISE, seed)
    if edit is not None:
        pts = edit(pts)
    return tw.write(path, tw.markers_section({f"{prefix}{i}": pts[:, i] for i in range(pts.shape[1])})), pts


def object_file(path, truth, origin_body=(0.03, -0.025, 0.01), seed=2, extra=None):
    objs = {"Wheel": tw.pose_of(truth, np.asarray(origin_body), NOISE, seed)}
    if extra:
        objs.update(extra)
    return tw.write(path, tw.objects_section(objs))


def check_walk(trial, truth, *, slope_tol_deg=0.05):
    """Slope, impacts, periods (within one frame), window and outcome against the truth."""
    m = trial.meta
    assert m.outcome == truth.outcome, m.outcome_reason
    assert abs(m.slope_deg - truth.slope_deg) < slope_tol_deg
    ti = truth.impact_time_s
    got = trial.impact_time_s
    assert got.size >= 2
    # one detected impact per true impact, each within one frame
    nearest = np.argmin(np.abs(got[:, None] - ti[None]), axis=1)
    assert np.all(np.abs(got - ti[nearest]) < FRAME)
    assert np.all(np.diff(nearest) > 0)
    # periods: only between consecutive true impacts, each within one frame of the truth
    starts = got[np.isin(trial.impact_step, trial.period_step - 1)]
    true_p = np.diff(ti)
    for a, p in zip(starts, trial.step_period_s):
        k = int(np.argmin(np.abs(ti - a)))
        assert abs(p - true_p[k]) < FRAME
    # window: release to the last impact
    w0, w1 = m.window_s
    assert abs(w0 - truth.release_s) <= 2 * FRAME
    assert abs(w1 - got[-1]) < 1e-9
    return nearest


ENDINGS = [
    ("walked", {}),
    ("left", {}),
    ("caught", {"lift_m": 0.02}),
    ("caught", {"lift_m": 0.15}),
    ("fell", {}),
    ("stalled", {"end_fraction": 0.3}),
]


@pytest.mark.parametrize("ending,kw", ENDINGS, ids=[f"{e}-{k.get('lift_m', '')}" for e, k in ENDINGS])
@pytest.mark.parametrize("kind", ["markers", "object"])
def test_endings_after_a_hold(tmp_path, ending, kw, kind):
    truth = tw.make_truth(ending=ending, slope_deg=2.3, **kw)
    if kind == "markers":

        def edit(p):
            if ending == "left":  # the wheel leaves the volume: every marker vanishes for the last 0.15 s
                p = tw.blank(p, truth, truth.time_s[-1] - 0.15, 1e9)
            return p

        path, _ = markers_file(tmp_path / "w.csv", truth, edit=edit)
    else:
        pose = tw.pose_of(truth, np.array([0.03, -0.025, 0.01]), NOISE, 2)
        if ending == "left":
            pose = tw.blank(pose, truth, truth.time_s[-1] - 0.15, 1e9)
        path = tw.write(tmp_path / "o.csv", tw.objects_section({"Wheel": pose}))
    trial = import_trial(path)
    nearest = check_walk(trial, truth)
    seen_until = truth.time_s[-1] - (0.15 if ending == "left" else 0.0)
    expected = truth.impact_time_s[truth.impact_time_s < seen_until - FRAME]
    assert nearest.size == expected.size  # every observed true impact found
    assert trial.step_period_s.size == expected.size - 1
    assert trial.meta.step_refused is None


def test_long_gap_mid_walk_keeps_every_fully_observed_period(tmp_path):
    truth = tw.make_truth(ending="caught", lift_m=0.05)
    t_gap = (truth.impact_time_s[2] + 0.1, truth.impact_time_s[2] + 0.55)  # 0.45 s: swallows impact 4
    short = [
        (truth.impact_time_s[0] + 0.15, truth.impact_time_s[0] + 0.18),  # 3-frame gaps mid-step
        (truth.impact_time_s[5] + 0.2, truth.impact_time_s[5] + 0.22),
    ]

    def edit(p):
        p = tw.blank(p, truth, *t_gap)
        for a, b in short:
            p = tw.blank(p, truth, a, b)
        return p

    path, _ = markers_file(tmp_path / "gap.csv", truth, edit=edit)
    trial = import_trial(path)
    check_walk(trial, truth)
    ti = truth.impact_time_s
    observed = ti[(ti < t_gap[0] - FRAME) | (ti > t_gap[1] + FRAME)]
    # every fully observed period (both impacts outside the gap and consecutive) is reported ...
    expected = [(a, b) for a, b in zip(ti[:-1], ti[1:]) if a in observed and b in observed]
    assert trial.step_period_s.size == len(expected)
    np.testing.assert_allclose(trial.step_period_s, [b - a for a, b in expected], atol=FRAME)
    # ... none across the gap, and the drop is said
    starts = trial.impact_time_s[np.isin(trial.impact_step, trial.period_step - 1)]
    for a, p in zip(starts, trial.step_period_s):
        assert a + p < t_gap[0] or a > t_gap[1]
    assert any("dropped" in w for w in trial.meta.warnings)
    # the short gaps were bridged (interpolated), the long one was not
    t = truth.time_s
    in_short = sum(((t >= a) & (t < b)).sum() for a, b in short)
    in_long = ((t >= t_gap[0]) & (t < t_gap[1])).sum()
    assert trial.meta.n_interpolated_frames == in_short
    assert trial.meta.n_gap_frames == in_long


def test_zeros_are_occlusions(tmp_path):
    truth = tw.make_truth(ending="walked")
    a, b = truth.impact_time_s[1] + 0.05, truth.impact_time_s[1] + 0.30

    def zero(p):
        p = p.copy()
        m = (truth.time_s >= a) & (truth.time_s < b)
        p[m, 1] = 0.0  # one marker written as 0,0,0 ...
        p[m & (truth.time_s < a + 0.04)] = 0.0  # ... and all of them for 4 frames
        return p

    trial = import_trial(markers_file(tmp_path / "z.csv", truth, edit=zero)[0])
    check_walk(trial, truth)
    hub = trial.series["hub"]
    assert np.nanmax(np.linalg.norm(np.diff(hub, axis=0), axis=1)) < 0.02  # no jump to the origin
    assert trial.meta.n_interpolated_frames == 4


@pytest.mark.parametrize("layout", ["objects", "trajectories", "ramp-object+markers", "object+ramp-markers"])
def test_static_ramp_is_never_the_wheel_and_gives_the_slope(tmp_path, layout):
    truth = tw.make_truth(ending="caught", slope_deg=3.1, ramp=True)
    ramp_pose = np.tile(truth.ramp_pose, (truth.time_s.size, 1))
    ramp_pose[:, 3:] = tw.noisy(ramp_pose[:, 3:], NOISE, 7)
    ramp_mk = tw.noisy(np.broadcast_to(truth.ramp_markers, (truth.time_s.size, 4, 3)), NOISE, 8)
    wheel_pose = tw.pose_of(truth, np.array([0.02, 0.01, 0.0]), NOISE, 3)
    wheel_mk = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), NOISE, 4)
    ramp_first = {"Ramp": ramp_pose}
    if layout == "objects":
        secs = [tw.objects_section({**ramp_first, "Wheel": wheel_pose})]
    elif layout == "trajectories":
        mk = {f"Ramp:R{i}": ramp_mk[:, i] for i in range(4)} | {f"wheel:M{i}": wheel_mk[:, i] for i in range(4)}
        secs = [tw.markers_section(mk)]
    elif layout == "ramp-object+markers":
        secs = [tw.objects_section(ramp_first), tw.markers_section({f"wheel:M{i}": wheel_mk[:, i] for i in range(4)})]
    else:
        secs = [
            tw.objects_section({"Wheel": wheel_pose}),
            tw.markers_section({f"R{i}": ramp_mk[:, i] for i in range(4)}),
        ]
    trial = import_trial(tw.write(tmp_path / f"{layout}.csv", *secs))
    m = trial.meta
    if layout in ("objects", "object+ramp-markers"):  # the wheel is a tracked object in these files
        assert m.object == "Wheel"
    else:
        assert m.object is None and m.markers == tuple(f"wheel:M{i}" for i in range(4))
    assert m.ramp_slope_deg == pytest.approx(3.1, abs=0.05)
    check_walk(trial, truth)


def test_only_a_static_object_is_refused_not_taken(tmp_path):
    truth = tw.make_truth(ramp=True)
    pose = np.tile(truth.ramp_pose, (truth.time_s.size, 1))
    with pytest.raises(TrialRefused, match="nothing moves like the wheel"):
        import_trial(tw.write(tmp_path / "r.csv", tw.objects_section({"Ramp": pose})))


def test_objects_and_trajectories_of_the_same_wheel(tmp_path):
    truth = tw.make_truth(ending="stalled", end_fraction=0.3)
    pts = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), NOISE, 5)
    path = tw.write(
        tmp_path / "both.csv",
        tw.objects_section({"Wheel": tw.pose_of(truth, np.array([0.0, 0.04, 0.0]), NOISE, 6)}),
        tw.markers_section({f"Wheel:M{i}": pts[:, i] for i in range(4)}),
    )
    trial = import_trial(path)
    check_walk(trial, truth)
    assert "also found" in trial.meta.source_reason


def test_unlabelled_markers_are_ignored(tmp_path):
    truth = tw.make_truth(ending="caught")
    rng = np.random.default_rng(3)
    pts = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), NOISE, 9)
    ghost = np.full((truth.time_s.size, 3), np.nan)
    ghost[100:130] = rng.uniform(-1, 1, 3) + rng.normal(0, 0.01, (30, 3))
    mk = {f"wheel:M{i}": pts[:, i] for i in range(4)} | {"2 1937": ghost, "*12": ghost[::-1]}
    trial = import_trial(tw.write(tmp_path / "u.csv", tw.markers_section(mk)))
    check_walk(trial, truth)
    assert any("unlabelled" in w for w in trial.meta.warnings)


def test_uneven_markers_com_height_within_1mm(tmp_path):
    assert tw.centroid_offset_mm(tw.UNEVEN_MARKERS) == pytest.approx(14.0, abs=0.5)
    truth = tw.make_truth(ending="caught", slope_deg=1.7)
    trial = import_trial(markers_file(tmp_path / "uneven.csv", truth)[0], leg_length_m=tw.L)
    check_walk(trial, truth)
    w = truth.walking
    err = trial.series["com_height"][w] - truth.com_height[w]
    assert np.sqrt(np.nanmean(err**2)) < 1e-3
    # the centre of rotation was found 14 mm off the centroid (in the wheel plane), and said
    off = np.asarray(trial.meta.hub_offset_m)
    assert np.linalg.norm(off) * 1e3 == pytest.approx(tw.centroid_offset_mm(tw.UNEVEN_MARKERS), abs=1.5)
    assert any("centre of rotation" in x for x in trial.meta.warnings)


def test_uneven_markers_centroid_is_the_hub_when_told(tmp_path):
    """The same file with the centroid as the hub (--hub-offset-mm 0,0,0): the hub is exactly the written
    markers' centroid (14 mm off the axle in the wheel plane), not a corrected point."""
    truth = tw.make_truth(ending="caught", slope_deg=1.7)
    path, pts = markers_file(tmp_path / "uneven.csv", truth)
    trial = import_trial(path, leg_length_m=tw.L, hub_offset_m=(0, 0, 0))
    w = truth.walking
    np.testing.assert_allclose(trial.series["hub"][w], pts[w].mean(axis=1), atol=1e-6)  # file rounding only
    assert trial.meta.hub_offset_m == (0.0, 0.0, 0.0)


def test_units_row_says_mm_but_numbers_are_metres(tmp_path):
    truth = tw.make_truth()
    pts = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), 0.3e-6, 1)
    sec = tw.section_text(
        "Trajectories",
        "100",
        [(f"w:M{i}", "", pts[:, i]) for i in range(4)],
        comps=("X", "Y", "Z"),
        units=("mm",) * 3,
        scale=(1e-3,) * 3,
    )  # metres written, mm said
    # section_text divides by scale: undo it so the numbers are metres
    lines = sec[:5] + [
        ",".join([c if i < 2 else f"{float(c) * 1e-3:.9f}" for i, c in enumerate(r.split(","))]) for r in sec[5:]
    ]
    with pytest.raises(TrialRefused) as e:
        import_trial(tw.write(tmp_path / "units.csv", lines))
    assert ":5:1:" in str(e.value) and "units row" in str(e.value) and "mm" in str(e.value)


def test_pasted_second_take(tmp_path):
    truth = tw.make_truth(ending="caught")
    pts = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), NOISE, 1)
    take = tw.markers_section({f"w:M{i}": pts[:, i] for i in range(4)})
    n = truth.time_s.size
    # (a) frame numbers restart: refused at the seam line
    path = tw.write(tmp_path / "restart.csv", take + take[5:])
    with pytest.raises(ViconCsvError) as e:
        import_trial(path)
    assert e.value.line == 5 + n + 1 and e.value.cause == "frame-order" and "second take" in str(e.value)
    # (b) frames continue, the wheel jumps back to the start: refused at the seam line, never a short "step"
    second = tw.markers_section({f"w:M{i}": pts[:, i] for i in range(4)}, first_frame=n + 1)
    path = tw.write(tmp_path / "jump.csv", take + second[5:])
    with pytest.raises(TrialRefused) as e:
        import_trial(path)
    assert f":{5 + n + 1}:1:" in str(e.value) and "second take" in str(e.value)


def test_lost_cell_is_an_error_at_its_line(tmp_path):
    truth = tw.make_truth()
    path, _ = markers_file(tmp_path / "cell.csv", truth, body=tw.EVEN_MARKERS)
    lines = Path(path).read_text().split("\n")
    cells = lines[40].split(",")
    del cells[4]  # one Y cell of the first marker: the rest would shift left
    lines[40] = ",".join(cells)
    Path(path).write_text("\n".join(lines))
    with pytest.raises(ViconCsvError) as e:
        import_trial(path)
    assert (e.value.line, e.value.cause) == (41, "missing-cell")
    assert e.value.location().startswith(f"{path}:41:")


RATE_REFUSAL_CALL_BUDGET = 5_000


@pytest.mark.parametrize("rate", ["5e-154", "1e308", "5e-324", "2.2e-308", "0", "-100", "0.5", "20000", "1e999"])
def test_absurd_rates_are_errors_at_the_rate_row(tmp_path, rate):
    truth = tw.make_truth()
    pts = tw.body_points(truth, tw.EVEN_MARKERS)
    path = tw.write(tmp_path / "rate.csv", tw.markers_section({f"w:M{i}": pts[:, i] for i in range(4)}, rate=rate))
    # refused at the rate row, before any frame is read: a small fraction of a whole import's ~24,000 calls
    with pytest.raises(ViconCsvError) as e, call_budget(RATE_REFUSAL_CALL_BUDGET):
        import_trial(path)
    assert (e.value.line, e.value.column, e.value.cause) == (2, 1, "bad-rate")


def test_errors_first_in_file_order_and_up_to_20():
    head = "Trajectories\n100\n,,A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n"
    rows = [f"{i},0,1,2,3" for i in range(1, 60)]
    for i in (7, 3, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 45, 46, 47, 48, 49, 50):
        rows[i] = f"{i + 1},0,1,x{i},3"
    with pytest.raises(ViconCsvError) as e:
        parse_vicon_text(head + "\n".join(rows) + "\n", "many.csv")
    errs = e.value.all_locations()
    assert len(errs) == 20
    assert errs[0] == "many.csv:9:4: section 'Trajectories': cell 'x3' is not a number [non-numeric]"
    assert [int(x.split(":")[1]) for x in errs] == sorted(int(x.split(":")[1]) for x in errs)


def test_non_ascii_digits_are_not_numbers():
    text = "Trajectories\n100\n,,A,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,1,\u0663,3\n"
    with pytest.raises(ViconCsvError) as e:
        parse_vicon_text(text, "arabic.csv")
    assert (e.value.line, e.value.column, e.value.cause) == (7, 4, "non-numeric")
