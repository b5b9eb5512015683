"""Critical slope of the compliant wheels: the paper's Algorithm 1 plus the located branch end.

Algorithm 1: continue the fixed point downward in slope from 0.05 rad with step `step_rad`, the previous
fixed point as the guess, and report the last slope where Newton converged.
Branch end, method "arclength" (default on the compiled path): pseudo-arclength continuation
(rimless.sim.continuation.arclength) from the start gait down to its first special point, located by bisection on the
test functions; the reason is read off the test functions at the located end.
Branch end, method "bisection" (the reference path's default): bisect between the last good slope and the
first bad one until the bracket is below `refine_tol_rad`; the reason again comes from the located end
(an eigenvalue at +1: fold; else the map's failure class just past it). Reasons (model.md section 7):
- `fold`: Newton stops converging while an eigenvalue approaches +1 (the fixed point vanishes);
- `stall`: the map fails because the wheel stops (the period grows without bound);
- `loss-of-stability`: a period-1 gait still exists but an eigenvalue leaves the unit circle;
- `infeasible`: a force or impulse condition fails (e.g. stance lift-off, negative impulse).
The critical slope is the smallest slope of the branch with a stable, valid period-1 gait.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.step.poincare import FixedPoint, NoFixedPoint, SectionMap, solve_fixed_point

START_SLOPE_RAD = 0.05
DEFAULT_STEP_RAD = 0.001
REFINE_TOL_RAD = 1e-6

M = TypeVar("M", bound=SectionMap)  # the map critical_slope is given (its jacobian_factory takes the same kind)


@dataclass
class BranchPoint:
    """One converged point of the branch."""

    slope_rad: float
    z: np.ndarray
    period_s: float
    max_abs_eigenvalue: float
    eigenvalues: np.ndarray


@dataclass
class CriticalSlope:
    """Result of the continuation; every slope in rad."""

    model: str
    algorithm1_slope_rad: float  # last converged slope of the fixed-step continuation
    algorithm1_step_rad: float
    critical_slope_rad: float  # smallest slope with a stable, valid gait, to refine_tol_rad
    refine_tol_rad: float
    reason: str  # fold | stall | loss-of-stability | infeasible | solver
    detail: str
    fixed_point: FixedPoint  # at critical_slope_rad
    branch: list[BranchPoint] = field(default_factory=list)
    start_guess: np.ndarray | None = None
    method: str = "bisection"
    end: Any = None  # rimless.sim.continuation.arclength.SpecialPoint at the located end (arclength method)
    special_points: list[Any] = field(default_factory=list)
    map_evaluations: int = 0
    located_to_rad: float | None = None  # width of the final bracket in slope (arclength method)

    @property
    def critical_slope_deg(self) -> float:
        return math.degrees(self.critical_slope_rad)

    @property
    def cot(self) -> float:
        """Cost of transport tan(phi_c) (model.md section 7)."""
        return math.tan(self.critical_slope_rad)


def _classify(err: StepFailure, last_good: FixedPoint | None) -> tuple[str, str]:
    """Why the fixed point is lost at a slope: from the map's failure and the last eigenvalues."""
    cause = err.last_failure if isinstance(err, NoFixedPoint) else err
    if cause is not None and cause.reason in (FailureReason.STALL,):
        return "stall", str(cause)
    if cause is not None and cause.reason not in (FailureReason.NO_CONVERGENCE, FailureReason.INTEGRATION):
        return "infeasible", str(cause)
    if last_good is not None:
        real_max = float(np.max(last_good.eigenvalues.real))
        if real_max > 0.9 and np.max(np.abs(last_good.eigenvalues.imag)) < 1e-9:
            return "fold", f"an eigenvalue approaches +1 ({real_max:.4f}) and the fixed point vanishes"
        if last_good.recorded_step.period_s > 0.6:
            return "stall", f"the period grows ({last_good.recorded_step.period_s:.3f} s) as the wheel nearly stops"
    return "solver", str(err)


def critical_slope(
    pmap: M,
    z_guess: np.ndarray,
    *,
    start_slope_rad: float = START_SLOPE_RAD,
    step_rad: float = DEFAULT_STEP_RAD,
    min_slope_rad: float = 1e-4,
    refine_tol_rad: float = REFINE_TOL_RAD,
    strict_contact: bool = False,
    jacobian_factory: Callable[[M], Callable[[np.ndarray], np.ndarray]] | None = None,
    progress: Callable[[float], None] | None = None,
    method: str = "auto",
) -> CriticalSlope:
    """Continue the branch through z_guess at start_slope_rad downward in slope (see module docstring).

    method: "arclength", "bisection" or "auto" (arclength when the map is compiled and strict_contact is off,
    else bisection)."""
    base = pmap.params
    if method == "auto":  # the arclength test functions do not include the strict-contact conditions
        method = "arclength" if hasattr(pmap, "evaluate") and not strict_contact else "bisection"
    if method not in ("arclength", "bisection"):
        raise ValueError(f"unknown method {method!r}")

    counted = [0]  # map evaluations of every map made here (Algorithm 1 and the bisection)

    def solve(slope: float, guess: np.ndarray) -> FixedPoint:
        m = pmap.with_params(base.replace(slope_rad=slope))
        jac = jacobian_factory(m) if jacobian_factory else None
        try:
            return solve_fixed_point(m, guess, jacobian=jac, strict_contact=strict_contact, max_iter=20)
        finally:
            counted[0] += getattr(m, "evaluations", 0)

    def good(fp: FixedPoint) -> bool:
        return fp.stable

    try:
        first = solve(start_slope_rad, z_guess)
    except StepFailure as err:
        raise NoFixedPoint(
            f"no fixed point at the start slope {start_slope_rad} rad from the guess "
            f"{np.asarray(z_guess).tolist()}: {err}",
            getattr(err, "last_failure", None),
        ) from None
    branch = [
        BranchPoint(start_slope_rad, first.z, first.recorded_step.period_s, first.max_abs_eigenvalue, first.eigenvalues)
    ]
    # Algorithm 1: fixed steps down while Newton converges.
    last_conv, last_conv_fp = start_slope_rad, first
    last_stable = start_slope_rad if good(first) else None
    last_stable_fp = first if good(first) else None
    failure_slope: float | None = None
    failure: tuple[str, str] | None = None
    slope = start_slope_rad
    while True:
        slope = round(slope - step_rad, 12)
        if slope < min_slope_rad:
            break
        try:
            fp = solve(slope, last_conv_fp.z)
        except StepFailure as err:
            failure_slope = slope
            failure = _classify(err, last_conv_fp)
            break
        if progress:
            progress(slope)
        branch.append(BranchPoint(slope, fp.z, fp.recorded_step.period_s, fp.max_abs_eigenvalue, fp.eigenvalues))
        last_conv, last_conv_fp = slope, fp
        if (
            good(fp)
            and last_stable is not None
            and last_stable_fp is not None
            and last_stable - slope <= step_rad * 1.5
        ):
            last_stable, last_stable_fp = slope, fp
        elif not good(fp) and last_stable is not None and failure is None:
            # loss of stability below last_stable: remember where, keep Algorithm 1 running
            failure = ("loss-of-stability", f"max |eigenvalue| = {fp.max_abs_eigenvalue:.4f} >= 1 at {slope:.6f} rad")
            failure_slope = slope
    algorithm1 = last_conv
    if last_stable is None or last_stable_fp is None:
        raise NoFixedPoint(
            f"the gait at the start slope {start_slope_rad} rad is not stable "
            f"(max |eigenvalue| {first.max_abs_eigenvalue:.4f})"
        )
    if method == "arclength":
        cs = _by_arclength(
            pmap,
            first,
            start_slope_rad,
            step_rad,
            algorithm1,
            last_conv_fp,
            branch,
            min_slope_rad,
            refine_tol_rad,
            z_guess,
            progress,
        )
        cs.map_evaluations += counted[0]
        return cs
    if failure is None or failure_slope is None:
        return CriticalSlope(
            pmap.model,
            algorithm1,
            step_rad,
            last_stable,
            refine_tol_rad,
            "min-slope",
            f"the branch reaches the smallest slope tried ({min_slope_rad} rad)",
            last_stable_fp,
            branch,
            np.asarray(z_guess),
        )
    # Refinement: bisect [bad, good] keeping the stable side's fixed point as the guess.
    lo, hi, hi_fp = failure_slope, last_stable, last_stable_fp
    reason, detail = failure
    if reason == "loss-of-stability":
        lo = max(lo, failure_slope)
    # secant predictor along the branch: (slope, z) of the last two good points
    prev_slope, prev_z = (branch[-2].slope_rad, branch[-2].z) if len(branch) > 1 else (hi, hi_fp.z)
    while hi - lo > refine_tol_rad:
        mid = 0.5 * (lo + hi)
        guesses = [hi_fp.z]
        if prev_slope != hi:
            guesses.insert(0, hi_fp.z + (mid - hi) * (hi_fp.z - prev_z) / (hi - prev_slope))
        for guess in guesses:
            try:
                fp = solve(mid, guess)
                break
            except StepFailure as err:
                last_err = err
        else:  # no guess converged
            lo = mid
            if reason != "loss-of-stability":
                reason, detail = _classify(last_err, hi_fp)
            continue
        if good(fp):
            prev_slope, prev_z = hi, hi_fp.z
            hi, hi_fp = mid, fp
        else:
            lo = mid
            reason, detail = (
                "loss-of-stability",
                f"max |eigenvalue| = {fp.max_abs_eigenvalue:.4f} >= 1 at {mid:.7f} rad",
            )
    if reason != "loss-of-stability":
        reason, detail = _reason_at_end(pmap, hi_fp, lo, reason, detail)
    return CriticalSlope(
        pmap.model,
        algorithm1,
        step_rad,
        hi,
        refine_tol_rad,
        reason,
        detail,
        hi_fp,
        branch,
        np.asarray(z_guess),
        "bisection",
        map_evaluations=counted[0],
    )


FOLD_EIGENVALUE_TOL = 0.02  # |eigenvalue - 1| at a bisected end (bracket 1e-6 rad) that marks a fold


def _reason_at_end(pmap: SectionMap, hi_fp: FixedPoint, lo: float, reason: str, detail: str) -> tuple[str, str]:
    """The reason from the located end itself: an eigenvalue at +1 is a fold whatever failed at a trial
    point; else the map's own failure just past the end (stall, lift-off, impulse)."""
    ev = hi_fp.eigenvalues
    evs = ", ".join(f"{e.real:.5f}{e.imag:+.5f}j" for e in ev)
    near_one = [e for e in ev if abs(e.imag) < 1e-9 and abs(e.real - 1.0) < FOLD_EIGENVALUE_TOL]
    if near_one:
        return "fold", (
            f"an eigenvalue reaches +1 at the located end ({near_one[0].real:.5f}; eigenvalues {evs}) "
            "and the fixed point vanishes"
        )
    try:
        pmap.with_params(pmap.params.replace(slope_rad=lo))(hi_fp.z)
    except StepFailure as err:
        if err.reason == FailureReason.STALL:
            return "stall", f"{err} (eigenvalues at the end {evs})"
        if err.reason in (FailureReason.STANCE_LIFT_OFF, FailureReason.NEGATIVE_IMPULSE):
            return "infeasible", f"{err} (eigenvalues at the end {evs})"
    return reason, f"{detail} (eigenvalues at the end {evs})"


def _by_arclength(
    pmap: SectionMap,
    first: FixedPoint,
    start_slope_rad: float,
    step_rad: float,
    algorithm1: float,
    algorithm1_fp: FixedPoint,
    branch: list[BranchPoint],
    min_slope_rad: float,
    refine_tol_rad: float,
    z_guess: np.ndarray,
    progress: Callable[[float], None] | None,
) -> CriticalSlope:
    from rimless.sim.continuation.arclength import ArclengthContinuation
    from rimless.sim.continuation.oracle import PARAMETERS

    scale = PARAMETERS["slope"][1]
    cont = ArclengthContinuation(
        lambda q: pmap.with_params(q),
        pmap.params.replace(slope_rad=start_slope_rad),
        pmap.model,
        "slope",
        locate_tol=min(1e-7, refine_tol_rad / scale),
    )
    br = cont.trace(
        first.z,
        direction=-1.0,
        p_min=min_slope_rad,
        stop_at_first_loss=True,
        progress=(lambda pt: progress(pt.p)) if progress else None,
    )
    end = br.first_loss()
    if end is None:
        last = br.points[-1]
        return CriticalSlope(
            pmap.model,
            algorithm1,
            step_rad,
            last.p,
            refine_tol_rad,
            "min-slope",
            f"the branch reaches the smallest slope tried ({min_slope_rad} rad)",
            algorithm1_fp,
            branch,
            np.asarray(z_guess),
            "arclength",
            None,
            br.special,
            br.map_evaluations,
        )
    reason = {
        "stance-force": "infeasible",
        "impulse": "infeasible",
        "period-doubling": "loss-of-stability",
        "neimark-sacker": "loss-of-stability",
        "end": "solver",
    }.get(end.kind, end.kind)
    return CriticalSlope(
        pmap.model,
        algorithm1,
        step_rad,
        end.p,
        refine_tol_rad,
        reason,
        end.detail,
        algorithm1_fp,
        branch,
        np.asarray(z_guess),
        "arclength",
        end,
        br.special,
        br.map_evaluations,
        abs(end.bracket_p[1] - end.bracket_p[0]),
    )
