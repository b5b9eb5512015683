"""Calibration that says whether it converged and how uncertain it is: the sandwich against a closed form, c and
k recovered from trials of a known ER wheel (c = 12 N s/m, k = 2200 N/m; Table 1 has 8 and 2500)."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.inference import calibrate as cal
from tests.support.analysis_sim_truth import sim_trial


def test_sandwich_matches_the_closed_form_of_a_one_parameter_regression():
    """y = a x + e with one row per cluster: var(a) = sum x^2 r^2 / (sum x^2)^2 * n / (n - 1) (HC0 with the
    small-sample factor); rows grouped two per cluster add the cross terms."""
    rng = np.random.default_rng(4)
    x = rng.normal(size=12)
    r = rng.normal(size=12) * (1 + np.abs(x))  # heteroscedastic residuals
    J = x[:, None]
    se = cal.sandwich_se(J, r, np.arange(13), 1, np.ones(1))
    ref = np.sqrt(np.sum(x**2 * r**2) / np.sum(x**2) ** 2 * 12 / 11)
    assert se[0] == pytest.approx(ref, rel=1e-12)
    offs = np.arange(0, 13, 2)
    se2 = cal.sandwich_se(J, r, offs, 1, np.ones(1))
    g = (x * r).reshape(6, 2).sum(axis=1)
    ref2 = np.sqrt(np.sum(g**2) / np.sum(x**2) ** 2 * 6 / 5)
    assert se2[0] == pytest.approx(ref2, rel=1e-12)
    assert np.isnan(cal.sandwich_se(J, r, np.array([0, 12]), 1, np.ones(1))[0])  # one trial: no sandwich


def test_not_converged_is_never_identifiable():
    glob = cal._Globals.of(__import__("rimless.sim.model.params", fromlist=["WheelParams"]).WheelParams(), ["c"])
    est = cal._estimates(glob, ["c"], np.array([11.0]), np.array([0.1]), [True], [""], np.array([0.2]), converged=False)
    assert not est[0].identifiable and "did not converge" in est[0].note
    assert est[0].se == pytest.approx(0.2)  # the larger of model-based and sandwich
    est = cal._estimates(glob, ["c"], np.array([11.0]), np.array([0.1]), [True], [""], np.array([8.0]))
    assert not est[0].identifiable and "hardly constrain" in est[0].note  # wide interval: not identifiable
    d = est[0].as_dict()
    assert d["value"] is None and d["se_sandwich"] == 8.0 and d["ci95_linear"][0] < 0 < d["ci95_linear"][1]
    assert d["ci95"][0] == 0.0 < d["ci95"][1] and d["ci_at_bound"]  # c >= 0: the interval is cut there


@pytest.fixture(scope="module")
def ck_trials():
    from rimless.sim.model.params import WheelParams

    truth = WheelParams(damping_ns_per_m=12.0, stiffness_n_per_m=2200.0)
    rng = np.random.default_rng(19)
    return truth, [sim_trial(truth, s, w, rng, name=f"er_{s}deg_{w}") for s in (1.8, 2.2, 2.6, 3.0) for w in (1.9, 2.4)]


@pytest.mark.slow
def test_recovers_c_and_k_within_its_interval_and_3_percent(ck_trials):
    truth, trials = ck_trials
    res = cal.calibrate(trials, [t.meta.source_file for t in trials], ["c", "k"])
    s = res.summary()
    assert s["converged"] is True and s["optimizer"]["status"] > 0 and s["optimizer"]["message"]
    for p in res.params:
        true = getattr(truth, p.field)
        lo, hi = p.ci95
        assert lo <= true <= hi, (p.name, p.value, p.se)
        assert abs(p.value - true) <= 0.03 * true
        assert p.identifiable
        assert p.se >= p.se_model
    assert len(s["correlation"]["names"]) == 2
