"""Leg-test priors in the whole-walk calibration (`trials calibrate --prior leg.json`): reading the leg-fit JSON,
the use of each prior, the penalty rows against a ridge with a closed form, and the c-k ridge of the real
calibration removed (its intervals narrow) on trials of a known ER wheel."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from rimless.analysis.inference.identifiability import least_squares_report
from rimless.analysis.inference.priors import Z95, read_priors
from rimless.errors import InputFileError
from rimless.sim.model.params import WheelParams


def _leg_json(path: Path, k=(2650.0, 2600.0, 2700.0), c=(7.5, 7.3, 7.7), f=(0.4, 0.35, 0.45)) -> Path:
    data = {
        "leg": 2,
        "k_n_per_m": k[0],
        "k_n_per_m_ci": [k[1], k[2]],
        "c_n_s_per_m": c[0],
        "c_n_s_per_m_ci": [c[1], c[2]],
        "guide_friction_n": f[0],
        "guide_friction_n_ci": [f[1], f[2]],
    }
    path.write_text(json.dumps(data))
    return path


def test_reads_mean_and_sd_from_the_interval(tmp_path: Path) -> None:
    pri = read_priors(_leg_json(tmp_path / "leg.json"))
    by = {p.key: p for p in pri.priors}
    assert by["k_n_per_m"].mean == 2650.0 and by["k_n_per_m"].sd == pytest.approx(50.0 / Z95)
    assert by["c_n_s_per_m"].field == "damping_ns_per_m" and by["guide_friction_n"].sd == pytest.approx(0.05 / Z95)
    assert pri.leg == 2


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("{", "not JSON"),
        ("[]", "JSON object"),
        ("{}", "none of the fields"),
        ('{"k_n_per_m": 2600}', "'k_n_per_m_ci'"),
        ('{"k_n_per_m": 2600, "k_n_per_m_ci": [2700, 2500]}', "lo < hi"),
        ('{"k_n_per_m": 2900, "k_n_per_m_ci": [2500, 2700]}', "outside its interval"),
        ('{"k_n_per_m": null, "k_n_per_m_ci": [2500, 2700]}', "'k_n_per_m'"),
    ],
)
def test_bad_prior_file_names_the_file_and_field(tmp_path: Path, text: str, named: str) -> None:
    p = tmp_path / "leg.json"
    p.write_text(text)
    with pytest.raises(InputFileError, match=named) as err:
        read_priors(p)
    assert "--prior" in str(err.value) and str(p) in str(err.value)


def test_plan_penalises_fitted_fixes_unfitted_and_reports_the_rest(tmp_path: Path) -> None:
    pri = read_priors(_leg_json(tmp_path / "leg.json"))
    base = WheelParams()
    wheel = pri.plan(base, ["damping_ns_per_m"])
    use = {p.key: p.use for p in pri.priors}
    assert use["c_n_s_per_m"] == "penalty"
    assert use["k_n_per_m"] == "fixed" and wheel.stiffness_n_per_m == 2650.0  # k from the leg test
    assert wheel.damping_ns_per_m == base.damping_ns_per_m  # c still starts at Table 1
    if hasattr(base, "guide_friction_n"):  # the wheel model has guide friction (issue 22, part 2)
        assert use["guide_friction_n"] == "fixed" and wheel.guide_friction_n == 0.4
    else:
        assert use["guide_friction_n"] == "not used by the walk model"
    rep = pri.report(None, ["damping_ns_per_m"], ["c"])
    rows = {r["key"]: r for r in rep["parameters"]}
    assert rows["k_n_per_m"]["source"].startswith("leg test (fixed")
    if not hasattr(base, "guide_friction_n"):
        assert "not used by the walk model" in rows["guide_friction_n"]["source"]


def test_penalty_rows_remove_an_exact_ridge_with_the_closed_form_uncertainty(tmp_path: Path) -> None:
    """Residuals that see only c - k / 1000 (a perfect ridge): flat without the prior; with a prior on k of sd s_k
    the posterior sd of k is s_k and that of c is sqrt(s_data^2 + (s_k / 1000)^2) (linear Gaussian algebra)."""
    pri = read_priors(_leg_json(tmp_path / "leg.json"))
    pri.plan(WheelParams(), ["damping_ns_per_m", "stiffness_n_per_m"])
    glob = SimpleNamespace(x0=np.array([8.0, 2700.0]), scale=np.array([8.0, 2700.0]))
    x_t = np.linspace(0, 1, 50)
    sd_data = 0.02  # each residual has unit sd after scaling by it

    class Obj:
        def fun(self, u: np.ndarray) -> np.ndarray:
            c, k = glob.x0 + u[:2] * glob.scale
            return ((c - k / 1000.0) - (7.5 - 2.65)) * (1 + x_t) / sd_data

        def jac(self, u: np.ndarray, central: bool = False) -> np.ndarray:
            col = (1 + x_t) / sd_data
            return np.column_stack([col * glob.scale[0], -col / 1000.0 * glob.scale[1]])

    obj = Obj()
    se0, _, ok0, _ = least_squares_report(obj.jac(np.zeros(2)), 2, glob.scale)
    assert not any(ok0)  # the ridge: neither is identifiable from the data alone
    pri.attach(obj, glob)
    J = obj.jac(np.zeros(2))
    assert J.shape == (x_t.size + 2, 2)  # one penalty row per fitted prior
    se, corr, ok, _ = least_squares_report(J, 2, glob.scale)
    assert all(ok)
    s_k = next(p.sd for p in pri.priors if p.key == "k_n_per_m")
    s_c = next(p.sd for p in pri.priors if p.key == "c_n_s_per_m")
    # the closed form: information on d = c - k/1000 from the data, plus both priors
    i_d = float(np.sum(((1 + x_t) / sd_data) ** 2))
    F = np.array([[i_d + s_c**-2, -i_d / 1000], [-i_d / 1000, i_d / 1e6 + s_k**-2]])
    cov = np.linalg.inv(F)
    assert se[0] == pytest.approx(math.sqrt(cov[0, 0]), rel=1e-9)
    assert se[1] == pytest.approx(math.sqrt(cov[1, 1]), rel=1e-9)
    r = obj.fun(np.zeros(2))
    assert r.size == x_t.size + 2
    i_k = [p.key for p in pri.penalties].index("k_n_per_m")
    assert r[x_t.size + i_k] == pytest.approx((2700.0 - 2650.0) / s_k)


@pytest.fixture(scope="module")
def ck_trials():
    from tests.support.analysis_sim_truth import sim_trial

    truth = WheelParams(damping_ns_per_m=12.0, stiffness_n_per_m=2200.0)
    rng = np.random.default_rng(19)
    # walks with the noise of a real capture (1.5 mm on the CoM height, 3 ms on the impact times): on their own they
    # see c and k mostly along the ridge
    return truth, [
        sim_trial(truth, s, w, rng, name=f"er_{s}deg_{w}", noise_m=1.5e-3, timing_noise_s=3e-3, n_steps=7)
        for s, w in ((1.8, 1.9), (2.4, 2.4), (3.0, 1.9), (2.2, 2.2))
    ]


@pytest.mark.slow
def test_prior_removes_the_c_k_ridge_of_the_walk_fit(ck_trials, tmp_path: Path) -> None:
    """c and k fitted on four walks of a known wheel: on the ridge without the prior (correlation 0.9); with a
    leg-test prior as precise as three releases give (k +- 0.5 %, c +- 1.1 %, 95 %: test_leg_fit) both intervals
    narrow, the correlation falls below 0.5, and the truth stays inside."""
    from rimless.analysis.inference.calibrate import calibrate

    truth, trials = ck_trials
    names = [t.meta.source_file for t in trials]
    free = calibrate(trials, names, ["c", "k"], max_rounds=2)
    # the walks' truth has no guide friction, and a leg test of that wheel would measure none: the walk model
    # takes an unfitted leg-test value as fixed, so a friction here would be a different wheel
    pri = read_priors(
        _leg_json(tmp_path / "leg.json", k=(2200.0, 2189.0, 2211.0), c=(12.0, 11.87, 12.13), f=(0.0, 0.0, 0.02))
    )
    wheel = pri.plan(WheelParams(), ["damping_ns_per_m", "stiffness_n_per_m"])
    held = calibrate(trials, names, ["c", "k"], params=wheel, max_rounds=2, prior=pri)
    width = {p.name: p.ci95[1] - p.ci95[0] for p in free.params}
    width_p = {p.name: p.ci95[1] - p.ci95[0] for p in held.params}
    print(
        f"95 % widths without / with the prior: c {width['c']:.3f} / {width_p['c']:.3f} N s/m, "
        f"k {width['k']:.1f} / {width_p['k']:.1f} N/m; correlation {free.correlation[0, 1]:+.3f} / "
        f"{held.correlation[0, 1]:+.3f}"
    )
    assert width_p["c"] < width["c"] and width_p["k"] < width["k"]
    assert abs(free.correlation[0, 1]) > 0.8 and abs(held.correlation[0, 1]) < 0.5
    for p in held.params:
        lo, hi = p.ci95
        assert lo <= getattr(truth, p.field) <= hi
        assert p.identifiable
    rep = pri.report(held, ["damping_ns_per_m", "stiffness_n_per_m"], ["c", "k"])
    rows = {r["key"]: r for r in rep["parameters"]}
    assert rows["k_n_per_m"]["use"] == rows["c_n_s_per_m"]["use"] == "penalty"
    assert 0.0 < rows["k_n_per_m"]["leg_test_share"] <= 1.0
    assert "conflict" not in rows["k_n_per_m"] and "conflict" not in rows["c_n_s_per_m"]  # same wheel
    assert rep["from_walks_only"] == []


def test_report_flags_walks_that_disagree_with_the_leg_test(tmp_path: Path) -> None:
    pri = read_priors(_leg_json(tmp_path / "leg.json"))
    pri.plan(WheelParams(), ["damping_ns_per_m", "stiffness_n_per_m"])
    s_c = next(p.sd for p in pri.priors if p.key == "c_n_s_per_m")
    est = [
        SimpleNamespace(field="damping_ns_per_m", value=7.5 + 5 * s_c, se=s_c / 2, se_model=s_c / 2),
        SimpleNamespace(field="stiffness_n_per_m", value=2650.0, se=200.0, se_model=200.0),
    ]
    rep = pri.report(SimpleNamespace(params=est), ["damping_ns_per_m", "stiffness_n_per_m"], ["c", "k"])
    rows = {r["key"]: r for r in rep["parameters"]}
    assert rows["c_n_s_per_m"]["prior_z"] == pytest.approx(5.0) and "disagree" in rows["c_n_s_per_m"]["conflict"]
    assert (
        rows["c_n_s_per_m"]["leg_test_share"] == pytest.approx(0.25)
        and rows["c_n_s_per_m"]["source"] == "leg test and walks"
    )
    k_share = (next(p.sd for p in pri.priors if p.key == "k_n_per_m") / 200.0) ** -2
    assert rows["k_n_per_m"]["leg_test_share"] == pytest.approx(min(k_share, 1.0))
    assert "conflict" not in rows["k_n_per_m"]


@pytest.mark.slow
def test_calibrate_command_reports_which_parameters_came_from_the_leg_test(tmp_path: Path) -> None:
    """`trials calibrate --fit c --prior leg.json` on two bundled walks (Table 1 wheel): c fitted with the leg
    test's prior, k and the guide friction fixed at the leg test's values (the bundled walks' truth has no
    friction, so the leg test measures none)."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[3]
    leg = _leg_json(tmp_path / "leg.json", k=(2700.0, 2680.0, 2720.0), c=(8.0, 7.85, 8.15), f=(0.0, 0.0, 0.02))
    csvs = sorted(str(p) for p in (root / "analysis" / "data").glob("SYNTHETIC_er_slope2.0deg_run*.csv"))
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "rimless",
            "trials",
            "calibrate",
            *csvs,
            "--fit",
            "c",
            "--prior",
            str(leg),
            "--no-critical",
            "--json",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, "COLUMNS": "80"},
    )
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout)
    rows = {r["key"]: r for r in out["prior"]["parameters"]}
    assert rows["c_n_s_per_m"]["use"] == "penalty" and 0 < rows["c_n_s_per_m"]["leg_test_share"] <= 1
    assert rows["k_n_per_m"]["use"] == "fixed" and rows["k_n_per_m"]["source"].startswith("leg test")
    if hasattr(WheelParams(), "guide_friction_n"):
        assert rows["guide_friction_n"]["use"] == "fixed"
    else:
        assert rows["guide_friction_n"]["use"] == "not used by the walk model"
    c = out["params"][0]
    assert c["name"] == "c" and c["identifiable"] and c["ci95"][0] < c["estimate"] < c["ci95"][1]
    assert rows["c_n_s_per_m"]["calibrated"] == c["estimate"]
    assert rows["c_n_s_per_m"]["prior_z"] == pytest.approx((c["estimate"] - 8.0) / (0.15 / Z95))
    assert out["prior"]["from_walks_only"] == []
