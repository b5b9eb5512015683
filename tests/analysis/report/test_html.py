"""Bundled SYNTHETIC dataset, comparison with the simulator, HTML report, `rimless trials report`, `rimless demo`."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import tempfile
from dataclasses import replace
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.examples.bundled import DATA_DIR, TRIALS, data_files, load_truth, simulate_trial, write_trial_csv
from rimless.analysis.inference.compare import Simulator, compare_trial, step_period_trends
from rimless.analysis.io.timeseries import Event, TimeSeries
from rimless.analysis.io.trial import Trial
from rimless.analysis.kinematics.build import import_trial
from rimless.analysis.report.html import build_report
from rimless.cli import app as root_app

runner = CliRunner()
FRAME_S = 0.01


@pytest.fixture(scope="module")
def sim():
    return Simulator()


@pytest.fixture(scope="module")
def truth():
    return load_truth()


# ------------------------------------------------------------------------------------------ bundled data


def test_bundled_dataset_files_and_labels(truth):
    files = data_files()
    assert len(files) == len(TRIALS) == 6
    assert all("SYNTHETIC" in f.name for f in files)
    assert sum(p.stat().st_size for p in DATA_DIR.iterdir()) < 1_000_000
    assert (DATA_DIR / "README.md").read_text().count("SYNTHETIC") >= 1
    assert {f.stem for f in files} == set(truth["trials"])
    assert truth["params"]["stiffness_n_per_m"] == 2700.0 and truth["params"]["leg_length_m"] == 0.237
    raw = files[0].read_bytes()
    head = raw.split(b"\r\n")[:5]  # Windows line ends
    assert head[0] == b"Objects" and head[1] == b"100"
    assert head[2].startswith(b",,Global Angle Wheel:Wheel")
    assert head[4] == b",,rad,rad,rad,mm,mm,mm"
    text = b"".join(f.read_bytes() for f in files)
    assert b"\r\n,,," in text or b",,,,,,\r\n" in text  # occlusions as empty cells
    assert any(line.count(b",") == 1 for line in text.split(b"\r\n")[5:] if line[:1].isdigit())  # short rows


@pytest.mark.parametrize("path", data_files(), ids=lambda p: p.stem)
def test_bundled_trial_imports_with_true_slope_and_periods(path, truth):
    tr = truth["trials"][path.stem]
    trial = import_trial(path, max_gap_s=0.05)
    assert abs(trial.meta.slope_deg - tr["slope_deg"]) < 0.05
    assert trial.meta.step_refused is None
    assert trial.step_period_s.size >= 5
    true_imp = np.asarray(tr["impact_time_s"]) - tr["first_frame_time_s"]  # same clock as the trial
    true_per = np.asarray(tr["step_period_s"])  # step j+1 of the simulation ends at impact j
    j = np.array([int(np.argmin(np.abs(true_imp - t))) for t in trial.impact_time_s])
    # every measured impact is the simulated one its step count says (an impact lost in a gap keeps the count)
    ks = trial.impact_step
    np.testing.assert_array_equal(j - j[0], ks - ks[0])
    assert np.all(np.abs(trial.impact_time_s - true_imp[j]) < 0.03)
    # a period is reported only when both its impacts were observed, and then within a frame of the truth
    at = {int(k): i for i, k in enumerate(ks)}
    for k, measured in zip(trial.period_step, trial.step_period_s):
        assert int(k) - 1 in at
        assert abs(measured - true_per[j[at[int(k)]]]) < FRAME_S


def test_number_format_is_printf_with_3_digit_exponents():
    from rimless.analysis.examples.bundled import format_number

    assert [format_number(v) for v in (7.2e-6, -1.5e-12, 123.45678912, 0.5, float("nan"))] == [
        "7.2e-006",
        "-1.5e-012",
        "123.4568",
        "0.5",
        "",
    ]


def test_generator_is_deterministic_per_seed():
    a = simulate_trial(2.0, 1.9, np.random.default_rng(3))
    b = simulate_trial(2.0, 1.9, np.random.default_rng(3))
    c = simulate_trial(2.0, 1.9, np.random.default_rng(4))
    np.testing.assert_array_equal(a.pose, b.pose)
    assert a.heading_deg != c.heading_deg


# ---------------------------------------------------------------------------------------------- compare


@pytest.mark.parametrize("noise_m", [0.0, 0.3e-3])
def test_compare_recovers_the_release_speed_and_noise_level(tmp_path, sim, noise_m):
    ex = simulate_trial(2.0, 1.92, np.random.default_rng(11), noise_m=noise_m, angle_noise_rad=3 * noise_m)
    trial = import_trial(write_trial_csv(ex, tmp_path / "t.csv"), slope_deg=2.0, max_gap_s=0.05)
    c = compare_trial(trial, sim)
    assert c.status == "ok", c.message
    assert abs(c.release_theta_dot_rad_s - 1.92) < 0.01
    assert abs(c.theta_dot_plus_rad_s - ex.post_impact_theta_dot_rad_s[0]) < 0.01
    assert c.n_steps >= 6 and np.all(np.abs(c.period_error_s) < 3e-3)
    assert abs(c.period_error_s[0]) < 1e-5  # what was fitted
    if noise_m == 0:
        assert c.rms_com_error_m < 0.2e-3
    else:
        assert 0.6 * noise_m < c.rms_com_error_m < 1.7 * noise_m
    m = c.metrics()
    assert m["rms_com_error_mm"] == pytest.approx(c.rms_com_error_m * 1e3)
    assert np.isfinite(c.sim_com_m[(c.time_s >= 0) & (c.time_s <= c.measured_impact_time_s[-1])]).mean() > 0.9


def test_compare_failures_are_messages(tmp_path, sim):
    ex = simulate_trial(2.0, 1.92, np.random.default_rng(2))
    trial = import_trial(write_trial_csv(ex, tmp_path / "t.csv"), max_gap_s=0.05)
    steep = Trial(trial.series, replace(trial.meta, slope_deg=40.0))
    c = compare_trial(steep, sim)
    assert c.status == "failed" and "40.000 deg cannot be simulated" in c.message
    none = Trial(TimeSeries(trial.time_s, trial.series.data, ()), replace(trial.meta, step_refused="too noisy"))
    c = compare_trial(none, sim)
    assert c.status == "failed" and "no steps detected (too noisy)" in c.message
    slow = Trial(TimeSeries(trial.time_s, trial.series.data, (Event(0.1, "impact"), Event(3.1, "impact"))), trial.meta)
    c = compare_trial(slow, sim)
    assert c.status == "failed" and "longer than any" in c.message
    groups = step_period_trends([c], sim)  # a failed fit still groups, without a simulation
    assert len(groups) == 1 and np.isnan(groups[0].sim_period_s).all() and groups[0].message


def test_step_period_trends_group_by_slope(sim):
    from rimless.analysis.inference.compare import TrialComparison

    def tc(name, slope, periods):
        return TrialComparison(
            name, name, slope, "given", "er", "ok", measured_period_s=np.asarray(periods), release_theta_dot_rad_s=1.95
        )

    groups = step_period_trends([tc("a", 1.9, [0.5, 0.4]), tc("b", 2.1, [0.7, 0.6, 0.5]), tc("c", 2.6, [0.3])], sim)
    assert [g.slope_deg for g in groups] == [2.0, 2.5]
    g = groups[0]
    np.testing.assert_allclose(g.mean_period_s, [0.6, 0.5, 0.5])
    np.testing.assert_allclose(g.std_period_s[:2], [np.std([0.5, 0.7], ddof=1)] * 2)
    assert np.isnan(g.std_period_s[2]) and list(g.count) == [2, 2, 1]
    assert np.all(np.isfinite(g.sim_period_s)) and np.all(np.diff(g.sim_period_s) < 0)  # it speeds up at 2 deg


# ----------------------------------------------------------------------------------------------- report


class _Refs(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.imgs: list[str] = []
        self.links: list[str] = []
        self.metric_rows = 0
        self._in_metrics = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a["src"])
        if tag == "a":
            self.links.append(a["href"])
        if tag == "table":
            self._in_metrics = a.get("id") == "metrics"
        if tag == "tr" and self._in_metrics and a.get("class") == "trial":
            self.metric_rows += 1


def test_report_files_and_structure(tmp_path, sim):
    files = data_files()[:3]
    pq = import_trial(files[2], max_gap_s=0.05).to_parquet(tmp_path / "third.trial.parquet")
    bad = tmp_path / "bad.csv"
    bad.write_text("Objects\n100\n,,Global Angle W:W\nFrame,Sub Frame,RX\n,,rad\n1,0,abc\n")
    res = build_report([files[0], files[1], pq, bad], tmp_path / "rep", sim=sim, import_kwargs={"max_gap_s": 0.05})
    page = res.report_html.read_text()
    refs = _Refs()
    refs.feed(page)
    trial_imgs = [f"trial-{n}.png" for n in (files[0].stem, files[1].stem, "third")]
    assert sorted(refs.imgs) == sorted(["com_height.png", "critical_slope.png", "step_period.png", *trial_imgs])
    for img in refs.imgs:  # print resolution
        from PIL import Image

        with Image.open(res.out_dir / img) as im:
            assert im.info["dpi"][0] >= 149.5
    assert "steps 2..N" in page and "Fitted per trial" in page and "time shift" in page
    for ref in refs.imgs + [r for r in refs.links if not r.startswith("#")]:  # anchors: test_report_page.py
        assert not ref.startswith(("/", "http")) and (res.out_dir / ref).stat().st_size > 500
    assert refs.metric_rows == 4
    assert [r.status for r in res.inputs] == ["imported", "imported", "read", "refused"]
    assert str(bad) in res.inputs[3].reason and "line 6" in res.inputs[3].reason
    assert "bad.csv" in page and str(bad) not in page  # by name: no folder of this machine in the report
    with open(res.metrics_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["status"] for r in rows] == ["ok", "ok", "ok", "refused"]
    assert all(float(r["rms_com_error_mm"]) < 1.5 for r in rows[:3])
    assert "<script" not in page and "http" not in page


def test_report_missing_file_is_named_before_any_work(tmp_path, sim):
    from rimless.errors import InputFileError

    with pytest.raises(InputFileError, match="nope.csv: no such file"):
        build_report([data_files()[0], tmp_path / "nope.csv"], tmp_path / "rep", sim=sim)
    assert not (tmp_path / "rep").exists()


# -------------------------------------------------------------------------------------------------- CLI


def test_cli_report_json_with_a_refused_file(tmp_path):
    bad = tmp_path / "empty.csv"
    bad.write_text("")
    res = runner.invoke(
        root_app, ["trials", "report", str(data_files()[0]), str(bad), "--out", str(tmp_path / "o"), "--json"]
    )
    assert res.exit_code == 2
    out = json.loads(res.stdout)
    assert out["report"].endswith("report.html") and Path(out["report"]).is_file()
    assert out["refused"] == [str(bad)]
    assert [t["status"] for t in out["trials"]] == ["ok", "refused"]
    assert str(bad) in out["trials"][1]["message"]


def test_cli_report_missing_file(tmp_path):
    res = runner.invoke(root_app, ["trials", "report", str(tmp_path / "gone.parquet"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "error:" in res.output and "gone.parquet: no such file" in res.output


def test_cli_report_bad_model(tmp_path):
    res = runner.invoke(root_app, ["trials", "report", str(data_files()[0]), "--out", str(tmp_path), "--model", "x"])
    assert res.exit_code == 2 and "--model must be one of er, ve" in res.output


@pytest.mark.xdist_group("demo")  # one worker reads the demo; the other never waits on its lock
@pytest.mark.slow
def test_demo(demo_run, tmp_path):
    from rimless.analysis.examples.critical_series import data_files as critical_files
    from rimless.analysis.examples.critical_series import load_truth as critical_truth

    out = demo_run.out
    assert demo_run.returncode == 0, demo_run.stderr[-3000:]
    assert (out / "report.html").is_file() and (out / "metrics.csv").is_file()
    assert f"report: {Path('rimless-demo') / 'report.html'}" in demo_run.stdout  # relative to where it ran
    page = (out / "report.html").read_text()
    n_all = len(set(data_files()) | set(critical_files()))
    assert "SYNTHETIC DATA" in page and page.count('<tr class="trial">') == n_all
    with open(out / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == n_all
    assert all(r["status"] == "ok" for r in rows if "_er_" in r["trial"])
    # the printed table at the README's 80 columns: every number of metrics.csv whole on its trial's line
    from tests.support.printed_table import parse_table

    printed, prefix = parse_table(demo_run.stdout)
    assert len(printed) == n_all
    for (name, cells), r in zip(printed, rows):
        assert (prefix or "") + name == r["trial"].removesuffix(".csv")
        for key, fmt in (("slope_deg", ".3f"), ("rms_com_error_mm", ".2f"), ("theta_dot_plus_rad_s", ".3f")):
            if r[key]:
                assert format(float(r[key]), fmt) in cells, (key, r[key], cells)
    # the two series stay apart; every trial has its section; no folder of this machine on the page
    assert {r["series"] for r in rows} == {"SYNTHETIC_er", "SYNTHETIC_crit"}
    assert page.count('<section class="trial"') == n_all
    assert str(out.resolve().parent) not in page and str(Path.cwd()) not in page
    # the critical slope: printed, on the page, and near the truth model's
    crit = critical_truth()["dataset"]["critical_slope_deg"]
    line = next(ln for ln in demo_run.stdout.splitlines() if ln.startswith("critical slope from the trials:"))
    value = float(line.split(":")[1].split("deg")[0])
    assert abs(value - crit) < 0.1, line
    assert "model critical slope, ER:" in demo_run.stdout and "calibrated c:" in demo_run.stdout
    # the series' truth has guide friction the model lacks: c is never claimed identifiable as the leg's damping
    c_line = next(ln for ln in demo_run.stdout.splitlines() if ln.startswith("calibrated c:"))
    assert "NOT identifiable" in c_line
    assert (
        "constant loss per step" in c_line or "c against a constant loss per step (guide friction):" in demo_run.stdout
    ), demo_run.stdout
    assert 'id="loss-separation"' in page
    assert 'id="critical-values"' in page and "critical_slope.png" in page and "Calibration" in page
    refs = _Refs()
    refs.feed(page)
    assert "critical_slope.png" in refs.imgs
    for img in refs.imgs:  # every figure the page shows exists, decodes, at print resolution
        from PIL import Image

        with Image.open(out / img) as im:
            im.load()
            assert im.info["dpi"][0] >= 149.5 and im.size[0] > 800
    if shutil.which("chromium") or shutil.which("chromium-browser"):
        _screenshot_has_content(out / "report.html", tmp_path / "shot.png")


@pytest.mark.xdist_group("demo")  # one worker reads the demo; the other never waits on its lock
@pytest.mark.slow
def test_demo_step_periods_never_pool_a_stall_with_a_walk(demo_run):
    """The demo's ``release1.9`` bin pooled two trials that stalled with one that walked (session 22: after step 2
    only the walker was drawn). The periods table names how each bin's trials ended, and the critical series'
    ``release1.9`` rows have stalled and walked bins apart."""
    import re

    from rimless.analysis.kinematics.walk import OUTCOMES

    assert demo_run.returncode == 0, demo_run.stderr[-3000:]
    page = (demo_run.out / "report.html").read_text()
    table = page.split('<table id="periods">', 1)[1].split("</table>", 1)[0]
    assert "<th>ended</th>" in table
    rows = [
        [re.sub(r"<[^>]+>", "", cell) for cell in re.findall(r"<td[^>]*>(.*?)</td>", row)]
        for row in re.findall(r"<tr>(.*?)</tr>", table.split("<tbody>", 1)[1])
    ]
    assert rows and all(r[2] in OUTCOMES for r in rows), {r[2] for r in rows}
    crit = {r[2] for r in rows if r[0].startswith("SYNTHETIC_crit") and r[1] == "release1.9"}
    assert {"stalled", "walked"} <= crit, crit


def _screenshot_has_content(page: Path, shot: Path) -> None:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run(
            [
                exe,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                f"--user-data-dir={profile}",
                f"--screenshot={shot}",
                "--window-size=1200,2000",
                page.resolve().as_uri(),
            ],
            check=True,
            capture_output=True,
            timeout=120,
        )
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[0] >= 1000 and img.shape[1] >= 1000
    rows_with_ink = (img[..., :3].std(axis=(1, 2)) > 0.02).mean()
    assert rows_with_ink > 0.3  # text and figures, not a blank page


@pytest.mark.skipif(not (shutil.which("chromium") or shutil.which("chromium-browser")), reason="chromium not installed")
def test_report_renders_in_chromium(tmp_path, sim):
    res = build_report(data_files()[:2], tmp_path / "rep", sim=sim, import_kwargs={"max_gap_s": 0.05})
    _screenshot_has_content(res.report_html, tmp_path / "shot.png")


def test_flat_line_cannot_pass_and_first_step_is_left_out(tmp_path, sim):
    """A measured CoM that does not move like a wheel (a flat line + noise) is suspect, never ok; the first
    period (fitted) does not enter the period error."""
    ex = simulate_trial(2.0, 1.92, np.random.default_rng(5))
    trial = import_trial(write_trial_csv(ex, tmp_path / "t.csv"), slope_deg=2.0, max_gap_s=0.05)
    good = compare_trial(trial, sim)
    assert good.status == "ok" and good.com_correlation > 0.95 and good.rms_com_relative < 0.1
    np.testing.assert_allclose(good.mean_abs_period_error_s, np.mean(np.abs(good.period_error_s[1:])))
    y = np.asarray(trial.series["com_height"], float)
    flat = np.where(np.isfinite(y), np.nanmean(y) + np.random.default_rng(1).normal(0, 0.3e-3, y.size), np.nan)
    data = dict(trial.series.data)
    data["com_height"] = flat
    bad = Trial(TimeSeries(trial.time_s, data, trial.series.events), trial.meta)
    c = compare_trial(bad, sim)
    assert c.status == "suspect", (c.com_correlation, c.rms_com_relative)
    assert "correlate" in c.message or "amplitude" in c.message
    assert c.metrics()["status"] == "suspect"
