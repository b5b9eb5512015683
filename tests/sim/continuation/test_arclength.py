"""Pseudo-arclength continuation of the gait branches against independent expectations.

Expectations: model.md section 9 (ER ends in a stall, VE in folds, both near 1.26 deg at Table 1: a bracket
for gross errors only), the located special points' own definitions (an eigenvalue at +1 or -1, the test function changing sign across
the final bracket), the paper's Algorithm 1 refined by plain bisection (an independent method), and the
gaits an independent scan of initial conditions finds (find_gaits).
"""

import math

import numpy as np
import pytest

from rimless.sim.continuation.algorithm1 import critical_slope
from rimless.sim.continuation.arclength import FOLD, PERIOD_DOUBLING, ArclengthContinuation, eigen_tests
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import make_map
from rimless.sim.step.poincare import default_guess, find_gaits, solve_fixed_point
from tests.support.simcli_truth import NEAR_1_26_DEG, er_stall_by_bisection

K = 2700.0


def _factory(model):
    return lambda q: make_map(q, model, backend="fast")


@pytest.fixture(scope="module")
def ve_medium_branch():
    """The VE medium gait at Table 1 followed down in slope past its fold, to the end."""
    p = WheelParams(stiffness_n_per_m=K)
    cont = ArclengthContinuation(_factory("ve"), p, "ve", "slope", max_points=120)
    seen = []
    # stop once the fold and a period doubling beyond it are located
    return cont.trace(
        default_guess(p, "ve"),
        direction=-1.0,
        stop=lambda pt: seen.append(pt) or pt.max_abs_eigenvalue < 1.0 and len(seen) > 30,
    )


def test_test_functions_are_the_eigenvalue_conditions():
    J = np.array([[0.3, 0.2], [-0.1, 0.9]])
    l1, l2 = np.linalg.eigvals(J)
    t = eigen_tests(J)
    assert t[FOLD] == pytest.approx(((l1 - 1) * (l2 - 1)).real, abs=1e-14)
    assert t[PERIOD_DOUBLING] == pytest.approx(((l1 + 1) * (l2 + 1)).real, abs=1e-14)


def test_er_branch_ends_in_a_stall_where_bisection_finds_it():
    """The located stall is where Algorithm 1 refined by plain bisection (another method) finds the branch end."""
    p = WheelParams(stiffness_n_per_m=K)
    cont = ArclengthContinuation(_factory("er"), p, "er", "slope")
    br = cont.trace(default_guess(p, "er"), direction=-1.0, stop_at_first_loss=True)
    end = br.first_loss()
    assert end is not None and end.kind == "stall"
    reason, slope_rad = er_stall_by_bisection(K)
    assert reason == "stall"
    assert end.p == pytest.approx(slope_rad, abs=1e-6)
    assert NEAR_1_26_DEG[0] < math.degrees(end.p) < NEAR_1_26_DEG[1]
    # the stall's test function (smallest theta' in single support) is positive on the good side and the
    # map fails with a stall just past it; the period has grown far beyond the 0.31 s of the start gait
    assert end.bracket_values[0] > 0
    assert end.point.period_s > 1.0
    assert end.point.max_abs_eigenvalue < 1.0  # still stable: it is not a fold (model.md section 9)
    assert "eigenvalues" in end.detail


def test_ve_medium_fold_has_an_eigenvalue_at_one(ve_medium_branch):
    """The fold is located by its definition (an eigenvalue at +1), near model.md's 1.26 deg."""
    folds = [sp for sp in ve_medium_branch.special if sp.kind == FOLD]
    assert folds, ve_medium_branch.special
    fold = folds[0]
    assert NEAR_1_26_DEG[0] < math.degrees(fold.p) < NEAR_1_26_DEG[1]
    ev = fold.point.eigenvalues
    assert min(abs(ev - 1.0)) < 1e-4
    # the sign change of det(J - I) brackets the point
    assert fold.bracket_values[0] * fold.bracket_values[1] < 0
    assert min(fold.bracket_p) - 1e-9 <= fold.p <= max(fold.bracket_p) + 1e-9


def test_every_special_point_is_bracketed_by_a_sign_change(ve_medium_branch):
    assert len(ve_medium_branch.special) >= 2
    for sp in ve_medium_branch.special:
        a, b = sp.bracket_values
        assert a * b <= 0, sp
        if sp.kind == PERIOD_DOUBLING:
            assert min(abs(sp.point.eigenvalues + 1.0)) < 1e-4


def test_continuation_passes_the_fold_onto_the_unstable_branch(ve_medium_branch):
    pts = ve_medium_branch.points
    fold = next(sp for sp in ve_medium_branch.special if sp.kind == FOLD)
    after = [pt for pt in pts if pt.arclength > fold.point.arclength]
    assert after, "the continuation stopped at the fold"
    assert after[0].max_abs_eigenvalue > 1.0
    # past the fold the slope grows again: the branch turned around
    assert after[2].p > fold.p


def test_fold_agrees_with_the_bisection_of_algorithm_1():
    p = WheelParams(stiffness_n_per_m=K)
    pmap = make_map(p, "ve", backend="fast")
    bis = critical_slope(
        pmap, default_guess(p, "ve"), jacobian_factory=lambda m: m.jacobian, method="bisection", refine_tol_rad=1e-8
    )
    arc = critical_slope(pmap, default_guess(p, "ve"), jacobian_factory=lambda m: m.jacobian, method="arclength")
    assert bis.reason == arc.reason == "fold"
    assert arc.critical_slope_rad == pytest.approx(bis.critical_slope_rad, abs=1e-6)


def test_branch_end_reason_does_not_depend_on_the_tolerance():
    """Table 1 VE was 'infeasible' at rtol 1e-8 and 'fold' at 1e-7 (a trial point's failure decided it)."""
    p = WheelParams()
    reasons = set()
    for rtol in (1e-8, 1e-10):
        pmap = make_map(p, "ve", backend="fast", rtol=rtol)
        cs = critical_slope(pmap, default_guess(p, "ve"), jacobian_factory=lambda m: m.jacobian)
        reasons.add(cs.reason)
        ev = cs.end.point.eigenvalues
        assert f"{max(ev.real):.6f}" in cs.detail  # the detail quotes the end's own eigenvalue
    assert reasons == {"fold"}


def test_continuation_up_from_the_medium_gait_reaches_the_unstable_gait_gaits_finds():
    """Upward in slope, the VE medium branch folds back and returns to the start slope as the unstable gait."""
    p = WheelParams(stiffness_n_per_m=K)
    pmap = make_map(p, "ve", backend="fast")
    unstable = [g for g in find_gaits(pmap) if not g.stable]
    assert unstable
    cont = ArclengthContinuation(_factory("ve"), p, "ve", "slope", max_points=60)
    crossed = []

    br = cont.trace(
        default_guess(p, "ve"),
        direction=+1.0,
        stop=lambda pt: (
            crossed.append(pt) or (len(crossed) > 2 and pt.p < p.slope_rad and crossed[-2].p >= p.slope_rad)
        ),
    )
    # it went up in slope, turned at a fold above the start slope, and came back down through it
    assert any(sp.kind == FOLD and sp.p > p.slope_rad for sp in br.special)
    a, b = br.points[-2], br.points[-1]
    assert a.p >= p.slope_rad > b.p
    assert b.max_abs_eigenvalue > 1.0
    w = (a.p - p.slope_rad) / (a.p - b.p)
    z_interp = a.z + w * (b.z - a.z)
    fp = solve_fixed_point(pmap, z_interp, jacobian=pmap.jacobian)
    assert not fp.stable
    assert min(np.max(np.abs(fp.z - g.z)) for g in unstable) < 1e-7
