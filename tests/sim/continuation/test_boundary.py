"""The critical slope as a curve over k (two-parameter continuation) against one-parameter located ends."""

import math

import pytest

from rimless.sim.continuation.algorithm1 import critical_slope
from rimless.sim.continuation.boundary import BoundaryContinuation, solve_at, start_on_boundary
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import make_map
from rimless.sim.step.poincare import default_guess


def _factory(model):
    return lambda q: make_map(q, model, backend="fast")


def test_fold_curve_passes_through_the_one_parameter_folds():
    """Traced from the fold at k = 2700, the VE medium fold curve meets the fold that the one-parameter
    continuation locates independently at k = 2500."""
    p = WheelParams()
    z, s0 = start_on_boundary(_factory("ve"), p, "ve", default_guess(p, "ve"), "fold")
    bc = BoundaryContinuation(_factory("ve"), p.replace(slope_rad=s0), "ve", "k", "fold", max_points=12)
    curve = bc.trace(z, s0, mu_min=2400, mu_max=2800)
    assert min(pt.mu for pt in curve.points) < 2500 < max(pt.mu for pt in curve.points)
    for pt in curve.points:
        assert min(abs(pt.eigenvalues - 1.0)) < 1e-6  # every point of the curve is a fold
    on_curve = solve_at(bc, curve, 2500.0)
    p2 = WheelParams(stiffness_n_per_m=2500.0)
    one = critical_slope(make_map(p2, "ve", backend="fast"), default_guess(p2, "ve"), method="arclength")
    assert one.reason == "fold"
    assert on_curve.slope_rad == pytest.approx(one.critical_slope_rad, abs=1e-6)


def test_er_stall_curve_is_the_stall_itself_point_by_point():
    """Every point of the ER stall curve is the stall at its k: it agrees with the stall that Algorithm 1 with
    bisection locates independently at that k (to 1e-6 rad), lies below its 1.6 s level-set point, and past
    it (slightly lower slope) no gait exists."""
    p = WheelParams()
    z, s0 = start_on_boundary(_factory("er"), p, "er", default_guess(p, "er"), "stall")
    bc = BoundaryContinuation(_factory("er"), p.replace(slope_rad=s0), "er", "k", "stall", max_points=3)
    curve = bc.trace(z, s0, mu_min=2650, mu_max=2750)
    assert len(curve.points) == len(curve.level_points) >= 3
    for stall, level in zip(curve.points, curve.level_points):
        assert stall.mu == level.mu and 0 < level.slope_rad - stall.slope_rad < math.radians(0.002)
    pt = next(pt for pt in curve.points if pt.mu != 2700.0)  # a point the continuation put at its own k
    q = WheelParams(stiffness_n_per_m=pt.mu)
    one = critical_slope(
        make_map(q, "er", backend="fast"), default_guess(q, "er"), method="bisection", refine_tol_rad=1e-9
    )
    assert one.reason == "stall"
    assert pt.slope_rad == pytest.approx(one.critical_slope_rad, abs=1e-6)
    with pytest.raises(StepFailure):
        bc.fixed_point_at(pt.z, pt.slope_rad - 1e-7, pt.mu)
