"""`rimless trials floquet` / `rimless.analysis.floquet`: the trials' step-to-step multiplier, its noise bias
corrected, beside the model's eigenvalue.

Expectations from outside the code under test: an AR(1) sequence with known slope and known measurement noise
(the attenuation of the plain regression is the reliability ratio, a closed form); the rigid wheel of
`rimless.analysis.validation.floquet_truth` (written apart: its multiplier is beta^2 exactly); and the ER wheel with
parameters away from Table 1, walking on per-step random slopes, recorded as Vicon Tracker exports with noise
and imported by the real importer (its multiplier is the model's eigenvalue the command prints beside).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.analysis.inference.floquet import NotIdentifiable, estimate_multiplier
from rimless.analysis.validation.floquet_truth import RigidWheel, er_walk, record, rigid_multiplier, rigid_walk
from tests.support.cli_lines import stderr_lines

runner = CliRunner()

#: the ER truth wheel: leg stiffness and damping away from Table 1 (2700 N/m, 8 N s/m)
ER_K, ER_C, ER_SLOPE_DEG = 2000.0, 14.0, 2.5


def _ar1(a: float, n: int, noise_sd: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A stationary AR(1) sequence (unit process noise) and its measurements."""
    x = np.empty(n + 1)
    x[0] = rng.normal(0, 1 / math.sqrt(1 - a * a))
    for k in range(n):
        x[k + 1] = a * x[k] + rng.normal()
    return x, x + rng.normal(0, noise_sd, x.size)


def test_the_correction_removes_the_regressions_attenuation() -> None:
    """With a known noise variance the corrected slope is unbiased, while the plain regression shrinks by the
    reliability ratio var(x) / (var(x) + var(u)) (errors in variables: a closed form)."""
    rng = np.random.default_rng(0)
    a, sd = 0.7, 0.8
    reliability = (1 / (1 - a * a)) / (1 / (1 - a * a) + sd * sd)
    corrected, ols, lagged = [], [], []
    for _ in range(60):
        _, m = _ar1(a, 800, sd, rng)
        e = estimate_multiplier(m[:-1], m[1:], np.full(800, sd * sd), (m[:-2], m[1:-1], m[2:]))
        corrected.append(e.multiplier)
        ols.append(e.ols)
        lagged.append(e.lagged)
    assert np.mean(ols) == pytest.approx(a * reliability, abs=0.015)  # 0.53: the bias the correction removes
    assert np.mean(corrected) == pytest.approx(a, abs=0.015)
    assert np.mean(lagged) == pytest.approx(a, abs=0.02)


def test_the_corrected_interval_covers_an_ar1_at_the_trials_length() -> None:
    """45 pairs (three trials of 15 impacts), reliability about 0.85: the 95 % interval holds the truth in 90-99 %
    of 300 sequences (binomial sd 1.3 %)."""
    rng = np.random.default_rng(1)
    a, sd, hits = 0.75, 0.6, 0
    for _ in range(300):
        _, m = _ar1(a, 45, sd, rng)
        e = estimate_multiplier(m[:-1], m[1:], np.full(45, sd * sd))
        hits += e.ci95[0] <= a <= e.ci95[1]
    assert 0.90 <= hits / 300 <= 0.99, hits


def test_no_estimate_without_wander_or_pairs() -> None:
    rng = np.random.default_rng(2)
    with pytest.raises(NotIdentifiable, match="too short: 5 pairs"):
        estimate_multiplier(rng.normal(size=5), rng.normal(size=5), np.full(5, 0.01))
    x = 2.0 + rng.normal(0, 0.01, 40)  # a walk at its gait: the spread is the noise alone
    with pytest.raises(NotIdentifiable, match="does not wander beyond the measurement noise"):
        estimate_multiplier(x[:-1], x[1:], np.full(39, 1e-4))


def _import(path):
    from rimless.analysis import import_trial

    return import_trial(path)


def test_section_points_follow_the_rigid_truths_post_impact_speed(tmp_path) -> None:
    """Each impact's section point follows the truth's post-impact speed: a smooth function of it (the fitted
    quadratic's slope reads a few % low: the stance's angular acceleration changes over the window; a smooth
    function of the state leaves the multiplier unchanged) plus noise of the stated size."""
    from rimless.analysis.inference.floquet import section_points

    rng = np.random.default_rng(3)
    wheel = RigidWheel()
    walk = rigid_walk(wheel, 4.5, 0.8, 20, rng)
    pts = section_points(_import(record(walk, tmp_path / "rigid.csv", rng)), "rigid.csv")
    assert pts.status == "used", pts.reason
    ok = np.isfinite(pts.speed_rad_s)
    assert ok.sum() >= 18
    truth = walk.post_impact_speed[pts.step[ok] - pts.step[0]]
    measured, sd = pts.speed_rad_s[ok], np.sqrt(pts.var_rad2_s2[ok])
    slope, offset = np.polyfit(truth, measured, 1)
    assert 0.9 < slope < 1.2 and abs(np.median(measured / truth) - 1) < 0.1
    z = (measured - (slope * truth + offset)) / sd
    assert 0.6 < np.std(z) < 1.6, z  # the stated noise is the noise (1 sigma)


def test_the_rigid_truths_multiplier_beta_squared_is_inside(tmp_path) -> None:
    """Three trials of the rigid truth (15 impacts, per-step slope sd 0.8 deg, released 5 % off the gait):
    the 95 % interval holds beta^2 (0.634), the closed form of the truth, not of the code."""
    from rimless.analysis import floquet

    rng = np.random.default_rng(4)
    wheel = RigidWheel()
    files = []
    for i, rel in enumerate((0.95, 1.0, 1.05)):
        walk = rigid_walk(wheel, 4.5, 0.8, 15, rng, start=rel * wheel.fixed_point(4.5))
        files.append(record(walk, tmp_path / f"rigid{i}.csv", rng))
    res = floquet(files, with_model=False)
    (g,) = res.groups
    assert g["status"] == "estimated" and g["pairs"] >= 28, (g, res.trials)
    assert g["ci95"][0] <= rigid_multiplier(wheel) <= g["ci95"][1], g
    assert g["model"]["eigenvalue"] is None and g["model_inside_ci95"] is None


@pytest.fixture(scope="module")
def er_files(tmp_path_factory):
    from rimless.sim.model.params import WheelParams

    rng = np.random.default_rng(5)
    where = tmp_path_factory.mktemp("floquet_er")
    params = WheelParams(stiffness_n_per_m=ER_K, damping_ns_per_m=ER_C)
    files = []
    for i, rel in enumerate((0.95, 1.03, 1.08)):
        walk = er_walk(params, ER_SLOPE_DEG, 0.6, 15, rng, release=rel)
        files.append(record(walk, where / f"er_wander_{i}.csv", rng))
    toml = where / "wheel.toml"
    toml.write_text(f"[wheel]\nk = {{value = {ER_K}, sd = 100}}\nc = {{value = {ER_C}, sd = 2}}\n")
    return files, toml


def test_the_interval_covers_the_er_models_eigenvalue(er_files) -> None:
    """The acceptance: on trials of an ER wheel away from Table 1 the trials' interval holds the model's
    eigenvalue at the wheel's parameters; the parameters are listed with their source."""
    from rimless.analysis import floquet
    from rimless.sim import Wheel

    files, toml = er_files
    res = floquet(files, Wheel(toml))
    (g,) = res.estimated
    assert g["model_inside_ci95"] is True, g
    assert g["ci95"][0] <= g["model"]["eigenvalue"] <= g["ci95"][1]
    assert 0.6 < g["model"]["eigenvalue"] < 0.85  # the ER wheel's dominant eigenvalue (the other is about 0.07)
    srcs = {p["symbol"]: p["source"] for p in res.to_dict()["parameters"]}
    assert srcs["k"] == "wheel_file" and srcs["I_c"] == "table1"
    c = {r["symbol"]: r["contribution"] for r in g["model"]["contributions"]}
    assert c["k"] > 0 and c["phi"] > 0 and "g" not in c  # g is exact (sd 0): not held with an uncertainty
    assert "FloquetResult(3 trial(s)" in repr(res) and "<table" in res._repr_html_()
    assert res.to_frame().shape[0] == 1


def test_the_command_prints_the_apis_object(er_files) -> None:
    from rimless.analysis import floquet
    from rimless.cli import app
    from rimless.sim import Wheel

    files, toml = er_files
    res = runner.invoke(app, ["trials", "floquet", *map(str, files), "--params", str(toml), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == json.loads(json.dumps(floquet(files, Wheel(toml)).to_dict()))
    text = runner.invoke(app, ["trials", "floquet", *map(str, files), "--params", str(toml)])
    assert text.exit_code == 0, text.output
    assert "k = 2000 ± 100 N/m  (wheel_file" in text.stdout and "95 %" in text.stdout


def test_vicon_exports_are_imported_with_the_wheel(er_files) -> None:
    """`floquet(paths, wheel)` (and so `trials floquet --params`, which prints the API's object) imports with the
    wheel: the group's slope sd is that of the trials imported with it (its legs' k bounds the slope's drift)
    and narrower than that of the trials imported without it (the importer's 45 ms bound)."""
    from rimless.analysis import floquet
    from rimless.analysis.kinematics.build import import_trial
    from rimless.sim import Wheel

    files, toml = er_files
    wheel = Wheel(toml)
    (paths,) = floquet(files, wheel, with_model=False).estimated
    (told,) = floquet([import_trial(f, wheel=wheel) for f in files], wheel, with_model=False).estimated
    (blind,) = floquet([import_trial(f) for f in files], wheel, with_model=False).estimated
    assert paths["slope_sd_deg"] == told["slope_sd_deg"] < blind["slope_sd_deg"], (paths, told, blind)
    assert paths["multiplier"] == pytest.approx(told["multiplier"], rel=1e-9)


def test_short_and_transient_only_trials_are_flagged(tmp_path) -> None:
    """A trial of two impacts is too short; a release far above the gait on an even slope (no wander) decays
    the same way every step: transient-only. Neither is fitted; with nothing left the command exits 1."""
    from rimless.cli import app

    rng = np.random.default_rng(6)
    wheel = RigidWheel()
    short = record(rigid_walk(wheel, 4.5, 0.8, 2, rng), tmp_path / "short.csv", rng)
    fast = 1.5 * wheel.fixed_point(4.5)
    transient = record(rigid_walk(wheel, 4.5, 0.0, 7, rng, start=fast), tmp_path / "transient.csv", rng)
    res = runner.invoke(app, ["trials", "floquet", short, transient, "--json"])
    assert res.exit_code == 1, res.output
    out = json.loads(res.stdout)
    by = {r["file"]: r for r in out["trials"]}
    assert by["short.csv"]["status"] == "flagged" and by["short.csv"]["reason"].startswith("too short")
    assert by["transient.csv"]["status"] == "flagged" and "transient-only" in by["transient.csv"]["reason"]
    assert all(g["status"] == "not_estimated" for g in out["groups"])
    (line,) = stderr_lines(res.stderr)
    assert line.startswith("error: no multiplier from the trials:")


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--model", "rigid"], "--model"),
        (["--group-tol-deg", "-1"], "--group-tol-deg"),
        (["--params", "x.toml"], "--params"),
    ],
)
def test_bad_options_are_one_error_line(args, names, er_files) -> None:
    from rimless.cli import app

    files, _ = er_files
    res = runner.invoke(app, ["trials", "floquet", str(files[0]), *args])
    assert res.exit_code == 2, res.output
    assert names in res.output and "Traceback" not in res.output


@pytest.mark.slow
def test_calibrated_c_is_fitted_on_the_trials_and_carried(er_files) -> None:
    """`--calibrated`: c is calibrated on the trials (source `fitted`), its standard error enters the model's
    interval like a held parameter's; the eigenvalue then comes from a fitted wheel, said so in the output."""
    from rimless.analysis import floquet
    from rimless.cli import app

    files, _ = er_files
    res = floquet(files, calibrate_c=True)
    cal = res.calibration
    assert cal is not None and cal["calibrated"] and cal["fit"] == ["c"], cal
    (c,) = [p for p in res.parameters if p["symbol"] == "c"]
    assert c["source"] == "fitted" and c["value"] == cal["c_ns_per_m"] and c["sd"] == cal["se_ns_per_m"] > 0
    (g,) = res.estimated
    rows = {r["symbol"]: r for r in g["model"]["contributions"]}
    assert rows["c"]["note"].startswith("fitted") and rows["c"]["contribution"] > 0
    text = runner.invoke(app, ["trials", "floquet", *map(str, files), "--calibrated"])
    assert text.exit_code == 0, text.output
    assert "c calibrated on these trials" in text.stdout
