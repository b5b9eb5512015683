"""The wheel's inertia ratio from its trials: what the step periods determine of the stance pendulum.

The verdicts and the critical slope from trials use the wheel only through the rigid stance pendulum
(`rimless.analysis.inference.sustained.StancePendulum`). For the rigid wheel of the eight-leg mass model
(M = m_H + 8 m, I_hub = I_c + 8 m L0^2) that pendulum and its impact depend on the masses and the inertia only
through the **inertia ratio** r = I_hub / (M L0^2):

- the stance: theta'^2 = e + kappa (1 - cos(theta + phi)), kappa = 2 g / (L0 (1 + r)) (1/s^2);
- the impact (angular momentum about the new foot): theta'+ = beta theta'-, beta = (r + cos alpha) / (r + 1);

so the squared speed over the top of consecutive steps obeys the exact affine return map (Coleman)
``e_{k+1} = beta^2 e_k + kappa [beta^2 (1 - cos(alpha/2 + phi)) - (1 - cos(alpha/2 - phi))]``, where every
e_k is the measured period T_k turned into a speed through the pendulum (`StancePendulum.energy`). A wrong r
bends both the conversion and the map, so r is estimated by **weighted least squares over every pair of
consecutive periods of every trial**, each residual ``e_{k+1} - map(e_k)`` weighed by the timing noise of both
periods through de/dT and the slope's uncertainty, with a constant loss per step (guide friction, in e) profiled
out beside it. The pendulum is kappa and beta, so the periods fix L0 as well as r: **r and L0 are fitted
together** (`_fit_joint`; g held). There each trial's slope error is what it is, an offset shared by
all its pairs (d b / d phi times the slope's sd, standard normal, profiled out per trial: generalised least
squares of a rank-one block), the timing noise is scaled by the residuals of a first pass (never below
`K_TIMING_FLOOR` of the weights': the importer's period errors are below the 1.4 ms floor), and r's standard
error carries L0's, the loss's and the slopes' (the Gauss-Newton covariance, inflated by the reduced chi^2 above
1, or the sandwich over trials when larger). Held at a wrong L0 (Table 1's 237 mm for a
wheel of 210-260 mm) the one-dimensional fit's r is the effective ratio that pendulum needs, not the wheel's: on 120
series of `rimless.analysis.validation.importer_coverage` its interval held the truth's r in 41 of 120 (at the
truth's L0: 119), the joint fit's in 120 of 120 (rms z 0.3-0.5: wide, mostly from the importer's slope sds;
with them a third, rms z 0.74 on 80); guide friction made no difference. That ratio at the held L0
(``ratio_at_held_l0``, JSON ``inertia_ratio_at_held_leg_length``) is still the one I_c is given from: the
verdicts' pendulum is made at the held L0. A compliant wheel's stance is not this pendulum: its r is then the
effective one (the reduced chi^2 at the held L0 says how well it fits), and so is the joint fit's L0 (on
the bundled compliant ER series the periods act as a rigid pendulum of L0 = 129-141 mm, reduced chi^2 0.4,
against legs of 237 mm): the verdict (JSON ``rigid_map_verdict``) is "fits" only when the map at the held L0
passes its test with r inside its range and I_c > 0, else "does not fit: effective only" (a fit exists, with
L0 fitted) or "does not fit: not estimated" (none; r at its bound and a negative I_c are no values), with the
reason. The masses only set I_c = r M L0^2 - 8 m L0^2.

`trial_inertia_input` uses it: a wheel input whose inertia is not stated (source ``table1``) takes the trials'
I_c (source ``trials``, its sd from the fit at the held L0); a stated one is compared with it, and a stated L0
with the periods' L0: a disagreement beyond their combined uncertainty is a warning. An effective-only ratio
(the rigid map at the held L0 does not fit) is neither used nor compared: it is no measurement of the wheel's
inertia (the models' critical slopes would be made at it). Too few consecutive periods (fewer than `MIN_PAIRS`
pairs) leave the input as it is, with a note.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["InertiaEstimate", "estimate_inertia_ratio", "trial_inertia_input", "inertia_ratio", "MIN_PAIRS"]

MIN_PAIRS = 6  # consecutive-period pairs needed for an estimate
R_BOUNDS = (0.02, 50.0)  # the inertia ratios searched
Z_DISAGREE = 2.0  # a stated inertia further than this many combined standard errors from the trials' is a warning
#: above this reduced chi^2 the rigid return map does not describe the periods (a compliant wheel: measured 3-8 on
#: the ER truth of tests/support/analysis_trial_truth.py, on that truth before 88dc178 (uncompressed hold), 0.1-0.6
#: on rigid truths): the ratio is effective only
CHI2_ADEQUATE = 2.0
#: the joint fit searches L0 within this factor of the held one
L0_FACTOR = 2.0
#: the least scale of the timing noise the joint fit takes from its residuals (of the weights' floor)
K_TIMING_FLOOR = 0.2
ASSUMED_JOINT = (
    "rigid stance pendulum and impact; r, L0, a constant loss per step and each trial's slope error (within "
    "its sd) fitted together from the periods, g held: r's se includes L0's, the loss's and the slopes'"
)
VERDICT_FITS = "fits"
VERDICT_EFFECTIVE = "does not fit: effective only"
VERDICT_NO_FIT = "does not fit: not estimated"
VERDICT_NOT_TRIED = "not estimated"
NOT_JOINT = "the joint fit of r and L0 not made: only the ratio at the held L0 was asked for"
ASSUMED_HELD_L0 = (
    "rigid stance pendulum and impact at the held L0 and g (a constant loss per step fitted beside r; L0's "
    "uncertainty not in r's se)"
)


def inertia_ratio(params: Any) -> float:
    """r = I_hub / (M L0^2) of the eight-leg-consistent rigid wheel of ``params`` (`WheelParams`)."""
    m8 = 8.0 * params.leg_mass_kg
    L = params.leg_length_m
    return (params.inertia_kg_m2 + m8 * L**2) / ((params.hub_mass_kg + m8) * L**2)


def inertia_for_ratio(params: Any, r: float) -> float:
    """The I_c (kg m^2) that gives ``params`` the inertia ratio r."""
    m8 = 8.0 * params.leg_mass_kg
    L = params.leg_length_m
    return r * (params.hub_mass_kg + m8) * L**2 - m8 * L**2


@dataclass
class _Pairs:
    """Consecutive periods (s) of all trials, with each pair's slope (rad) and timing noise (s)."""

    t0: np.ndarray
    t1: np.ndarray
    phi: np.ndarray
    sig: np.ndarray
    phi_sd: np.ndarray  # the slope's 1-sigma uncertainty, rad
    trial: np.ndarray  # the index of the trial each pair comes from


def _pairs(trials: Sequence[Any], alpha: float) -> _Pairs:
    from rimless.analysis.inference.sustained import TIMING_SIGMA_FLOOR_S, consecutive_periods, trial_slope_sigma_deg

    t0: list[float] = []
    t1: list[float] = []
    phi: list[float] = []
    sig: list[float] = []
    phi_sd: list[float] = []
    trial: list[int] = []
    for i_trial, tr in enumerate(trials):
        slope = float(getattr(tr.meta, "slope_deg", math.nan))
        if not (math.isfinite(slope) and 0.0 < math.radians(slope) < alpha / 2):
            continue
        rate = float(getattr(tr.meta, "rate_hz", 0.0) or 0.0)
        s = max(TIMING_SIGMA_FLOOR_S, 0.1 * math.sqrt(2.0) / rate) if rate > 0 else TIMING_SIGMA_FLOOR_S
        s_phi = math.radians(trial_slope_sigma_deg(tr.meta)[0])
        for c in consecutive_periods(tr):
            c = np.asarray(c, float)
            n = c.size - 1
            if n > 0:
                t0.extend(c[:-1])
                t1.extend(c[1:])
                phi.extend([math.radians(slope)] * n)
                sig.extend([s] * n)
                phi_sd.extend([s_phi] * n)
                trial.extend([i_trial] * n)
    return _Pairs(np.array(t0), np.array(t1), np.array(phi), np.array(sig), np.array(phi_sd), np.array(trial, int))


def _period(e: np.ndarray, alpha: float, kappa: float, phi: np.ndarray) -> np.ndarray:
    """Rigid stance period (s) at squared top speeds e > 0 (vectorised `StancePendulum.period_s`)."""
    from scipy.special import ellipkinc

    m = -2.0 * kappa / e
    return 2.0 / np.sqrt(e) * (ellipkinc(0.5 * (phi + alpha / 2), m) - ellipkinc(0.5 * (phi - alpha / 2), m))


def _energy(T: np.ndarray, alpha: float, kappa: float, phi: np.ndarray) -> np.ndarray:
    """Inverse of `_period` by bisection in log e (NaN where T is outside (T(1e4), T(e^-25)))."""
    lo = np.full(T.shape, -25.0)
    hi = np.full(T.shape, math.log(1e4))
    ok = (T < _period(np.exp(lo), alpha, kappa, phi)) & (T > _period(np.exp(hi), alpha, kappa, phi))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        longer = _period(np.exp(mid), alpha, kappa, phi) > T  # too slow: raise e
        lo = np.where(longer, mid, lo)
        hi = np.where(longer, hi, mid)
    return np.where(ok, np.exp(0.5 * (lo + hi)), np.nan)


def _gaps(log_r: float, pairs: _Pairs, alpha: float, L: float, g: float) -> tuple[np.ndarray, np.ndarray]:
    """(what each step loses beyond the rigid impact, ``beta^2 e_k + b - e_{k+1}``, rad^2/s^2; its 1-sigma
    noise from the two periods' timing and the slope's uncertainty) at the inertia ratio exp(log_r); NaN where a
    measured period is outside what that pendulum can walk."""
    gap, s_timing, s_slope = _gap_parts(log_r, pairs, alpha, L, g)
    return gap, np.sqrt(s_timing**2 + s_slope**2)


def _gap_parts(
    log_r: float, pairs: _Pairs, alpha: float, L: float, g: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`_gaps` with the noise in its two parts: (gap, the periods' timing 1-sigma, the slope's 1-sigma: shared by
    every pair of a trial, d b / d phi times the slope's sd)."""
    r = math.exp(log_r)
    kappa = 2.0 * g / (L * (1.0 + r))
    beta2 = ((r + math.cos(alpha)) / (r + 1.0)) ** 2
    phi = pairs.phi
    e0 = _energy(pairs.t0, alpha, kappa, phi)
    e1 = _energy(pairs.t1, alpha, kappa, phi)
    b = kappa * (beta2 * (1.0 - np.cos(alpha / 2 + phi)) - (1.0 - np.cos(alpha / 2 - phi)))
    h = 1e-4  # de/dT by a difference in log e
    with np.errstate(invalid="ignore", divide="ignore"):
        d0 = (
            e0
            * 2
            * math.sinh(h)
            / (_period(e0 * math.exp(h), alpha, kappa, phi) - _period(e0 * math.exp(-h), alpha, kappa, phi))
        )
        d1 = (
            e1
            * 2
            * math.sinh(h)
            / (_period(e1 * math.exp(h), alpha, kappa, phi) - _period(e1 * math.exp(-h), alpha, kappa, phi))
        )
        db = kappa * (beta2 * np.sin(alpha / 2 + phi) + np.sin(alpha / 2 - phi))  # d b / d phi
        s_timing = pairs.sig * np.sqrt(d1**2 + beta2**2 * d0**2)
    return beta2 * e0 + b - e1, s_timing, db * pairs.phi_sd


def _trial_residuals(x: np.ndarray, pairs: _Pairs, alpha: float, g: float, k: float) -> tuple[np.ndarray, float]:
    """The joint fit's residuals at (log r, log L0): each trial's slope error a shared offset of its gaps
    (standard normal in units of its sd, profiled out per trial: the generalised least squares of a rank-one
    block), the constant loss per step profiled out, the timing noise scaled by ``k``; (residuals: the pairs'
    then one per trial, the degrees of freedom the trials' offsets take)."""
    gap, st, c = _gap_parts(float(x[0]), pairs, alpha, math.exp(float(x[1])), g)
    st = st * k
    ok = np.isfinite(gap) & np.isfinite(st) & (st > 0) & np.isfinite(c)
    _, inv = np.unique(pairs.trial, return_inverse=True)
    w = np.where(ok, 1.0 / np.where(ok, st, 1.0) ** 2, 0.0)
    gz = np.where(ok, gap, 0.0)
    A = np.bincount(inv, w)
    B = np.bincount(inv, w * gz)
    ct = np.bincount(inv, np.where(ok, c, 0.0)) / np.maximum(np.bincount(inv, ok.astype(float)), 1.0)
    q = 1.0 / (1.0 + ct**2 * A)  # 1 - gamma A
    den = float(np.sum(q * A))
    loss = float(np.sum(q * B)) / den if den > 0 else 0.0
    delta = ct * (B - loss * A) * q
    with np.errstate(invalid="ignore", divide="ignore"):
        res = (gz - loss - ct[inv] * delta[inv]) / st
    res = np.where(ok, res, 1e3)
    return np.concatenate([res, delta]), float(np.sum(1.0 - q))


def _residuals(log_r: float, pairs: _Pairs, alpha: float, L: float, g: float) -> np.ndarray:
    """Weighted residuals of the return map at the inertia ratio exp(log_r), with the constant loss per step
    that fits best there (profiled out); a large constant where a measured period is outside what that
    pendulum can walk."""
    gap, s = _gaps(log_r, pairs, alpha, L, g)
    loss = _weighted_loss(gap, s)
    with np.errstate(invalid="ignore", divide="ignore"):
        res = (loss - gap) / s
    return np.where(np.isfinite(res), res, 1e3)


@dataclass
class InertiaEstimate:
    """The trials' inertia ratio r = I_hub / (M L0^2) and what it gives I_c (kg m^2); ``ok`` False: none."""

    ok: bool
    note: str
    pairs: int = 0
    ratio: float = math.nan
    ratio_se: float = math.nan
    inertia_kg_m2: float = math.nan
    inertia_sd_kg_m2: float = math.nan
    reduced_chi2: float = math.nan
    at_bound: bool = False
    #: the rigid return map fits at the held L0 (reduced chi^2 <= CHI2_ADEQUATE and r inside `R_BOUNDS` with
    #: I_c > 0); None: not tested (too few pairs)
    adequate: bool | None = None
    loss_per_step: float = math.nan  # the constant loss per step fitted beside r, rad^2/s^2 (in e)
    comparison: dict[str, Any] = field(default_factory=dict)
    #: the ratio the pendulum needs at the held L0 (what I_c is given from; equal to ``ratio`` when L0 was not fitted)
    ratio_at_held_l0: float = math.nan
    ratio_at_held_l0_se: float = math.nan
    reduced_chi2_at_held_l0: float = math.nan
    held_l0_m: float = math.nan
    #: L0 the periods determine beside r (NaN: not fitted)
    leg_length_m: float = math.nan
    leg_length_sd_m: float = math.nan
    assumption: str = ""
    #: the rigid map fits with L0 fitted beside r (reduced chi^2 <= CHI2_ADEQUATE, inside the range searched);
    #: None: not tested
    fits_with_fitted_l0: bool | None = None
    #: `VERDICT_FITS`, `VERDICT_EFFECTIVE`, `VERDICT_NO_FIT` or `VERDICT_NOT_TRIED`, and why
    verdict: str = ""
    verdict_reason: str = ""
    #: where the trials' slope sds (the fit's slope noise) came from: the importer's allowance for the legs'
    #: drift per trial (`_slope_sd_from`); the same recordings imported told the wheel or not give other sds, so
    #: another reduced chi^2
    slope_sd_from: str = ""

    def as_dict(self) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "estimated": self.ok,
            "note": self.note,
            "consecutive_period_pairs": self.pairs,
            "inertia_ratio": num(self.ratio),
            "inertia_ratio_se": num(self.ratio_se),
            "inertia_kg_m2": num(self.inertia_kg_m2),
            "inertia_sd_kg_m2": num(self.inertia_sd_kg_m2),
            "reduced_chi2": num(self.reduced_chi2),
            "rigid_map_fits": self.adequate,
            "rigid_map_fits_with_fitted_leg_length": self.fits_with_fitted_l0,
            "rigid_map_verdict": self.verdict,
            "rigid_map_verdict_reason": self.verdict_reason,
            # r and L0 describe the periods' pendulum, not the wheel's (the map does not fit at the held L0)
            "effective_only": self.verdict == VERDICT_EFFECTIVE,
            "reduced_chi2_at_held_leg_length": num(self.reduced_chi2_at_held_l0),
            "loss_per_step_rad2_s2": num(self.loss_per_step),
            "leg_length_m": num(self.leg_length_m),
            "leg_length_sd_m": num(self.leg_length_sd_m),
            "held_leg_length_m": num(self.held_l0_m),
            "inertia_ratio_at_held_leg_length": num(self.ratio_at_held_l0),
            "inertia_ratio_at_held_leg_length_se": num(self.ratio_at_held_l0_se),
            "assumption": self.assumption,
            "slope_sd_from": self.slope_sd_from,
            "method": "weighted least squares of the rigid return map over consecutive step periods (log r"
            + (", log L0" if math.isfinite(self.leg_length_m) else "")
            + "; the constant loss per step profiled out)",
            **({"comparison": self.comparison} if self.comparison else {}),
        }


def _fit_at_held_l0(pairs: _Pairs, alpha: float, L: float, g: float) -> tuple[float, float, float, bool]:
    """(log r, its standard error, reduced chi^2, at the end of the range) with L0 held at ``L``."""
    from scipy.optimize import minimize_scalar

    n = int(pairs.t0.size)
    lo, hi = math.log(R_BOUNDS[0]), math.log(R_BOUNDS[1])
    grid = np.linspace(lo, hi, 25)
    cost = [float(np.sum(_residuals(x, pairs, alpha, L, g) ** 2)) for x in grid]
    i = int(np.argmin(cost))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    opt = minimize_scalar(
        lambda x: float(np.sum(_residuals(x, pairs, alpha, L, g) ** 2)),
        bounds=(a, b),
        method="bounded",
        options={"xatol": 1e-6},
    )
    x = float(opt.x)
    chi2 = float(opt.fun) / max(n - 2, 1)
    h = 1e-3
    jac = (_residuals(x + h, pairs, alpha, L, g) - _residuals(x - h, pairs, alpha, L, g)) / (2 * h)
    jj = float(jac @ jac)
    se_log = math.sqrt(max(chi2, 1.0) / jj) if jj > 0 else math.inf
    # the pairs of one trial share its slope error (and its release): a sandwich over trials, when larger
    res0 = _residuals(x, pairs, alpha, L, g)
    groups = np.unique(pairs.trial)
    if groups.size >= 2 and jj > 0:
        score = np.array([float(jac[pairs.trial == k] @ res0[pairs.trial == k]) for k in groups])
        se_cluster = math.sqrt(groups.size / (groups.size - 1) * float(score @ score)) / jj
        se_log = max(se_log, se_cluster)
    return x, se_log, chi2, bool(x - lo < 0.05 or hi - x < 0.05)


@dataclass
class _Joint:
    """The fit of log r and log L0 together (the constant loss per step profiled out)."""

    x: np.ndarray  # (log r, log L0)
    cov: np.ndarray  # 2 x 2 covariance of x
    chi2: float
    ok: bool
    why: str = ""
    timing_scale: float = 1.0  # the periods' timing noise over the weights' (`TIMING_SIGMA_FLOOR_S`)


def _fit_joint(pairs: _Pairs, alpha: float, L: float, g: float, log_r0: float) -> _Joint:
    """r and L0 from the periods together: the stance pendulum is kappa = 2 g / (L0 (1 + r)) and the impact's
    beta(r), so the periods fix both; started at (``log_r0``, held L0), L0 searched within a factor 2."""
    from scipy.optimize import least_squares

    n = int(pairs.t0.size)
    lb = [math.log(R_BOUNDS[0]), math.log(L / L0_FACTOR)]
    ub = [math.log(R_BOUNDS[1]), math.log(L * L0_FACTOR)]
    x0 = [min(max(log_r0, lb[0] + 1e-3), ub[0] - 1e-3), math.log(L)]

    k = 1.0
    for _pass in range(2):  # the timing noise's scale from the first pass's pairs (the weights' floor is above it)

        def f(x: np.ndarray, k: float = k) -> np.ndarray:
            return _trial_residuals(x, pairs, alpha, g, k)[0]

        sol = least_squares(f, x0, bounds=(lb, ub), x_scale=[0.1, 0.05], diff_step=1e-4, max_nfev=200)
        res, dof_trials = _trial_residuals(sol.x, pairs, alpha, g, k)
        dof = max(n - 3 - dof_trials, 1.0)
        chi2 = float(np.sum(res[:n] ** 2)) / dof
        x0 = list(sol.x)
        if _pass == 0:
            k = max(K_TIMING_FLOOR, math.sqrt(chi2))
    x = np.asarray(sol.x, float)
    jac = np.asarray(sol.jac, float)
    jj = jac.T @ jac
    nan2 = np.full((2, 2), math.nan)
    if not sol.success and sol.status == 0:
        return _Joint(x, nan2, chi2, False, "the joint fit of r and L0 stopped on its budget (200 evaluations)")
    if min(x[0] - lb[0], ub[0] - x[0], x[1] - lb[1], ub[1] - x[1]) < 0.02:
        return _Joint(x, nan2, chi2, False, "the joint fit of r and L0 ended at the end of the range searched")
    if np.linalg.cond(jj) > 1e12:
        return _Joint(x, nan2, chi2, False, "these periods do not separate r from L0")
    inv = np.linalg.inv(jj)
    cov = inv * max(chi2, 1.0)
    trial = np.concatenate([pairs.trial, np.unique(pairs.trial)])  # a trial's offset residual is its own
    groups = np.unique(pairs.trial)
    if groups.size >= 2:  # the sandwich over trials, when larger
        score = np.array([jac[trial == t].T @ sol.fun[trial == t] for t in groups])
        sw = inv @ (groups.size / (groups.size - 1) * score.T @ score) @ inv
        if sw[0, 0] > cov[0, 0]:
            cov = sw
    return _Joint(x, cov, chi2 * k**2, True, timing_scale=k)
    return _Joint(x, cov, chi2, True)


#: `rimless.analysis.kinematics.build.import_parameters`' sources of the legs' drift time, in words
_DRIFT_WORDS = {
    "derived": "derived from the wheel the import was told (its masses and k)",
    "assumed_bound": "the importer's bound (no wheel told: `wheel=`, `--params`)",
    "rigid_legs": "none (rigid legs)",
}


def _slope_sd_from(trials: Sequence[Any]) -> str:
    """Where the trials' slope sds came from, in words: each import's allowance for the legs' compression drift
    (its ``meta.parameters`` entry ``leg_drift_time_s``), counted by source."""
    counts: dict[str, int] = {}
    for tr in trials:
        rows = getattr(getattr(tr, "meta", None), "parameters", None) or ()
        src = next((r.get("source") for r in rows if r.get("name") == "leg_drift_time_s"), None) or "not recorded"
        counts[src] = counts.get(src, 0) + 1
    parts = [f"{_DRIFT_WORDS.get(k, k)}: {n} trial(s)" for k, n in counts.items()]
    return "each trial's slope sd as its import gives it; the legs' drift allowed in it: " + "; ".join(parts)


def estimate_inertia_ratio(trials: Sequence[Any], params: Any, *, fit_leg_length: bool = True) -> InertiaEstimate:
    """The inertia ratio the trials' consecutive step periods determine (see the module doc), at the masses, L0
    and g of ``params`` (`WheelParams`). ``fit_leg_length`` False: the ratio at the held L0 only (what I_c is
    given from: ``ok``, ``inertia_kg_m2`` and ``ratio_at_held_l0`` are the same as with it), without the joint
    fit of r and L0 (``leg_length_m`` NaN, ``ratio`` the one at the held L0; for refits at perturbed held
    parameters).

    The verdict (``verdict``, ``verdict_reason``): `VERDICT_FITS` only when the rigid map at the held L0 passes
    its goodness-of-fit test (reduced chi^2 <= `CHI2_ADEQUATE`) with r inside `R_BOUNDS` and I_c > 0;
    `VERDICT_EFFECTIVE` when a fit exists but not that one (r, and L0 when fitted, are then the periods'
    effective pendulum, not the wheel's); `VERDICT_NO_FIT` when no fit does (r at the end of its range or
    I_c <= 0, and no joint fit that fits: nothing is reported as a value); `VERDICT_NOT_TRIED` below `MIN_PAIRS`."""
    alpha, L, g = float(params.alpha), float(params.leg_length_m), float(params.gravity_m_s2)
    pairs = _pairs(trials, alpha)
    n = int(pairs.t0.size)
    if n < MIN_PAIRS:
        why = f"{n} pair(s) of consecutive step periods (need {MIN_PAIRS})"
        return InertiaEstimate(
            False, why + ": the inertia is not estimated", n, verdict=VERDICT_NOT_TRIED, verdict_reason=why
        )
    x, se_log, chi2, at_bound = _fit_at_held_l0(pairs, alpha, L, g)
    r = math.exp(x)
    est = InertiaEstimate(True, "", n, r, r * se_log, reduced_chi2=chi2, at_bound=at_bound)
    est.ratio_at_held_l0, est.ratio_at_held_l0_se, est.reduced_chi2_at_held_l0 = r, r * se_log, chi2
    est.held_l0_m = L
    est.slope_sd_from = _slope_sd_from(trials)
    m8 = 8.0 * params.leg_mass_kg
    i_c = inertia_for_ratio(params, r)
    unusable = [  # the held-L0 fit gives no value: its r is no estimate, a negative I_c no inertia
        *([f"r = {r:.3g} at the end of the range searched ({R_BOUNDS[0]:g}-{R_BOUNDS[1]:g})"] if at_bound else []),
        *([] if math.isfinite(se_log) else ["r's standard error is not finite"]),
        *([f"it gives I_c = {i_c:.3g} kg m^2 <= 0 at these masses: no inertia"] if i_c <= 0 else []),
    ]
    misfit = [] if chi2 <= CHI2_ADEQUATE else [f"reduced chi² {chi2:.2f} above {CHI2_ADEQUATE:g}"]
    held_why = "; ".join(unusable + misfit)
    est.adequate = not held_why
    est.loss_per_step = _loss(x, pairs, alpha, L, g)
    if unusable:
        est.ok = False
        est.ratio = est.ratio_se = est.ratio_at_held_l0 = est.ratio_at_held_l0_se = math.nan
    else:
        est.inertia_kg_m2 = i_c
        est.inertia_sd_kg_m2 = est.ratio_at_held_l0_se * (params.hub_mass_kg + m8) * L**2
    joint = (
        _fit_joint(pairs, alpha, L, g, x)
        if fit_leg_length
        else _Joint(np.full(2, math.nan), np.full((2, 2), math.nan), math.nan, False, NOT_JOINT)
    )
    est.fits_with_fitted_l0 = bool(joint.chi2 <= CHI2_ADEQUATE) if joint.ok else est.adequate
    held_l0 = f"the rigid return map at the held L0 {1000 * L:.1f} mm"
    if joint.ok:
        est.ratio = math.exp(float(joint.x[0]))
        est.ratio_se = est.ratio * math.sqrt(float(joint.cov[0, 0]))
        est.leg_length_m = math.exp(float(joint.x[1]))
        est.leg_length_sd_m = est.leg_length_m * math.sqrt(float(joint.cov[1, 1]))
        est.reduced_chi2 = joint.chi2
        est.assumption = ASSUMED_JOINT
        est.loss_per_step = _loss(float(joint.x[0]), pairs, alpha, est.leg_length_m, g)
        joint_text = (
            f"inertia ratio I_hub/(M L0^2) = {est.ratio:.3f} +- {est.ratio_se:.3f} from {n} pairs of consecutive "
            f"step periods (L0 = {1000 * est.leg_length_m:.1f} +- {1000 * est.leg_length_sd_m:.1f} mm and a "
            f"constant loss per step fitted beside it; reduced chi² {joint.chi2:.2f})"
        )
    else:
        est.assumption = ASSUMED_HELD_L0
        joint_text = joint.why
    at_held = f"at it the pendulum needs r = {r:.3f} +- {est.ratio_at_held_l0_se:.3f}"
    if est.adequate:
        est.verdict = VERDICT_FITS
        est.verdict_reason = (
            f"{held_l0} fits these periods (reduced chi² {chi2:.2f} <= {CHI2_ADEQUATE:g}, r inside the range "
            "searched, I_c > 0)"
        )
        if joint.ok:
            z_l = abs(est.leg_length_m - L) / est.leg_length_sd_m if est.leg_length_sd_m > 0 else math.inf
            est.note = joint_text
            if z_l > Z_DISAGREE:
                est.note += (
                    f"; the held L0 {1000 * L:.1f} mm is {z_l:.1f} sd from the periods': {at_held} (an effective "
                    "ratio: the one I_c is given from)"
                )
        else:
            est.note = (
                f"inertia ratio I_hub/(M L0^2) = {r:.3f} +- {est.ratio_se:.3f} from {n} pairs of consecutive step "
                f"periods at the held L0 {1000 * L:.1f} mm (reduced chi² {chi2:.2f}; {joint.why})"
            )
        return est
    if joint.ok and est.fits_with_fitted_l0:
        est.verdict = VERDICT_EFFECTIVE
        est.verdict_reason = (
            f"{held_l0} does not fit ({held_why}); with L0 fitted beside r it fits (reduced chi² {joint.chi2:.2f}) "
            f"at L0 = {1000 * est.leg_length_m:.1f} mm, r = {est.ratio:.3f}: an effective pendulum, not a "
            "measurement of the wheel's legs or inertia (a compliant wheel's stance is a shorter pendulum; or the "
            "held L0 is not the wheel's)"
        )
    elif not unusable:
        est.verdict = VERDICT_EFFECTIVE
        est.verdict_reason = f"{held_l0} does not fit ({held_why}; with L0 fitted: {joint_text}; a compliant wheel?)"
    else:
        est.verdict = VERDICT_NO_FIT
        est.verdict_reason = f"{held_l0} gives no value ({held_why}) and no fit with L0 fitted ({joint_text})"
        est.ratio = est.ratio_se = est.leg_length_m = est.leg_length_sd_m = math.nan
        est.note = f"the step periods give no usable inertia ratio: {est.verdict_reason}"
        return est
    est.note = (
        f"EFFECTIVE ONLY: {est.verdict_reason}; "
        + (
            f"at the held L0 the pendulum needs r = {r:.3f} +- {est.ratio_at_held_l0_se:.3f} (the ratio I_c is given from; "
            if est.ok
            else "no inertia at the held L0 ("
        )
        + f"{n} pairs of consecutive step periods)"
    )
    if not joint.ok:
        est.ratio, est.ratio_se = r, r * se_log
    return est


def _loss(log_r: float, pairs: _Pairs, alpha: float, L: float, g: float) -> float:
    """The constant loss per step (rad^2/s^2, in e) profiled out at the inertia ratio exp(log_r)."""
    gap, s = _gaps(log_r, pairs, alpha, L, g)
    return _weighted_loss(gap, s)


def _weighted_loss(gap: np.ndarray, s: np.ndarray) -> float:
    ok = np.isfinite(gap) & np.isfinite(s) & (s > 0)
    if not ok.any():
        return math.nan
    w = 1.0 / s[ok] ** 2
    return float(np.sum(w * gap[ok]) / np.sum(w))


def _leg_length_warning(win: Any, est: InertiaEstimate) -> list[str]:
    """A stated L0 further than `Z_DISAGREE` combined standard errors from the one the periods determine."""
    entry = win.entries["leg_length_m"]
    if entry.source == "table1" or not math.isfinite(est.leg_length_m):
        return []
    comb = math.hypot(entry.sd, est.leg_length_sd_m)
    z = abs(entry.value - est.leg_length_m) / comb if comb > 0 else math.inf
    est.comparison["leg_length"] = {"stated_m": entry.value, "stated_sd_m": entry.sd, "source": entry.source, "z": z}
    if z <= Z_DISAGREE:
        return []
    periods = (
        "effective pendulum length (not a measurement of the legs: the map does not fit at the stated L0)"
        if est.verdict == VERDICT_EFFECTIVE
        else "L0"
    )
    return [
        f"the wheel's L0 = {1000 * entry.value:.1f} +- {1000 * entry.sd:.1f} mm ({entry.source}) disagrees with the "
        f"{1000 * est.leg_length_m:.1f} +- {1000 * est.leg_length_sd_m:.1f} mm {periods} the step periods give "
        f"({z:.1f} combined standard errors): the stated value is used"
    ]


def trial_inertia_input(win: Any, trials: Sequence[Any]) -> tuple[Any, InertiaEstimate, list[str]]:
    """(the wheel input to use, the trials' estimate, warnings). ``win``'s inertia not stated (source
    ``table1``): replaced by the trials' (source ``trials``). Stated: kept, and compared with the trials'
    (a warning beyond `Z_DISAGREE` combined standard errors). An effective-only ratio: neither."""
    est = estimate_inertia_ratio(trials, win.params)
    entry = win.entries["inertia_kg_m2"]
    if not est.ok:
        if entry.source == "table1":
            est.note += "; Table 1's inertia is held"
        return win, est, []
    if not est.adequate:  # an effective ratio is no measurement of the inertia: neither used nor compared
        if entry.source == "table1":
            est.note += "; not used: Table 1's inertia is held"
        else:
            est.comparison = {
                "stated_kg_m2": entry.value,
                "stated_sd_kg_m2": entry.sd,
                "source": entry.source,
                "z": None,
            }
            est.note += "; not compared with the stated inertia"
        # a rigid map that fits with L0 fitted but not at the held one: a stated L0 is compared
        return win, est, _leg_length_warning(win, est) if est.fits_with_fitted_l0 else []
    if entry.source == "table1":
        new = win.with_entry(
            "inertia_kg_m2", est.inertia_kg_m2, est.inertia_sd_kg_m2, "trials", est.note + " (in place of Table 1's)"
        )
        return new, est, _leg_length_warning(win, est)
    warnings = _leg_length_warning(win, est)
    diff = entry.value - est.inertia_kg_m2
    comb = math.hypot(entry.sd, est.inertia_sd_kg_m2)
    z = abs(diff) / comb if comb > 0 else math.inf
    est.comparison.update({"stated_kg_m2": entry.value, "stated_sd_kg_m2": entry.sd, "source": entry.source, "z": z})
    if z > Z_DISAGREE:
        warnings.append(
            f"the wheel's inertia I_c = {entry.value:.4g} +- {entry.sd:.2g} kg m^2 ({entry.source}) disagrees with "
            f"the trials' {est.inertia_kg_m2:.4g} +- {est.inertia_sd_kg_m2:.2g} kg m^2 ({z:.1f} combined standard "
            f"errors; inertia ratio {inertia_ratio(win.params):.3f} stated, {est.ratio:.3f} +- {est.ratio_se:.3f} "
            "from the step periods): the stated value is used"
        )
    return win, est, warnings
