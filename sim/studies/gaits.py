"""The work behind `rimless sim fixed-point`, `gaits` and `critical-slope`: one call each, returning the plain
dict `--json` emits (keys of rimless.sim.studies.summary). Inputs are validated here, errors name the option
(ParameterError); a valid input without a result raises RunFailure."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rimless.errors import ParameterError, RunFailure

GaitsProgress = Callable[[int, int], None] | None


def guess_from_options(
    params: Any, model: str, theta_dot_guess: float | None, theta_plus_guess: float | None = None
) -> np.ndarray:
    """The default section guess (theta+ rad, theta'+ rad/s), with either value overridden."""
    from rimless.sim.model.params import SPOKE_ANGLE_RAD
    from rimless.sim.step.poincare import default_guess

    z = default_guess(params, model)
    if theta_dot_guess is not None:
        if not (math.isfinite(theta_dot_guess) and theta_dot_guess > 0):
            raise ParameterError(
                f"--theta-dot-guess must be a positive angular velocity in rad/s, got {theta_dot_guess}"
            )
        z[1] = theta_dot_guess
    if theta_plus_guess is not None:
        if not (math.isfinite(theta_plus_guess) and -SPOKE_ANGLE_RAD < theta_plus_guess < 0):
            raise ParameterError(
                f"--theta-plus-guess must be a stance angle in (-{SPOKE_ANGLE_RAD:.4f}, 0) rad, got {theta_plus_guess}"
            )
        z[0] = theta_plus_guess
    return z


def start_guess(
    params: Any,
    model: str,
    *,
    theta_dot_guess: float | None,
    theta_plus_guess: float | None,
    gait: int | None,
    backend: str,
    rtol: float,
    progress: GaitsProgress = None,
) -> np.ndarray:
    """The section point to start Newton from: gait N of the `gaits` scan, or the (overridden) default guess.

    progress(i, n): guesses of the gait scan done (only with `gait`)."""
    if gait is None:
        return guess_from_options(params, model, theta_dot_guess, theta_plus_guess)
    if theta_dot_guess is not None or theta_plus_guess is not None:
        raise ParameterError("give either --gait or --theta-dot-guess/--theta-plus-guess, not both")
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import find_gaits

    pmap = make_map(params, model, backend=backend, rtol=rtol)
    found = find_gaits(pmap, progress=progress, include_invalid=True)
    if not found:
        raise RunFailure(f"--gait {gait}: no period-1 gait of the {model} wheel at {params.slope_deg:.4f} deg")
    if gait > len(found):
        raise ParameterError(
            f"--gait {gait}: only {len(found)} gait(s) of the {model} wheel at "
            f"{params.slope_deg:.4f} deg (see `rimless sim gaits`)"
        )
    fp = found[gait - 1]
    if fp.bilateral:
        from rimless.sim.continuation.branches import contact_reason
        from rimless.sim.continuation.contact import contact_facts
        from rimless.sim.step.poincare import bilateral_map

        raise RunFailure(
            f"--gait {gait}: that gait of the {model} wheel violates unilateral contact "
            f"({contact_reason(contact_facts(bilateral_map(pmap), fp.z, 5e-4))}); it exists only "
            "with the stance foot held"
        )
    return fp.z.copy()


def solve_or_search(
    pmap: Any,
    guess: np.ndarray,
    *,
    jacobian: Any = None,
    diagnostics: bool = False,
    strict_contact: bool = False,
    progress: GaitsProgress = None,
) -> tuple[Any, str]:
    """The period-1 gait nearest `guess` (theta+ rad, theta'+ rad/s): Newton from the guess, and when that fails,
    the gaits search (find_gaits, as `rimless sim gaits`) and its stable gait nearest the guess in theta'+ (an
    unstable one if none is stable). Returns (FixedPoint, how it was found: "newton" or "gaits search").
    Raises the Newton failure (NoFixedPoint) when the search finds no gait either."""
    from rimless.errors import interrupted_by_user
    from rimless.sim.step.poincare import NoFixedPoint, find_gaits, solve_fixed_point

    try:
        return solve_fixed_point(
            pmap, guess, jacobian=jacobian, diagnostics=diagnostics, strict_contact=strict_contact
        ), "newton"
    except NoFixedPoint as err:
        newton_failure = err
    if _integrator_gave_up(newton_failure.last_failure):  # the search would fail the same way at every guess
        raise newton_failure
    try:
        found = find_gaits(pmap, progress=progress)
    except Exception as err:
        if interrupted_by_user(err):
            raise KeyboardInterrupt from err
        raise newton_failure from None
    if not found:
        raise newton_failure
    pool = [fp for fp in found if fp.stable] or found
    best = min(pool, key=lambda fp: abs(float(fp.z[1]) - float(guess[1])))
    fp = solve_fixed_point(pmap, best.z, jacobian=jacobian, diagnostics=diagnostics, strict_contact=strict_contact)
    return fp, "gaits search"


def _integrator_gave_up(err: Any) -> bool:
    from rimless.sim.model.failures import FailureReason

    return err is not None and getattr(err, "reason", None) is FailureReason.INTEGRATION


def check_integrable(pmap: Any, params: Any, model: str, z: np.ndarray) -> None:
    """Raise RunFailure at once when the integrator gives up on one step from `z` (its step budget spent, as
    with very light, stiff legs): a scan of guesses would spend that budget at every guess (minutes) to
    find nothing. A step failing for a physical reason (stall, lift-off) passes: another guess may walk."""
    from rimless.sim.model.failures import StepFailure

    try:
        pmap(z)
    except StepFailure as err:
        if not _integrator_gave_up(err):
            return
        leg_period = 2 * math.pi * math.sqrt(params.leg_mass_kg / params.k)
        raise RunFailure(
            f"no period-1 gait can be searched for the {model} wheel: the integrator gives up on one "
            f"step from theta'+ = {z[1]:.3f} rad/s ({err}); legs of {params.leg_mass_kg:g} kg on "
            f"k = {params.k:g} N/m oscillate with period {leg_period:.2g} s against a step of about "
            "0.3 s"
        ) from None


def fixed_point_study(
    params: Any,
    model: str,
    *,
    theta_dot_guess: float | None = None,
    theta_plus_guess: float | None = None,
    gait: int | None = None,
    strict_contact: bool = False,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: GaitsProgress = None,
    power: Any = None,
) -> dict[str, Any]:
    """The period-1 gait from the start guess: fixed point, eigenvalues, period and contact diagnostics, and its
    cost of transport (mechanical_cot, electrical_energy_per_step_j, system_cot; power: a ClutchPower, default
    none)."""
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.step.poincare import solve_fixed_point
    from rimless.sim.studies.summary import fixed_point_summary

    guess = start_guess(
        params,
        model,
        theta_dot_guess=theta_dot_guess,
        theta_plus_guess=theta_plus_guess,
        gait=gait,
        backend=backend,
        rtol=rtol,
        progress=progress,
    )
    pmap = make_map(params, model, backend=backend, rtol=rtol)
    jf = jacobian_factory(backend)
    jacobian = jf(pmap) if jf else None
    try:
        if theta_dot_guess is None and theta_plus_guess is None and gait is None:
            # the default guess: when Newton fails from it, the gaits search finds the gait if there is one
            fp, found_by = solve_or_search(
                pmap, guess, jacobian=jacobian, diagnostics=True, strict_contact=strict_contact, progress=progress
            )
        else:  # a guess the user chose is followed as given
            fp = solve_fixed_point(pmap, guess, jacobian=jacobian, diagnostics=True, strict_contact=strict_contact)
            found_by = "newton"
    except StepFailure as err:
        searched = (
            " or by the gaits search" if theta_dot_guess is None and theta_plus_guess is None and gait is None else ""
        )
        raise RunFailure(
            f"no period-1 gait found for the {model} wheel from the guess "
            f"theta+ = {guess[0]:.4f} rad, theta'+ = {guess[1]:.4f} rad/s{searched}: {err}"
        ) from None
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.step.cot import step_cot

    out = fixed_point_summary(fp, params, model, guess=guess)
    out["found_by"] = found_by
    power = power or ClutchPower()
    out.update(step_cot(fp.step, params, model, power))
    out["electrical_power"] = power.as_dict()
    return out


def gait_scan(
    params: Any,
    model: str,
    *,
    theta_dot_min: float = 0.8,
    theta_dot_max: float = 6.0,
    guesses: int = 14,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: GaitsProgress = None,
) -> dict[str, Any]:
    """Every period-1 gait at one slope (theta'+ guesses in [min, max] rad/s), each with its contact facts."""
    from rimless.sim.continuation.branches import contact_reason
    from rimless.sim.continuation.contact import contact_facts
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import bilateral_map, find_gaits

    if not 0 < theta_dot_min < theta_dot_max:
        raise ParameterError("need 0 < --theta-dot-min < --theta-dot-max (rad/s)")
    pmap = make_map(params, model, backend=backend, rtol=rtol)
    from rimless.sim.step.poincare import default_guess

    check_integrable(pmap, params, model, default_guess(params, model))
    found = find_gaits(
        pmap, theta_dot_range=(theta_dot_min, theta_dot_max), n_guesses=guesses, progress=progress, include_invalid=True
    )
    items = []
    for fp in found:
        try:  # a gait found with the stance foot held is recorded that way too
            facts = contact_facts(bilateral_map(pmap) if fp.bilateral else pmap, fp.z, 5e-4)
        except StepFailure:
            facts = None
        items.append(
            {
                "theta_plus_rad": float(fp.z[0]),
                "theta_dot_plus_rad_s": float(fp.z[1]),
                "step_period_s": fp.recorded_step.period_s,
                "eigenvalues": [[float(e.real), float(e.imag)] for e in fp.eigenvalues],
                "max_abs_eigenvalue": fp.max_abs_eigenvalue,
                "stable": fp.stable,
                "energy_ratio": fp.recorded_step.impact.energy_ratio,
                "contact_valid": bool(facts is not None and facts.contact_valid),
                "contact_reason": contact_reason(facts),
                "contact_violation": facts.violation if facts is not None else "unknown",
                "contact_model": "bilateral" if fp.bilateral else "unilateral",
                "contact": facts.as_dict() if facts is not None else None,
            }
        )
    return {"model": model, "slope_rad": params.slope_rad, "k": params.k, "c": params.c, "gaits": items}


def critical_slope_study(
    params: Any,
    model: str,
    *,
    theta_dot_guess: float | None = None,
    theta_plus_guess: float | None = None,
    gait: int | None = None,
    step_rad: float = 0.001,
    start_slope_rad: float | None = 0.05,
    strict_contact: bool = False,
    backend: str = "auto",
    rtol: float = 1e-10,
    gaits_progress: GaitsProgress = None,
    progress: Callable[[float], None] | None = None,
    power: Any = None,
) -> dict[str, Any]:
    """Critical slope and minimum cost of transport: Algorithm 1 from `start_slope_rad` and the refined end of
    the branch; model "rigid" gives the closed form (it takes no slope: start_slope_rad None). progress(slope_rad): the continuation's current slope.
    power (a ClutchPower, default none): also the cost of transport at the critical slope and the least system
    CoT along the branch (rimless.sim.studies.system_cot)."""
    from rimless.sim.studies.summary import critical_slope_summary, rigid_summary

    if model == "rigid":
        if power is not None and not power.is_zero:
            raise ParameterError(
                "--clutch-hold-power-w, --clutch-switch-energy-j, --electronics-power-w: the rigid "
                "wheel (closed form) has no clutch and no step record; use --model er or ve"
            )
        return rigid_summary(params)
    from rimless.sim.continuation.algorithm1 import critical_slope
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import SPOKE_ANGLE_RAD
    from rimless.sim.step.backend import jacobian_factory, make_map

    if start_slope_rad is None or not 0 < start_slope_rad < SPOKE_ANGLE_RAD / 2:
        raise ParameterError(f"--start-slope-rad must be in (0, {SPOKE_ANGLE_RAD / 2:.4f}) rad, got {start_slope_rad}")
    start_params = params.replace(slope_rad=start_slope_rad)
    pmap = make_map(start_params, model, backend=backend, rtol=rtol)
    guess = start_guess(
        start_params,
        model,
        theta_dot_guess=theta_dot_guess,
        theta_plus_guess=theta_plus_guess,
        gait=gait,
        backend=backend,
        rtol=rtol,
        progress=gaits_progress,
    )
    try:
        cs = critical_slope(
            pmap,
            guess,
            start_slope_rad=start_slope_rad,
            step_rad=step_rad,
            strict_contact=strict_contact,
            jacobian_factory=jacobian_factory(backend),
            progress=progress,
        )
    except StepFailure as err:
        raise RunFailure(f"critical slope of the {model} wheel: {err}") from None
    out = critical_slope_summary(cs, params)
    out.update(critical_slope_cot(cs, params, model, power, backend=backend, rtol=rtol))
    return out


def critical_slope_cot(cs: Any, params: Any, model: str, power: Any, *, backend: str, rtol: float) -> dict[str, Any]:
    """The cost of transport at the critical slope and the least system CoT along the stable part of the branch."""
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.step.cot import cot_of
    from rimless.sim.studies.system_cot import critical_slope_branch

    power = power or ClutchPower()
    br = critical_slope_branch(cs, params, backend, rtol)
    tr = br.transport(br.lo_rad)
    out: dict[str, Any] = {}
    if tr is not None:
        out.update(cot_of(tr, params.replace(slope_rad=br.lo_rad), model, power))
    out.update(br.minimise(power))
    out["electrical_power"] = power.as_dict()
    return out
