"""The calibration's and the comparison's fast inner paths against independent truths: the CoM curve's
Hermite interpolation against a densely recorded walk, the start refinement against a closed-form parabola,
the release scan on the compiled map against the scan on walks, and the refined start against the coarse one
(the same objective, so the same estimate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.inference import calibrate as cal
from tests.support.analysis_sim_truth import sim_trial


def _walk(record_dt: float):
    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_integrator

    p = WheelParams().replace(slope_rad=math.radians(1.9))
    return cal._com_walk(p, "er", np.array([-cal.ALPHA_RAD / 2, 2.3]), 8, make_integrator("auto", rtol=1e-7), record_dt)


def test_hermite_curve_matches_a_densely_recorded_walk():
    """Truth: the same walk recorded every 0.1 ms, linearly interpolated (error ~ h^2 |h''| / 8 ~ 1e-9 m)."""
    coarse, fine = _walk(8e-3), _walk(1e-4)
    t0 = coarse.steps[1].t_start_s
    end = coarse.steps[-1].t_start_s + coarse.steps[-1].period_s - t0
    tt = np.linspace(-0.1, end, 4001)
    kt, ky = cal._clean_knots(*cal._hermite_parts(fine, t0)[:2])
    truth = np.interp(tt, kt, ky)
    got = cal._hermite_curve(coarse, t0, tt)
    assert np.max(np.abs(got - truth)) < 0.5e-6  # well below a micrometre on the 8 ms record
    # the impact cusps stay cusps: the curve's minima are at the simulated impacts, within the record spacing
    impacts = np.array([s.t_start_s + s.period_s for s in coarse.steps[1:-1]]) - t0
    for ti in impacts:
        near = np.abs(tt - ti) < 0.03
        assert abs(tt[near][np.argmin(got[near])] - ti) <= (tt[1] - tt[0]) + 1e-12


def test_start_refinement_lands_on_the_parabola_vertex():
    """A quadratic cost: one parabolic step through three profile points is its exact minimum (closed form)."""
    vertex = 0.3

    def cost(x: float) -> float:
        return 2.0 * (x - vertex) ** 2 + 1.0

    seen = {x: cost(x) for x in (-0.5, -0.3, 0.0, 0.4, 1.0)}
    best = {"ug": np.array([0.4])}
    calls = []

    def try_start(ug: np.ndarray) -> float:
        calls.append(float(ug[0]))
        c = cost(float(ug[0]))
        if c < cost(float(best["ug"][0])):
            best["ug"] = ug
        return c

    cal._refine_start(seen, lambda: best["ug"], 0, try_start)
    assert calls[0] == pytest.approx(vertex, abs=1e-12)
    assert float(best["ug"][0]) == pytest.approx(vertex, abs=1e-12)
    assert len(calls) == 1  # at the vertex already: no second evaluation there


def test_start_refinement_stays_put_at_the_end_of_the_profile():
    seen = {0.0: 5.0, 0.4: 3.0, 1.0: 1.0}  # still falling at the last point: nothing is bracketed
    calls = []
    cal._refine_start(seen, lambda: np.array([1.0]), 0, lambda ug: calls.append(ug) or 0.0)
    assert calls == []


def test_release_scan_on_the_map_gives_the_walks_release(monkeypatch):
    """The compiled-map scan only brackets: the release is the one a scan on walks finds, and a period no release
    gives gets the same reason."""
    from rimless.analysis.inference import compare

    sim = compare.Simulator()
    cases = [(1.9, 0.42), (1.5, 0.45), (2.5, 0.38), (1.9, 5.0)]  # (slope deg, first period s); the last: none
    fast = [compare.fit_release_speed(sim, s, t) for s, t in cases]
    monkeypatch.setattr(compare, "_map_periods", lambda *a: None)
    walks = [compare.fit_release_speed(sim, s, t) for s, t in cases]
    for (wf, why_f), (ww, why_w) in zip(fast, walks):
        assert (wf is None) == (ww is None)
        if ww is not None:
            assert wf == pytest.approx(ww, abs=1e-9)
        else:
            assert why_f == why_w
    assert walks[0][0] is not None and walks[-1][0] is None  # both kinds of case were exercised


@pytest.mark.slow
def test_refined_start_reaches_the_coarse_starts_estimate(monkeypatch):
    """The refinement changes where the least squares begin, not what they minimise (the sigmas and bounds
    stay the coarse start's): the estimate and its uncertainty agree with the unrefined fit's far inside
    its own uncertainty."""
    from rimless.sim.model.params import WheelParams

    truth = WheelParams(damping_ns_per_m=11.0)
    rng = np.random.default_rng(5)
    trials = [sim_trial(truth, s, w, rng, name=f"sim_{s}deg_{w}") for s in (1.6, 2.2) for w in (1.9, 2.3)]
    names = [t.meta.source_file for t in trials]
    refined = calibrate_c(trials, names)
    monkeypatch.setattr(cal, "REFINE_ROUNDS", 0)
    monkeypatch.setattr(cal._refine_start, "__defaults__", (0,))
    coarse = calibrate_c(trials, names)
    (a,), (b,) = refined.params, coarse.params
    assert refined.converged and coarse.converged
    assert abs(a.value - b.value) < 0.05 * b.se, (a.value, b.value, b.se)
    assert a.se == pytest.approx(b.se, rel=0.02)
    assert a.identifiable == b.identifiable


def calibrate_c(trials, names):
    return cal.calibrate(trials, names, ["c"])


def test_the_gauss_newton_stop_is_a_tenth_of_a_standard_error_on_a_linear_problem() -> None:
    """Unit-variance residuals f(u) = J u - y of a linear model: the cost 0.5 |f|^2 at u exceeds its minimum by
    exactly 0.5 (u - u*)^T J^T J (u - u*), a half chi-square. The fit may stop when that is below
    GN_STOP_COST = 0.005 (u within 0.1 standard error of u* along every direction), and not before."""
    rng = np.random.default_rng(3)
    J = rng.normal(size=(200, 3))
    y = rng.normal(size=200)
    u_star = np.linalg.lstsq(J, y, rcond=None)[0]
    cov = np.linalg.inv(J.T @ J)
    obj = object.__new__(cal._Objective)
    for n_se, stops in ((0.05, True), (0.095, True), (0.105, False), (1.0, False)):
        direction = rng.normal(size=3)
        step = direction / math.sqrt(direction @ np.linalg.inv(cov) @ direction)  # one standard error (Mahalanobis)
        u = u_star + n_se * step
        obj.last_jac = (u.copy(), J)
        assert obj.near_minimum(u, J @ u - y) is stops, n_se
    obj.last_jac = (u_star + 1.0, J)  # a Jacobian taken elsewhere says nothing
    assert obj.near_minimum(u_star, J @ u_star - y) is False
