"""The model choice's quasi-likelihood test (`rimless.analysis.inference.model_choice`, issue 31), against closed
forms and against a linear truth whose errors are shared within each trial, written here apart from the code.

The linear truth: four trials of 25 "periods", a global speed-dependent loss (c's column), a constant loss per
step (friction's: ones) and one transient per trial (its release); each trial's residuals share its slope error
(sd 1, stated), which moves all its periods together, as friction does, plus white noise. The plain likelihood
ratio (the previous rule: delta chi^2 against chi^2_1 on residuals scaled by their rms) then claims friction
on most frictionless draws; the quasi-likelihood test, its statistic divided by the dispersion that the
calibration's standard errors carry (slopes, trial-clustered sandwich), at most at its nominal rate.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.inference.identifiability import least_squares_report, sandwich_se
from rimless.analysis.inference.model_choice import MODEL_CHOICE_P, choice_row, dispersion, quasi_likelihood_p
from rimless.analysis.inference.trial_slopes import slope_response
from rimless.analysis.validation.coverage import wilson_interval


def _chi2_1_sf(x: float) -> float:
    return math.erfc(math.sqrt(x / 2.0))  # P(Z^2 > x)


def _f_1_3_sf(x: float) -> float:
    """P(F(1, 3) > x) = P(|T_3| > sqrt(x)), T_3's CDF in closed form."""
    t = math.sqrt(x)
    u = t / math.sqrt(3.0)
    return 1.0 - (2.0 / math.pi) * (u / (1.0 + u * u) + math.atan(u))


def test_the_dispersion_is_the_carried_variance_over_the_models():
    """Hand-computed: se_model 0.05 with a slope part 0.1 is se 0.05 sqrt(5): phi 5 from the slopes (known
    sds: chi^2_1); a sandwich of 0.2 is larger: phi 16 from the trial scatter, with n_trials - 1 dof; a held part
    0.3 beside it: se^2 = 0.04 + 0.09, phi 52; a sandwich below the model's: phi 1 (never below)."""
    d = dispersion(0.05, 0.1)
    assert d["dispersion"] == pytest.approx(5.0) and d["source"] == "slopes" and d["dof"] is None
    d = dispersion(0.05, 0.1, 0.2, None, 4)
    assert d["dispersion"] == pytest.approx(16.0) and d["source"] == "trial scatter" and d["dof"] == 3
    d = dispersion(0.05, 0.1, 0.2, 0.3, 4)
    assert d["dispersion"] == pytest.approx(52.0) and d["source"] == "held parameters" and d["dof"] == 3
    d = dispersion(0.05, math.nan, 0.03, None, 4)
    assert d["dispersion"] == 1.0 and d["source"] == "model" and d["dof"] is None
    assert dispersion(math.inf, 0.1)["dispersion"] == 1.0


def test_the_p_value_against_closed_forms_halved_on_the_bound():
    """F = 20 / 5 = 4: P(chi^2_1 > 4) = erfc(sqrt 2) = 0.0455, halved on the bound 0.0228; against F(1, 3)
    (Student's t with 3 dof, squared) 0.139, halved 0.0697."""
    stat, p = quasi_likelihood_p(20.0, 5.0, None, False)
    assert stat == pytest.approx(4.0) and p == pytest.approx(_chi2_1_sf(4.0), rel=1e-9)
    assert quasi_likelihood_p(20.0, 5.0, None, True)[1] == pytest.approx(0.5 * _chi2_1_sf(4.0), rel=1e-9)
    assert quasi_likelihood_p(20.0, 5.0, 3, True)[1] == pytest.approx(0.5 * _f_1_3_sf(4.0), rel=1e-9)
    assert quasi_likelihood_p(20.0, 0.5, None, False)[0] == pytest.approx(20.0)  # phi below 1 counts as 1


def test_a_delta_chi2_the_plain_test_calls_friction_is_not_supported_when_the_slopes_explain_it():
    """delta chi^2 = 20 on the bound: the plain rule's p = 0.5 P(chi^2_1 > 20) = 3.9e-6 would claim friction; with
    the slopes' part making phi 5 the p-value is 0.0228 >= 0.01 and the statement names the dispersion."""
    row = choice_row("guide_friction_n", ["c"], 0.0, 100.0, 120.0, True, {"c": 11.0}, dispersion(0.05, 0.1))
    assert row["p_value_chi2"] == pytest.approx(0.5 * _chi2_1_sf(20.0), rel=1e-9) and row["p_value_chi2"] < 1e-5
    assert row["p_value"] == pytest.approx(0.5 * _chi2_1_sf(4.0), rel=1e-9)
    assert row["supported"] is False and row["delta_chi2"] == pytest.approx(20.0)
    assert row["dispersion"] == pytest.approx(5.0) and row["statistic"] == pytest.approx(4.0)
    assert "dispersion 5 (from the slopes)" in row["statement"] and "not supported" in row["statement"]
    strong = choice_row("guide_friction_n", ["c"], 0.0, 100.0, 160.0, True, {"c": 11.0}, dispersion(0.05, 0.1))
    assert strong["supported"] is True and strong["p_value"] < MODEL_CHOICE_P  # F = 12: p = 2.7e-4
    stuck = choice_row("guide_friction_n", ["c"], 0.0, 100.0, 160.0, False, {"c": 11.0}, dispersion(0.05, 0.1))
    assert stuck["supported"] is False and "did not converge" in stuck["statement"]


N_TRIALS, N_ROWS = 4, 25


def _linear_series(rng: np.random.Generator, friction: float) -> tuple[float, float]:
    """One series of the linear truth: (plain p, quasi-likelihood p) of friction, two-sided (no bound)."""
    k = np.arange(N_ROWS, dtype=float)
    n = N_TRIALS * N_ROWS
    offs = np.arange(0, n + 1, N_ROWS)
    speeds = rng.uniform(0.8, 1.6, N_TRIALS)
    x_c = np.concatenate([v * (1.0 + 0.5 * np.exp(-k / 6.0)) for v in speeds])  # a speed-dependent loss
    x_f = np.ones(n)  # a constant loss per step
    release = np.zeros((n, N_TRIALS))
    slope = np.zeros((n, N_TRIALS))  # each trial's residuals per 1 sd of its slope: all its periods together
    for i in range(N_TRIALS):
        release[offs[i] : offs[i + 1], i] = np.exp(-k / 4.0)
        slope[offs[i] : offs[i + 1], i] = 1.5 * (1.0 + 0.2 * k / N_ROWS)
    y = 2.0 * x_c + friction * x_f + release @ rng.normal(0.0, 1.0, N_TRIALS)
    y += slope @ rng.normal(0.0, 1.0, N_TRIALS) + rng.normal(0.0, 1.0, n)
    X = np.column_stack([x_c, x_f, release])
    full = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    Xr = np.column_stack([x_c, release])
    reduced = y - Xr @ np.linalg.lstsq(Xr, y, rcond=None)[0]
    sigma = float(np.sqrt(np.mean(full**2)))  # the calibration's block sigma: the rms residual at the solution
    J, r, ones = X / sigma, full / sigma, np.ones(X.shape[1])
    delta = float(np.sum(reduced**2) - np.sum(full**2)) / sigma**2
    se_model = least_squares_report(J, 2, ones)[0][1]
    se_sand = sandwich_se(J, r, offs, 2, ones)[1]
    se_slope = slope_response(
        J, 2, ones, [1.0] * N_TRIALS, lambda i, d: d * slope[offs[i] : offs[i + 1], i] / sigma, offs
    )[0][1]
    disp = dispersion(float(se_model), float(se_slope), float(se_sand), None, N_TRIALS)
    return _chi2_1_sf(delta), quasi_likelihood_p(delta, disp["dispersion"], disp["dof"], False)[1]


def test_on_a_linear_truth_with_shared_trial_errors_friction_is_claimed_at_most_at_the_nominal_rate():
    """600 frictionless draws at p < 0.05: the plain likelihood ratio claims friction in most (above 30 %); the
    quasi-likelihood test in at most 5 % (the Wilson 95 % interval of its count reaches down to 5 % or below) and
    not never (above 0.5 %: it is a test, not a refusal). With friction of 16 (about 3 carried standard errors:
    the slopes' part is about 5, as c and friction trade along their ridge) it finds it in more than half."""
    rng = np.random.default_rng(31)
    null = [_linear_series(rng, 0.0) for _ in range(600)]
    plain = sum(p < 0.05 for p, _ in null)
    quasi = sum(q < 0.05 for _, q in null)
    assert plain / 600 > 0.30, plain
    assert wilson_interval(quasi, 600)[0] <= 0.05 and quasi / 600 > 0.005, quasi
    found = sum(q < 0.05 for _, q in (_linear_series(rng, 16.0) for _ in range(200)))
    assert found / 200 > 0.5, found


def test_the_adequacy_study_keeps_every_figure_of_the_test():
    """`trials adequacy-coverage --json` keeps per series the model choice's verdict and its test's figures (so
    another rule can be checked offline): every key it names is one the model choice writes."""
    from rimless.analysis.validation.adequacy_coverage import CHOICE_KEYS

    row = choice_row("guide_friction_n", ["c"], 0.0, 100.0, 120.0, True, {"c": 11.0}, dispersion(0.05, 0.1))
    assert set(CHOICE_KEYS) <= set(row)
    assert {"dispersion", "dispersion_parts", "statistic", "p_value_chi2"} <= set(CHOICE_KEYS)


def test_the_linear_prediction_of_the_fit_without_is_exact_on_a_linear_model():
    """On a linear model the Gauss-Newton prediction from the fit with the extra parameter (column 1) to the fit
    with it held at 0.3 is the constrained least squares itself (solved here directly on the other columns)."""
    from rimless.analysis.inference.model_choice import predicted_without

    rng = np.random.default_rng(4)
    X = rng.normal(size=(40, 4))
    y = X @ np.array([1.0, 2.0, -0.5, 0.3]) + rng.normal(0.0, 0.1, 40)
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    d = predicted_without(X, X @ beta - y, 1, 0.3 - beta[1])
    others = [0, 2, 3]
    direct = np.linalg.lstsq(X[:, others], y - 0.3 * X[:, 1], rcond=None)[0]
    assert (beta + d)[1] == pytest.approx(0.3)
    assert (beta + d)[others] == pytest.approx(direct, rel=1e-9)


class _Stop:
    """A least-squares result: ``status`` 0 (stopped on its budget) or 5 (converged)."""

    def __init__(self, x, status):
        self.x, self.status, self.rounds, self.nfev_total = np.asarray(x, float), status, 1, 20
        self.message = "budget" if status == 0 else "converged"


def test_a_refit_that_stops_on_its_budget_goes_on_then_tries_the_other_start_and_says_why_not():
    """A fake solve that moves halfway to 0 each call and converges within 0.01: from the start of lowest
    chi^2 (|x|^2) first, on from where it stopped; a start it cannot finish leaves ``converged`` False with
    the Gauss-Newton gain left, the statement "undecided" naming the budget, and ``supported`` False however
    large delta chi^2 is."""
    from rimless.analysis.inference.model_choice import refit_without

    calls = []

    def solve(x, rounds):
        calls.append((float(x[0]), rounds))
        y = x / 2.0**rounds
        return _Stop(y, 5 if abs(y[0]) < 0.01 else 0)

    def cost(x):
        return float(np.sum(x**2))

    r, how = refit_without([("far", np.array([1.0])), ("near", np.array([0.05]))], cost, solve, cost, 3, 3)
    assert how["converged"] and how["start"] == "near" and len(how["starts"]) == 1 and calls[0] == (0.05, 3)
    r, how = refit_without([("far", np.array([40.0])), ("farther", np.array([80.0]))], cost, solve, cost, 1, 2)
    assert calls[-4:] == [(40.0, 1), (20.0, 2), (80.0, 1), (40.0, 2)]  # on from where it stopped, then the other
    assert not how["converged"] and how["start"] == "far" and how["gain_left_chi2"] == pytest.approx(25.0)
    assert how["rounds"] == 4 and how["nfev"] == 80 and [s["chi2"] for s in how["starts"]] == [25.0, 100.0]
    row = choice_row("guide_friction_n", ["c"], 0.0, 100.0, 1e5, False, {"c": 11.0}, dispersion(0.05, 0.1), how)
    assert row["supported"] is False and row["decided"] is False and row["simpler_optimizer"]["gain_left_chi2"] == 25.0
    assert row["statement"].startswith("undecided: the fit without it stopped on its budget (4 rounds, 80 ")
    assert "about 25" in row["statement"] and "upper bound" in row["statement"]


def test_the_fit_without_friction_converges_from_a_start_its_budget_could_not_reach():
    """Three simulated trials (12 steps, 0.1 mm) of a wheel with guide friction 0.8 N (c = 6 N s/m), fitted as
    c and F_c from the truth: dropping F_c, c must climb to about 9.6 N s/m. Started where the fit with friction
    ended (the previous model choice's only start) the least squares stop on a one-round budget (so the test
    was not made: main's statement "did not converge"); the model choice now reaches, within that budget, the
    fit without friction that the c-only calibration's own start (its profile, `_start`) reaches with ten
    rounds: the same c within a tenth of a percent and the same chi^2 within 0.1."""
    from rimless.analysis.inference import calibrate as cal
    from rimless.sim.model.params import WheelParams
    from tests.support.analysis_sim_truth import sim_trial

    truth = WheelParams(damping_ns_per_m=6.0, guide_friction_n=0.8)
    rng = np.random.default_rng(3)
    runs = ((2.5, 2.0), (3.0, 2.6), (2.0, 2.3))
    trials = [sim_trial(truth, s, w, rng, name=f"t{s}_{w}", n_steps=12, noise_m=0.1e-3) for s, w in runs]
    data, _ = cal._usable(trials, [t.meta.source_file for t in trials])
    sim, fit = cal._Sim("er", 1e-7, 8e-3), ["c", "guide_friction_n"]
    releases = cal._ReleaseFit(sim, lambda: None)
    ws = np.array([releases.fit(truth, d, None)[0] for d in data])
    obj = cal._Objective(sim, cal._Globals.of(WheelParams(), fit), data, lambda: None)
    u = obj.start((np.array([6.0, 0.8]) - obj.glob.x0) / obj.glob.scale, ws)
    obj.set_sigmas(u)
    lo, hi = obj.bounds(ws)
    full = obj.solve(u, lo, hi, 3)
    assert full.status > 0
    e = cal.ParamEstimate("guide_friction_n", "guide_friction_n", "N", 0.0, obj.unpack(full.x)[0][1], 0.05, True)
    e.se_model = 0.05
    row = cal._model_choice(obj, full.x, fit, (lo, hi), 1, [e])["guide_friction_n"]

    obj_c = cal._Objective(sim, cal._Globals.of(WheelParams(), ["c"]), data, lambda: None)
    obj_c.sig = dict(obj.sig)
    sel = np.array([0, *range(2, full.x.size)])
    assert obj_c.solve(full.x[sel], lo[sel], hi[sel], 1).status == 0  # the previous only start: budget
    _, ug, ug_refined, _ = cal._start(releases, obj_c.glob, data)
    good = obj_c.start(ug_refined, np.array([d.refined_release_rad_s for d in data]))
    ref = obj_c.solve(good, *cal._widened(obj_c, obj_c.bounds(good[1:4]), good[1:4]), 10)
    assert ref.status > 0
    assert row["without"]["c"] == pytest.approx(obj_c.unpack(ref.x)[0][0], rel=1e-3), row["statement"]
    assert row["chi2_without"] == pytest.approx(obj_c.cost(ref.x), abs=0.1)
    assert row["supported"] and row["delta_chi2"] > 1e3
    assert row["decided"] and row["simpler_optimizer"]["converged"]
