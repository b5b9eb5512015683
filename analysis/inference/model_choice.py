"""Model choice of a calibration: is an extra parameter (guide friction beside c) supported over the fit without it?

The calibration (`rimless.analysis.inference.calibrate`) solves the fit again without the extra parameter (held at
the wheel's value, 0 for friction; the same residual sigmas; `refit_without` from the solution with it dropped
and from the Gauss-Newton prediction of where the others go, `predicted_without`, on from where it stopped when
it stops on its budget) and hands over delta chi^2 = chi^2 without - chi^2 with, on its residuals scaled by the solution's sigmas. Against chi^2_1 that likelihood-ratio statistic
assumes the scaled residuals are independent with unit variance. They are not: each trial's residuals share the
error of its measured slope (which shifts all its periods together, as a constant loss per step does) and the
imported CoM height and impact times carry correlated errors, so delta chi^2 is larger than chi^2_1 on a wheel
without friction (7 of 30 false claims at p < 0.01 on the model's own truth, `rimless trials adequacy-coverage`).

The test here is a **quasi-likelihood** test: the statistic is scaled by the dispersion the data show in the
direction of the extra parameter,

    F = delta chi^2 / phi,   phi = (se / se_model)^2 (at least 1),

se_model the parameter's standard error from the Jacobian with the block sigmas (independent residuals, the
model right: the one the likelihood ratio assumes; in the linear regime delta chi^2 = (estimate / se_model)^2)
and se the standard error the calibration carries (`dispersion`): the larger of the model's with each trial's
slope uncertainty in quadrature and the trial-clustered sandwich (within-trial correlation and model mismatch,
seen through the trials' scatter), with the held parameters' part in quadrature when it was computed. So F is,
in the linear regime, (estimate / se)^2: the test and the reported interval agree, and the test carries what
the interval carries. phi is the variance-inflation factor of the misspecified likelihood ratio for one
parameter (Kent 1982: under misspecification delta chi^2 tends to phi chi^2_1 with phi the ratio of the
sandwich variance to the model's), with the slopes' and held parameters' stated uncertainties added.

Reference distribution: F(1, nu) with nu the degrees of freedom of the estimate that set phi: infinite
(chi^2_1) when it came from the stated slope or held-parameter uncertainties or the model, n_trials - 1 when the
trial-clustered sandwich set it (a variance estimated from that many trials' scatter). On the bound (a force at
0 under the simpler model) the null is half the point mass at 0 and half F(1, nu): p halved. The extra parameter
is supported when p < `MODEL_CHOICE_P` and the simpler fit converged; when it stopped on its budget however it
was started, delta chi^2 is only an upper bound and the choice is undecided (``decided`` False), never "not
supported".

Measured on the model's own truth (docs/trials.md, `rimless trials adequacy-coverage --scenario
choice-null,choice-friction --series 30 --seed 0`): friction claimed on 0 of 30 frictionless series (the plain
likelihood ratio on the same fits: 8 of 30) and found on 2 of 30 with F_c 0.1-0.6 N (plain: 20 of 30); phi came
from the slopes' part in 56 of 60 series (median 46 and 91): with four trials, F_c trades with the slopes' errors,
and the test is as strong as the stated slope uncertainty lets it be. With the fit without friction started also
from its prediction (`refit_without`; the same study, 20 series, main's code and this one on the same draws):
found in 6 of 20 (was 5), none undecided (was 1, delta chi^2 1.1e5), and no delta chi^2 above 908 (main's
included 2.1e5 and 2.5e5 from a fit without friction stuck far from its minimum; docs/trials.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

#: extra parameters: each is claimed only when the quasi-likelihood test supports it over the fit without it
#: (held at the wheel's value, 0 for friction), with the reason it is extra
EXTRA_PARAMETERS = {"guide_friction_n": "a second loss beside the damper (Coulomb friction in the guides)"}
MODEL_CHOICE_P = 0.01  # the test's p-value below which an extra parameter is supported
#: further rounds (each `calibrate.MAX_NFEV` evaluations) the fit without the extra parameter may take after the
#: calibration's own ``max_rounds`` from its best start, before the other start is tried (`refit_without`)
EXTRA_ROUNDS = 3
TEST_NAME = "quasi-likelihood ratio: F = delta chi^2 / dispersion against F(1, nu)"


def dispersion(
    se_model: float,
    se_slope: float = math.nan,
    se_sandwich: float = math.nan,
    se_held: float | None = None,
    n_trials: int = 0,
) -> dict[str, Any]:
    """phi = (se / se_model)^2, at least 1, with se the carried standard error: max(hypot(se_model, se_slope),
    se_sandwich), with ``se_held`` in quadrature (any unit, the same for all). Returns ``dispersion`` (phi),
    ``source`` (what set it: "model", "slopes", "trial scatter", "held parameters"), ``dof`` (nu: None for
    infinite, n_trials - 1 for the trial scatter) and the parts. A missing or non-finite part is left out; phi is
    1 (the plain likelihood ratio) when se_model is not finite and positive."""
    parts = {"se_model": se_model, "se_slope": se_slope, "se_sandwich": se_sandwich, "se_held": se_held}
    out: dict[str, Any] = {"dispersion": 1.0, "source": "model", "dof": None, "parts": parts}
    if not (math.isfinite(se_model) and se_model > 0):
        out["source"] = "model (no finite standard error: not scaled)"
        return out
    with_slopes = math.hypot(se_model, se_slope) if math.isfinite(se_slope) else se_model
    se, source, dof = with_slopes, ("slopes" if with_slopes > se_model else "model"), None
    if math.isfinite(se_sandwich) and se_sandwich > se:
        se, source, dof = se_sandwich, "trial scatter", max(n_trials - 1, 1)
    if se_held is not None and math.isfinite(se_held) and se_held > 0:
        total = math.hypot(se, se_held)
        if se_held > se:  # the larger part names the source; the dof stay the estimated part's
            source = "held parameters"
        se = total
    out.update(dispersion=max((se / se_model) ** 2, 1.0), source=source, dof=dof)
    return out


def quasi_likelihood_p(delta_chi2: float, phi: float, dof: int | None, boundary: bool) -> tuple[float, float]:
    """(F = delta_chi2 / phi, its upper-tail p-value against F(1, dof), chi^2_1 when dof is None), p halved on
    the boundary (half the null's mass at 0)."""
    from scipy.stats import chi2, f

    stat = max(delta_chi2, 0.0) / max(phi, 1.0)
    p = float(chi2.sf(stat, 1)) if dof is None else float(f.sf(stat, 1, dof))
    return stat, p * (0.5 if boundary else 1.0)


DETECTION_POWER = 0.8  # the power at which `detectable_above` states the smallest value the test would find


def detectable_above(
    se_model: float,
    phi: float,
    dof: int | None,
    boundary: bool,
    p: float = MODEL_CHOICE_P,
    power: float = DETECTION_POWER,
) -> float:
    """The smallest departure of the extra parameter from its held value that the quasi-likelihood test would
    find with probability ``power`` at p < ``p`` (same unit as ``se_model``): in the linear regime delta chi^2 /
    phi is noncentral chi^2_1 (F(1, dof) noncentral when dof is given) with noncentrality
    lambda = delta^2 J_j^T (I - P_others) J_j / phi = (delta / se_model)^2 / phi (se_model^2 the inverse of that
    Schur complement, in the parameter's unit: the Jacobian's projection off the other unknowns); lambda solved
    for the power (scipy.stats.ncx2 / ncf), on the bound against the halved p. NaN when se_model is not finite."""
    from scipy.optimize import brentq
    from scipy.stats import chi2, f, ncf, ncx2

    if not (math.isfinite(se_model) and se_model > 0):
        return math.nan
    alpha = 2.0 * p if boundary else p  # p halved on the bound: the statistic's critical value is at 2p
    if dof is None:
        crit = float(chi2.isf(alpha, 1))

        def gap(lam: float) -> float:
            return float(ncx2.sf(crit, 1, lam)) - power
    else:
        crit = float(f.isf(alpha, 1, dof))

        def gap(lam: float) -> float:
            return float(ncf.sf(crit, 1, dof, lam)) - power

    hi = 10.0
    while gap(hi) < 0 and hi < 1e6:
        hi *= 4.0
    lam = float(brentq(gap, 1e-9, hi, xtol=1e-10))
    return se_model * math.sqrt(lam * max(phi, 1.0))


def predicted_without(J: np.ndarray, f: np.ndarray, j: int, step_j: float) -> np.ndarray:
    """The Gauss-Newton (linear) prediction of the fit without parameter j from the fit with it: the step d
    that minimises |f + J d|^2 with d_j = ``step_j`` (the parameter moved to where it is held), every other
    component free (f the scaled residuals at the solution, J their Jacobian, in the optimiser's variables). A
    fit with guide friction dropped must move c (and each trial's release) to make up the lost loss per step:
    started where the fit with it ended, the least squares have that whole way to go on its budget."""
    others = [k for k in range(J.shape[1]) if k != j]
    d = np.zeros(J.shape[1])
    d[j] = step_j
    d[others] = np.linalg.lstsq(J[:, others], -(f + J[:, j] * step_j), rcond=None)[0]
    return d


def refit_without(
    starts: Sequence[tuple[str, np.ndarray]],
    cost: Callable[[np.ndarray], float],
    solve: Callable[[np.ndarray, int], Any],
    gain_left: Callable[[np.ndarray], float],
    max_rounds: int,
    extra_rounds: int = EXTRA_ROUNDS,
) -> tuple[Any, dict[str, Any]]:
    """The fit without the extra parameter, made to converge or to say why not. From the start of lowest
    chi^2 (``starts``: label, point), ``solve(x, rounds)`` (a scipy result with ``status`` 0 when it stopped
    on its budget, ``rounds``, ``nfev_total``) for ``max_rounds`` rounds, then on from where it stopped for
    ``extra_rounds`` more; when it still stopped on its budget, the same from the next start; the lowest chi^2
    is kept. Returns (its result, the JSON ``simpler_optimizer``: each start tried with its chi^2 before and
    after, its rounds and evaluations; the kept start; ``converged``; when not, ``gain_left_chi2``, what a
    Gauss-Newton step from where it stopped would still gain)."""
    ranked = sorted(((float(cost(x)), label, x) for label, x in starts), key=lambda t: t[0])
    tried: list[dict[str, Any]] = []
    best: tuple[float, Any, str] | None = None
    for chi2_start, label, x in ranked:
        r = solve(x, max_rounds)
        rounds, nfev = int(r.rounds), int(r.nfev_total)
        if r.status == 0 and extra_rounds > 0:  # stopped on its budget: on from where it stopped
            r = solve(r.x, extra_rounds)
            rounds, nfev = rounds + int(r.rounds), nfev + int(r.nfev_total)
        chi2_end = float(cost(r.x))
        tried.append(
            {
                "start": label,
                "chi2_start": chi2_start,
                "chi2": chi2_end,
                "converged": bool(r.status > 0),
                "status": int(r.status),
                "rounds": rounds,
                "nfev": nfev,
            }
        )
        if best is None or chi2_end < best[0]:
            best = (chi2_end, r, label)
        if r.status > 0:
            break
    assert best is not None, "refit_without needs a start"
    chi2_end, r, label = best
    row: dict[str, Any] = {
        "converged": bool(r.status > 0),
        "status": int(r.status),
        "message": str(r.message),
        "start": label,
        "rounds": sum(t["rounds"] for t in tried),
        "nfev": sum(t["nfev"] for t in tried),
        "starts": tried,
    }
    if not row["converged"]:
        row["gain_left_chi2"] = float(gain_left(r.x))
    return r, row


def choice_row(
    name: str,
    simpler_fit: list[str],
    held_at: float,
    chi2_with: float,
    chi2_without: float,
    simpler_converged: bool,
    without: Mapping[str, float],
    disp: Mapping[str, Any],
    simpler_optimizer: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON row of one extra parameter: the likelihood-ratio figures (``delta_chi2``, ``p_value_chi2`` the
    plain chi^2_1 p), the quasi-likelihood test's (``dispersion``, ``dispersion_source``, ``dispersion_dof``,
    ``statistic``, ``p_value``, ``test``), ``supported``, ``decided`` (False when the fit without it stopped on
    its budget: then delta chi^2 is only an upper bound, and the statement says what the budget left,
    ``simpler_optimizer`` from `refit_without`), ``calibrated_model`` (which fit the calibrated model is: "with"
    it when supported or undecided, "without" it when not supported) and the ``statement`` naming the dispersion
    used. ``without`` holds the fit without it's values only when that fit converged: an undecided row's are
    where it stopped, ``simpler_optimizer["stopped_at"]``, never a result."""
    from scipy.stats import chi2

    delta = max(chi2_without - chi2_with, 0.0)
    boundary = name == "guide_friction_n" and held_at == 0.0
    phi, dof = float(disp["dispersion"]), disp["dof"]
    stat, p = quasi_likelihood_p(delta, phi, dof, boundary)
    supported = bool(p < MODEL_CHOICE_P and simpler_converged)
    nu = "inf" if dof is None else str(dof)
    limit = detectable_above(float(disp["parts"].get("se_model", math.nan)), phi, dof, boundary)
    limit_text = (
        f"; these trials would find {name} only {'above' if boundary else 'beyond'} {held_at:g} "
        f"{'+' if boundary else '+-'} {limit:.3g} ({DETECTION_POWER:.0%} power at p < {MODEL_CHOICE_P:g})"
        if math.isfinite(limit)
        else ""
    )
    test = (
        f"delta chi^2 = {delta:.3g} / dispersion {phi:.3g} (from the {disp['source']}) = {stat:.3g} against "
        f"F(1, {nu}){', p halved on the bound' if boundary else ''}: p = {p:.2g}"
    )
    if supported:
        why = f"supported over the fit without it: {test}"
    elif simpler_converged:
        why = (
            f"not supported over the fit without it ({name} held at {held_at:g}): {test} >= {MODEL_CHOICE_P:g}"
            + limit_text
        )
    else:
        why = f"undecided: {_budget_statement(simpler_optimizer)}; " + (
            f"delta chi^2 = {delta:.3g} is only an upper bound (the test on it: {test}), the test cannot be made; "
            f"the calibrated model is the fit with {name} (converged), {name} not claimed"
        )
    opt = dict(simpler_optimizer) if simpler_optimizer is not None else None
    if not simpler_converged:  # where the unfinished fit stopped: a diagnosis, not a result
        opt = {**(opt or {}), "stopped_at": dict(without)}
    return {
        "why_extra": EXTRA_PARAMETERS.get(name, ""),
        "simpler_fit": list(simpler_fit),
        "held_at": held_at,
        "chi2_with": chi2_with,
        "chi2_without": chi2_without,
        "delta_chi2": delta,
        "p_value": p,
        "p_value_chi2": float(chi2.sf(delta, 1)) * (0.5 if boundary else 1.0),
        "dispersion": phi,
        "dispersion_source": disp["source"],
        "dispersion_dof": dof,
        "dispersion_parts": {k: _finite(v) for k, v in disp["parts"].items()},
        "statistic": stat,
        "test": TEST_NAME,
        "delta_aic": delta - 2.0,
        "boundary": boundary,
        "supported": supported,
        "threshold_p": MODEL_CHOICE_P,
        "detectable_above": _finite(limit),
        "detection_power": DETECTION_POWER,
        "without": dict(without) if simpler_converged else {},
        "decided": bool(simpler_converged),
        "calibrated_model": "without" if simpler_converged and not supported else "with",
        "simpler_optimizer": opt,
        "statement": why,
    }


def _budget_statement(opt: Mapping[str, Any] | None) -> str:
    """Why the fit without the extra parameter stopped: its rounds, evaluations and starts, and the chi^2 a
    Gauss-Newton step from where it stopped would still gain."""
    if not opt:
        return "the fit without it did not converge"
    gain = opt.get("gain_left_chi2")
    left = f"; a Gauss-Newton step from there would still lower its chi^2 by about {gain:.3g}" if gain else ""
    return (
        f"the fit without it stopped on its budget ({opt['rounds']} rounds, {opt['nfev']} evaluations, "
        f"{len(opt['starts'])} start(s), best from {opt['start']}: {opt['message']}){left}"
    )


def _finite(v: float | None) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None
