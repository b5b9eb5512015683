"""Studies of the firmware in the loop: the gait the firmware settles on, and the slope below which it stops.

`firmware_fixed_point` fits the walk of rimless.sim.in_the_loop.loop to a linear map and extrapolates its
fixed point; `walks_under_firmware` is one walk from the ideal-clutch gait; `firmware_critical_slope`
bisects the slope on it; `firmware_boundaries` tells a firmware fault from a mechanical failure
(`without_step_timing_checks`). Angles in rad, times in s, energies in J.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from rimless.sim.in_the_loop.loop import FirmwareLoop, FirmwareLoopConfig, FirmwareWalk
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import WheelParams
from rimless.sim.step.poincare import FixedPoint, NoFixedPoint, PoincareMap, default_guess, solve_fixed_point


@dataclass
class FirmwareFixedPoint:
    """The period-1 gait under the firmware, from a walk (the map is sampled: see `firmware_fixed_point`)."""

    z: np.ndarray  # extrapolated fixed point (theta+ rad, theta'+ rad/s)
    z_mean: np.ndarray  # mean of the last `n_average` section points
    z_std: np.ndarray
    eigenvalues: np.ndarray  # of the linear map fitted to the walk (nan when the fit is not determined)
    fit_residual: float  # rms misfit of z_{k+1} = A z_k + c over the fitted steps (the sampling noise), rad-ish
    period_s: float  # mean over the last steps
    period_std_s: float
    stored_energy_J: float  # mean spring energy held at touchdown over the last steps
    walk: FirmwareWalk
    n_average: int

    @property
    def stable(self) -> bool | None:
        """max |eigenvalue| < 1 of the fitted linear map (None when it could not be fitted)."""
        if not np.all(np.isfinite(self.eigenvalues)):
            return None
        return bool(np.max(np.abs(self.eigenvalues)) < 1.0)


def firmware_fixed_point(
    params: WheelParams,
    config: FirmwareLoopConfig,
    z_ideal: np.ndarray,
    *,
    steps: int = 12,
    n_average: int = 4,
    progress: Callable[[int], None] | None = None,
) -> FirmwareFixedPoint:
    """The fixed point under the firmware, found from one walk started at the ideal-clutch fixed point.

    The firmware samples at instants unrelated to the step, so the step map is not a smooth function of
    z alone (it depends on the sampling phase and the controller's memory). Instead of Newton on a noisy
    map, the walk itself is the iteration: its section points z_k are fitted by a linear map
    z_{k+1} = A z_k + c (least squares over all steps after the first), and the fixed point is
    z* = (I - A)^-1 c, a derivative-free extrapolation of the transient (exact for a linear map; the
    fit residual measures what the sampling phase adds). eig(A) estimates the eigenvalues of the map.
    The mean and spread of the last `n_average` points are reported beside it.
    Raises StepFailure (classified) if the walk fails before enough steps are done.
    """
    loop = FirmwareLoop(params, config)
    try:
        walk = loop.walk(z_ideal, steps, progress=progress)
    finally:
        loop.close()
    if walk.failure is not None and len(walk.steps) < 4:
        raise walk.failure
    zs = walk.section_points[1:]  # skip the start: the firmware's first step follows the priming step
    last = zs[-n_average:]
    eig = np.full(2, np.nan, dtype=complex)
    z_fit = last.mean(axis=0)
    misfit = float("nan")
    if len(zs) >= 5:
        X = np.hstack((zs[:-1], np.ones((len(zs) - 1, 1))))
        coef, *_ = np.linalg.lstsq(X, zs[1:], rcond=None)
        A, c = coef[:2].T, coef[2]
        misfit = float(np.sqrt(np.mean((X @ coef - zs[1:]) ** 2)))
        try:
            cand = np.linalg.solve(np.eye(2) - A, c)
            if np.all(np.isfinite(cand)) and np.max(np.abs(cand - z_fit)) < 10 * np.max(np.abs(zs[-1] - zs[0]) + 1e-6):
                z_fit = cand
                eig = np.linalg.eigvals(A)
        except np.linalg.LinAlgError:
            pass
    tail = walk.steps[-n_average:]
    periods = np.array([s.period_s for s in tail])
    return FirmwareFixedPoint(
        z=z_fit,
        z_mean=last.mean(axis=0),
        z_std=last.std(axis=0),
        eigenvalues=eig,
        fit_residual=misfit,
        period_s=float(periods.mean()),
        period_std_s=float(periods.std()),
        stored_energy_J=float(np.mean([s.stored_energy_J for s in tail])),
        walk=walk,
        n_average=len(tail),
    )


@dataclass
class FirmwareCriticalSlope:
    """The smallest slope at which the firmware keeps the wheel walking (see `firmware_critical_slope`)."""

    critical_slope_rad: float  # lowest slope found that walks
    failing_slope_rad: float  # highest slope found that does not (the boundary lies between)
    reason_below: str  # why the walk fails just below
    evaluations: list[tuple[float, bool, str]]  # (slope rad, walks, reason)

    @property
    def limited_by(self) -> str:
        """ "firmware" when a firmware fault (its leg count or clutch timeout) ends the walk just below,
        "mechanics" when the wheel itself fails (stall, contact, ...)."""
        return "firmware" if self.reason_below.startswith(FIRMWARE_FAULT_PREFIX) else "mechanics"


FIRMWARE_FAULT_PREFIX = "the firmware faulted"
# what the step-timing checks are relaxed to for the mechanical boundary: the longest step and hold the
# detector's and controller's validation accept, and the widest period tolerance
RELAXED_MAX_STEP_S = 10.0
RELAXED_PERIOD_TOLERANCE = 0.9
RELAXED_MAX_HOLD_S = 60.0


def without_step_timing_checks(config: FirmwareLoopConfig) -> FirmwareLoopConfig:
    """The same firmware with its step-timing fail-safes (leg count: `max_step_s`, `step_period_tolerance`;
    clutch timeout: `max_hold_s`) relaxed to their widest valid values, so that a walk under it ends only
    by the mechanics. Everything else (sensor, detector thresholds, delays) is unchanged."""
    det = replace(config.detector, max_step_s=RELAXED_MAX_STEP_S, step_period_tolerance=RELAXED_PERIOD_TOLERANCE)
    return replace(config, detector=det, max_hold_s=RELAXED_MAX_HOLD_S).validated()


@dataclass
class FirmwareBoundaries:
    """The critical slope under the firmware as configured, and, when a firmware fault limits it, the
    mechanical one (the same firmware with its step-timing checks relaxed: `without_step_timing_checks`)."""

    firmware: FirmwareCriticalSlope
    mechanical: FirmwareCriticalSlope | None  # None when the mechanics already limit the configured firmware

    @property
    def limited_by(self) -> str:
        """ "firmware" when the relaxed firmware walks at a slope where the configured one faults (the
        fault stops a wheel that would walk), else "mechanics" (the fault, if any, only comes first)."""
        if self.mechanical is None:
            return "mechanics"
        m = self.mechanical.critical_slope_rad
        return "firmware" if math.isfinite(m) and m <= self.firmware.failing_slope_rad else "mechanics"

    @property
    def detail(self) -> str:
        """Why the boundary is where it is, in a sentence."""
        fw, mech = self.firmware, self.mechanical
        if mech is None:
            return f"the wheel fails mechanically below it: {fw.reason_below}"
        if self.limited_by == "firmware":
            return (
                f"a firmware fault stops a wheel that would walk: below it {fw.reason_below}; with the step-timing "
                f"checks relaxed it walks down to {math.degrees(mech.critical_slope_rad):.3f} deg"
            )
        return (
            f"the firmware's fault fires first ({fw.reason_below}), but with the step-timing checks relaxed the "
            f"wheel fails there too, in a walk {MECHANICAL_WALK_FACTOR} times as long: {mech.reason_below}"
        )

    @property
    def mechanical_slope_rad(self) -> float:
        """The mechanical boundary: the relaxed search's, or the configured one when mechanics limit it."""
        return (self.mechanical or self.firmware).critical_slope_rad


def ideal_gait(params: WheelParams) -> FixedPoint:
    """The ideal-clutch ER fixed point the walks start from (reference path, rtol 1e-9); raises StepFailure
    or NoFixedPoint."""
    return solve_fixed_point(
        PoincareMap(params, "er", ScipyIntegrator(rtol=1e-9, atol=1e-11)), default_guess(params, "er")
    )


def walks_under_firmware(params: WheelParams, config: FirmwareLoopConfig, steps: int) -> tuple[bool, str]:
    """(True, "") if a walk of `steps` steps from the ideal fixed point at these parameters completes
    without a failed step and without a firmware fault; else (False, the reason)."""
    try:
        ideal = ideal_gait(params)
    except (StepFailure, NoFixedPoint) as err:
        return False, f"no ideal-clutch gait to start from ({err})"
    loop = FirmwareLoop(params, config)
    try:
        walk = loop.walk(ideal.z, steps)
    finally:
        loop.close()
    if walk.failure is not None:
        return False, f"step {len(walk.steps) + 1}: {walk.failure}"
    faults = [f["fault"] for _, name, f in walk.events if name == "fault"]
    if faults:
        details = "; ".join(f"{f.get('fault')}: {f.get('detail')}" for _, name, f in walk.events if name == "fault")
        return False, f"{FIRMWARE_FAULT_PREFIX} ({', '.join(faults)}): it no longer clutches ({details})"
    return True, ""


def firmware_critical_slope(
    params: WheelParams,
    config: FirmwareLoopConfig,
    *,
    low_rad: float,
    steps: int = 10,
    tol_rad: float = 1e-3,
    progress: Callable[[int], None] | None = None,
) -> FirmwareCriticalSlope:
    """Bisection on the slope between `low_rad` (must fail) and params.slope_rad (must walk) for the lowest
    slope at which `walks_under_firmware` holds, to `tol_rad`. It assumes one boundary (walking at a slope
    implies walking at steeper ones), which the returned evaluations let the caller check.
    Raises ValueError if the bracket does not straddle the boundary."""
    evals: list[tuple[float, bool, str]] = []

    def test(slope: float) -> tuple[bool, str]:
        ok, why = walks_under_firmware(params.replace(slope_rad=slope), config, steps)
        evals.append((slope, ok, why))
        if progress:
            progress(len(evals))
        return ok, why

    hi, lo = params.slope_rad, low_rad
    ok_hi, why_hi = test(hi)
    if not ok_hi:
        raise ValueError(f"the wheel does not walk under the firmware at the start slope {hi:.5f} rad: {why_hi}")
    ok_lo, why_lo = test(lo)
    if ok_lo:
        raise ValueError(f"the wheel still walks under the firmware at the low end {lo:.5f} rad; lower it")
    while hi - lo > tol_rad:
        mid = 0.5 * (hi + lo)
        ok, why = test(mid)
        if ok:
            hi = mid
        else:
            lo, why_lo = mid, why
    return FirmwareCriticalSlope(critical_slope_rad=hi, failing_slope_rad=lo, reason_below=why_lo, evaluations=evals)


MECHANICAL_WALK_FACTOR = 3  # the relaxed walks are this many times longer (see firmware_boundaries)


def firmware_boundaries(
    params: WheelParams,
    config: FirmwareLoopConfig,
    *,
    low_rad: float,
    steps: int = 10,
    tol_rad: float = 1e-3,
    progress: Callable[[int], None] | None = None,
) -> FirmwareBoundaries:
    """`firmware_critical_slope` under `config`; if a firmware fault is what fails just below it, is that
    fault what stops the wheel? The same firmware with its step-timing checks relaxed walks
    MECHANICAL_WALK_FACTOR x `steps` steps at the failing slope: a wheel slowing towards a stall trips the
    leg-count check (its steps outgrow the running period or `max_step_s`) a step or two before it stalls,
    and a walk only as long as the configured one could miss that stall. If the long relaxed walk fails
    too, the boundary is mechanical (the fault only came first); if it walks, the mechanical boundary is
    bisected below with long relaxed walks. Raises ValueError as `firmware_critical_slope` does."""
    n = [0]

    def count(_k: int) -> None:
        n[0] += 1
        if progress:
            progress(n[0])

    fw = firmware_critical_slope(params, config, low_rad=low_rad, steps=steps, tol_rad=tol_rad, progress=count)
    if fw.limited_by != "firmware":
        return FirmwareBoundaries(fw, None)
    relaxed = without_step_timing_checks(config)
    long_steps = MECHANICAL_WALK_FACTOR * steps
    ok, why = walks_under_firmware(params.replace(slope_rad=fw.failing_slope_rad), relaxed, long_steps)
    count(0)
    if not ok:  # the wheel fails there anyway: the boundary is mechanical, the fault only came first
        return FirmwareBoundaries(
            fw,
            FirmwareCriticalSlope(
                fw.critical_slope_rad, fw.failing_slope_rad, why, [(fw.failing_slope_rad, False, why)]
            ),
        )
    top = params.replace(slope_rad=fw.failing_slope_rad)
    try:
        mech = firmware_critical_slope(top, relaxed, low_rad=low_rad, steps=long_steps, tol_rad=tol_rad, progress=count)
    except ValueError as err:  # e.g. relaxed, the wheel still walks at low_rad: the boundary is below the bracket
        mech = FirmwareCriticalSlope(math.nan, low_rad, f"not bracketed: {err}", [])
    return FirmwareBoundaries(fw, mech)
