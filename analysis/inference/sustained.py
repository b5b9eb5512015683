"""Is a trial's walking sustained? A verdict from its measured step-to-step return map.

Reaching the end of a short ramp proves nothing (a wheel released fast below the critical slope walks the
whole ramp while slowing every step), so the verdict comes from the step periods:

1. Each measured step period T_k is turned into the squared angular speed the wheel has when its hub passes
   over the stance foot, ``e_k = theta'_top^2`` (rad^2/s^2), through the rigid stance pendulum of the wheel
   (`StancePendulum`): ``T(e) = integral over theta in [-alpha/2, alpha/2] of dtheta / sqrt(e + kappa (1 -
   cos(theta + phi)))``. e -> 0 is the stall (the period grows without bound); e is the natural variable of
   the step-to-step map, which for a rigid wheel is exactly affine in it (Coleman).
2. The return map ``e_{k+1} = a e_k + b`` is fitted by least squares over consecutive steps (a period that
   spans a gap breaks the chain), with a in [0, A_MAX] (a dissipative walker contracts). Over several
   trials (`trial_verdicts`) the slope a, the wheel's step-to-step factor, is pooled and shared.
3. Its fixed point ``e* = b / (1 - a)`` and the standard error from the fit decide:
   ``sustained`` when e* > 0 by more than `Z_SIGMA` standard errors (a gait with a finite period exists and
   the steps converge to it), ``decaying`` when e* < 0 by as much (every step loses speed until a stall) or
   the trial stalled on the ramp, ``undetermined`` otherwise or with fewer than `MIN_PERIODS` consecutive
   periods (the reason says which).

kappa = 2 M g L0 / (I_hub + M L0^2) and alpha come from the wheel parameters (the rigid wheel consistent with
the eight-leg mass model: M = m_H + 8 m, I_hub = I_c + 8 m L0^2); phi is the trial's slope. For a compliant
wheel the relation is an approximation whose error shifts e* a little; the sign test is what matters.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "StancePendulum",
    "Verdict",
    "trial_verdict",
    "verdict_from_periods",
    "consecutive_periods",
    "MIN_PERIODS",
    "Z_SIGMA",
    "A_MAX",
    "trial_slope_sigma_deg",
    "DEFAULT_SLOPE_SIGMA_DEG",
]

MIN_PERIODS = 4  # consecutive periods needed to fit the return map (3 pairs for 2 parameters)
Z_SIGMA = 2.0  # e* must differ from 0 by this many standard errors for a verdict
A_MAX = 0.98  # largest return-map slope allowed (a dissipative walker contracts)
TIMING_SIGMA_FLOOR_S = 2e-4  # smallest per-period timing noise assumed, s
POOL_MIN_PAIRS = 20  # return-map pairs beyond the fits' parameters before the pooled scatter may lower the noise
Z95 = 1.959963984540054
#: 1-sigma slope uncertainty (deg) assumed when a trial states no interval, by its ``slope_source``
DEFAULT_SLOPE_SIGMA_DEG = {"ramp": 0.02, "given": 0.05, "estimated": 0.1}
DEFAULT_SLOPE_SIGMA_UNKNOWN_DEG = 0.1


def trial_slope_sigma_deg(meta: Any) -> tuple[float, str]:
    """(1-sigma uncertainty of a trial's slope in deg, where it comes from).

    From ``meta.slope_ci_rad`` (a 95 % interval (low, high), rad) when present and finite; else the default
    of its ``meta.slope_source`` (`DEFAULT_SLOPE_SIGMA_DEG`), else `DEFAULT_SLOPE_SIGMA_UNKNOWN_DEG`."""
    ci: Any = getattr(meta, "slope_ci_rad", None)  # anything: what is not two numbers raises below
    try:
        lo, hi = (float(v) for v in ci)
        if math.isfinite(lo) and math.isfinite(hi) and hi >= lo:
            return max(math.degrees(hi - lo) / (2 * Z95), 1e-4), "slope_ci_rad"
    except (TypeError, ValueError):
        pass
    src = getattr(meta, "slope_source", None)
    if isinstance(src, str) and src in DEFAULT_SLOPE_SIGMA_DEG:
        return DEFAULT_SLOPE_SIGMA_DEG[src], f"default for slope_source {src}"
    return DEFAULT_SLOPE_SIGMA_UNKNOWN_DEG, "default (no slope uncertainty given)"


@dataclass(frozen=True)
class StancePendulum:
    """The rigid stance phase: step period <-> squared speed over the top, at one slope.

    alpha_rad: angle between legs; kappa_s2: 2 M g L / I_foot (1/s^2); slope_rad: phi.
    """

    alpha_rad: float
    kappa_s2: float
    slope_rad: float

    @classmethod
    def from_params(cls, params: Any, slope_rad: float) -> StancePendulum:
        """From `rimless.sim.model.params.WheelParams` (eight-leg-consistent rigid wheel)."""
        m8 = 8.0 * params.leg_mass_kg
        mass = params.hub_mass_kg + m8
        L = params.leg_length_m
        inertia_hub = params.inertia_kg_m2 + m8 * L**2
        kappa = 2.0 * mass * params.gravity_m_s2 * L / (inertia_hub + mass * L**2)
        return cls(float(params.alpha), float(kappa), float(slope_rad))

    def period_s(self, e: float) -> float:
        """Step period (s) of a rigid stance with squared top speed e > 0 (rad^2/s^2).

        With x = theta + phi and u = x/2 the integral is (2/sqrt(e)) [F(u | -2 kappa/e)] between the bounds
        (incomplete elliptic integral of the first kind, odd in u)."""
        from scipy.special import ellipkinc

        if not e > 0:
            return math.inf
        a, k, phi = self.alpha_rad, self.kappa_s2, self.slope_rad
        m = -2.0 * k / e
        u_lo, u_hi = 0.5 * (phi - a / 2), 0.5 * (phi + a / 2)
        return float(2.0 / math.sqrt(e) * (ellipkinc(u_hi, m) - ellipkinc(u_lo, m)))

    def min_period_s(self, e_max: float = 1e4) -> float:
        return self.period_s(e_max)

    def energy(self, period_s: float) -> float:
        """Inverse of `period_s`: squared top speed (rad^2/s^2) for a measured period; NaN if out of range."""
        from scipy.optimize import brentq

        if not (math.isfinite(period_s) and period_s > 0):
            return math.nan
        lo, hi = -25.0, math.log(1e4)  # log e
        if period_s >= self.period_s(math.exp(lo)) or period_s <= self.period_s(math.exp(hi)):
            return math.nan
        x = brentq(lambda le: self.period_s(math.exp(le)) - period_s, lo, hi, xtol=1e-12, rtol=1e-12)
        return math.exp(x)

    def energy_slope(self, e: float) -> float:
        """de/dT at e (rad^2/s^3), by a central difference in log e."""
        h = 1e-4
        t1, t2 = self.period_s(e * math.exp(h)), self.period_s(e * math.exp(-h))
        return (e * (math.exp(h) - math.exp(-h))) / (t1 - t2)


@dataclass
class Verdict:
    """One trial's verdict and the fitted return map (e in rad^2/s^2)."""

    verdict: str  # sustained | decaying | undetermined
    reason: str
    steps: int  # measured periods used
    slope_deg: float
    a: float = math.nan  # return-map slope (the step-to-step eigenvalue)
    b: float = math.nan
    fixed_point: float = math.nan  # e*, rad^2/s^2
    fixed_point_se: float = math.nan
    fixed_point_period_s: float = math.nan  # period of the fitted gait (inf/NaN when e* <= 0)
    energies: np.ndarray = field(default_factory=lambda: np.zeros(0))
    periods_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stalled: bool = False
    a_free: float = math.nan  # the slope this trial alone gives, and its standard error
    a_free_se: float = math.nan
    slope_sigma_deg: float = math.nan  # 1-sigma uncertainty of the trial's slope, deg (`trial_slope_sigma_deg`)
    slope_sigma_source: str = ""  # where slope_sigma_deg comes from
    #: the free fit's residual r'r, its expectation under the assumed timing noise and its degrees of freedom
    #: (`_fit_affine`), for the timing scale pooled over a wheel's trials (`pooled_timing_scale`); zeros without
    timing_scatter: tuple[float, float, int] = (0.0, 0.0, 0)

    def as_dict(self) -> dict[str, Any]:
        return {
            "verdict": self.verdict,
            "reason": self.reason,
            "steps": self.steps,
            "slope_deg": self.slope_deg,
            "return_map_slope": self.a,
            "return_map_slope_alone": self.a_free,
            "fixed_point_e_rad2_s2": self.fixed_point,
            "fixed_point_e_se_rad2_s2": self.fixed_point_se,
            "fixed_point_period_s": self.fixed_point_period_s,
            "stalled": self.stalled,
            "slope_sigma_deg": self.slope_sigma_deg,
            "slope_ci_deg": (
                [self.slope_deg - Z95 * self.slope_sigma_deg, self.slope_deg + Z95 * self.slope_sigma_deg]
                if math.isfinite(self.slope_sigma_deg)
                else None
            ),
            "slope_sigma_source": self.slope_sigma_source,
        }


def consecutive_periods(trial: Any) -> list[np.ndarray]:
    """Chains of consecutive step periods (s) of a trial: a period whose impacts are not both observed breaks it.

    Uses ``trial.impact_time_s`` and ``trial.step_period_s``: a period is matched to the impact it starts at;
    periods that do not start where the previous one ended begin a new chain.
    """
    periods = np.asarray(getattr(trial, "step_period_s", np.zeros(0)), float)
    impacts = np.asarray(getattr(trial, "impact_time_s", np.zeros(0)), float)
    periods = periods[np.isfinite(periods)]
    if periods.size == 0:
        return []
    if impacts.size == periods.size + 1 and np.allclose(np.diff(impacts), periods, atol=1e-6):
        return [periods]
    if impacts.size < 2:
        return [periods]
    # periods may skip gaps: match each period to an impact pair (start, start + period)
    chains: list[list[float]] = []
    last_end = math.nan
    used = 0
    for i in range(impacts.size - 1):
        d = impacts[i + 1] - impacts[i]
        if used < periods.size and abs(d - periods[used]) < 1e-6:
            if chains and abs(impacts[i] - last_end) < 1e-9:
                chains[-1].append(d)
            else:
                chains.append([d])
            last_end = impacts[i + 1]
            used += 1
    if used != periods.size:  # could not match: trust the periods as one chain
        return [periods]
    return [np.array(c) for c in chains]


def _trial_stalled(trial: Any) -> bool:
    """The trial ended in a stall: the importer says so (``meta.outcome``), or the hub stopped advancing
    for longer than 1.5 last periods after the last impact while the recording went on."""
    meta = getattr(trial, "meta", None)
    outcome = getattr(meta, "outcome", None)
    if isinstance(outcome, str):
        return outcome == "stalled"
    try:
        t = np.asarray(trial.time_s, float)
        imp = np.asarray(trial.impact_time_s, float)
        per = np.asarray(trial.step_period_s, float)
        x = np.asarray(trial.series["hub_slope"], float)[:, 0]
    except Exception:  # noqa: BLE001 - a trial object without these fields: no stall evidence
        return False
    if x is None or imp.size < 2 or per.size == 0:
        return False
    after = (t > imp[-1]) & np.isfinite(x)
    if not after.any() or t[after][-1] - imp[-1] < 1.5 * per[-1]:
        return False
    ok = np.isfinite(x)
    x_at = np.interp(imp, t[ok], x[ok])
    step_len = abs(float(np.median(np.diff(x_at))))
    x_imp = float(x_at[-1])
    travel = float(np.nanmax(x[after]) - x_imp)
    return travel < 0.8 * step_len


def verdict_from_periods(
    chains: list[np.ndarray],
    pendulum: StancePendulum,
    *,
    slope_deg: float,
    stalled: bool = False,
    timing_sigma_s: float | None = None,
    shared_slope: tuple[float, float] | None = None,
) -> Verdict:
    """Fit the return map over the chains of consecutive periods and decide (see the module doc).

    ``shared_slope`` = (a, standard error): use this return-map slope (the wheel's step-to-step factor,
    pooled over trials) instead of fitting it, and propagate its uncertainty."""
    n = int(sum(c.size for c in chains))
    longest = max((c.size for c in chains), default=0)
    es = [np.array([pendulum.energy(float(T)) for T in c]) for c in chains]
    all_e = np.concatenate(es) if es else np.zeros(0)
    all_T = np.concatenate(chains) if chains else np.zeros(0)
    v = Verdict("undetermined", "", n, slope_deg, energies=all_e, periods_s=all_T, stalled=stalled)
    if n and not np.all(np.isfinite(all_e)):
        bad = all_T[~np.isfinite(all_e)]
        v.reason = (
            f"step period(s) {', '.join(f'{x:.3f}' for x in bad)} s outside what a wheel of these parameters "
            f"can walk at {slope_deg:.2f} deg (shorter than the fastest)"
        )
        if stalled:
            v.verdict, v.reason = "decaying", f"stalled on the ramp after {n} step(s)"
        return v
    if longest < MIN_PERIODS:
        if stalled:
            v.verdict, v.reason = "decaying", f"stalled on the ramp after {n} step(s)"
        else:
            v.reason = (
                f"too few consecutive steps to fit the return map ({longest} periods in a row, need {MIN_PERIODS})"
            )
        return v
    x_arr = np.concatenate([e[:-1] for e in es])
    y_arr = np.concatenate([e[1:] for e in es])
    # each impact time carries its own noise; a period is the difference of two (sig_t is a period's noise)
    sig_t = timing_sigma_s if timing_sigma_s is not None else TIMING_SIGMA_FLOOR_S
    jx, jy = _impact_jacobians(es, pendulum, sig_t / math.sqrt(2.0))
    a, b, cov, v.timing_scatter = _fit_affine(x_arr, y_arr, jx, jy)
    v.a_free, v.a_free_se = a, (math.sqrt(cov[0, 0]) if cov[0, 0] > 0 else math.inf)
    if shared_slope is not None:
        a, a_se = shared_slope
        b = float(np.mean(y_arr - a * x_arr))
        var_b = _mean_noise_var(y_arr - a * x_arr, jy - a * jx)
        mx = float(np.mean(x_arr))
        cov = np.array([[a_se**2, -mx * a_se**2], [-mx * a_se**2, var_b + mx**2 * a_se**2]])
    v.a, v.b = a, b
    e_star = b / (1.0 - a)
    g = np.array([b / (1.0 - a) ** 2, 1.0 / (1.0 - a)])  # d e*/d(a, b)
    se = float(math.sqrt(max(g @ cov @ g, 0.0)))
    v.fixed_point, v.fixed_point_se = float(e_star), se
    if e_star > 0:
        v.fixed_point_period_s = pendulum.period_s(e_star)
    last = float(all_e[-1])
    trend = "slowing" if y_arr[-1] < x_arr[-1] else "speeding up"
    if stalled:
        v.verdict = "decaying"
        v.reason = f"stalled on the ramp after {n} steps (fitted fixed point e* = {e_star:.3f} ± {se:.3f} rad²/s²)"
    elif e_star - Z_SIGMA * se > 0:
        v.verdict = "sustained"
        v.reason = (
            f"converges to a gait of period {v.fixed_point_period_s:.3f} s (e* = {e_star:.3f} ± {se:.3f} "
            f"rad²/s², step-to-step factor {a:.2f})"
        )
    elif e_star + Z_SIGMA * se < 0:
        steps_left = _steps_to_stall(a, b, last)
        v.verdict = "decaying"
        v.reason = (
            f"{trend} every step towards a stall: no gait (e* = {e_star:.3f} ± {se:.3f} rad²/s² < 0); "
            f"about {steps_left} more step(s) to the stall"
        )
    else:
        v.reason = (
            f"the fitted fixed point e* = {e_star:.3f} ± {se:.3f} rad²/s² cannot be told from the stall "
            f"(0) at {Z_SIGMA:g} sigma"
        )
    return v


def _steps_to_stall(a: float, b: float, e: float) -> str:
    for k in range(1, 1000):
        e = a * e + b
        if e <= 0:
            return str(k)
    return ">1000"


def _impact_jacobians(
    es: list[np.ndarray], pendulum: StancePendulum, sig_impact_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """d(x, y)/d(impact times) of the return-map pairs (x = e_k, y = e_k+1 over each chain), times the noise of
    one impact time (s): rows are pairs, columns impacts (a chain of m periods has m + 1 impacts of its own).
    Consecutive periods share an impact, so their energies' errors are correlated (e_k = E(t_k+1 - t_k))."""
    n_pairs = sum(max(e.size - 1, 0) for e in es)
    n_imp = sum(e.size + 1 for e in es)
    jx, jy = np.zeros((n_pairs, n_imp)), np.zeros((n_pairs, n_imp))
    row, col = 0, 0
    for e in es:
        g = np.array([pendulum.energy_slope(max(float(v), 1e-9)) for v in e]) * sig_impact_s  # de/dT per impact
        for k in range(e.size - 1):
            jx[row, col + k], jx[row, col + k + 1] = -g[k], g[k]
            jy[row, col + k + 1], jy[row, col + k + 2] = -g[k + 1], g[k + 1]
            row += 1
        col += e.size + 1
    return jx, jy


def _scatter_scale(resid: np.ndarray, resid_noise: np.ndarray) -> float:
    """How much larger the residuals are than the timing noise predicts (>= 1: never deflated): r'r over its
    expectation under the noise (``resid_noise``: the residuals' linear map of the unit impact noises)."""
    expected = float(np.sum(resid_noise**2))
    return max(float(resid @ resid) / expected, 1.0) if expected > 0 else 1.0


def _mean_noise_var(r: np.ndarray, noise: np.ndarray) -> float:
    """Variance of mean(r) (r = y - a x at a given a; ``noise`` = d r / d(impact noises)): the timing noise
    propagated with its correlations (the mean over a chain nearly telescopes), scaled up by the residual
    scatter when that is larger."""
    mean_row = noise.mean(axis=0)
    return float(mean_row @ mean_row) * _scatter_scale(r - r.mean(), noise - mean_row)


def _fit_affine(
    x: np.ndarray, y: np.ndarray, jx: np.ndarray, jy: np.ndarray
) -> tuple[float, float, np.ndarray, tuple[float, float, int]]:
    """Least squares y = a x + b with 0 <= a <= A_MAX; covariance of (a, b) from the timing noise of the impact
    times propagated through both coordinates with its correlations (``jx``, ``jy``: `_impact_jacobians`),
    scaled up by the residual scatter when that is larger; and (r'r, its expectation under the noise, degrees of
    freedom) of a free fit (zeros when the slope is constrained)."""
    A = np.column_stack([x, np.ones_like(x)])
    sol, *_ = np.linalg.lstsq(A, y, rcond=None)
    a, b = float(sol[0]), float(sol[1])
    free = 0.0 <= a <= A_MAX
    if not free:  # constrain the slope, refit the intercept
        a = min(max(a, 0.0), A_MAX)
        b = float(np.mean(y - a * x))
        var_b = _mean_noise_var(y - a * x, jy - a * jx)
        return a, b, np.array([[0.0, 0.0], [0.0, var_b]]), (0.0, 0.0, 0)
    noise = jy - a * jx  # d(y - a x)/d(impact noises) at the fitted a
    try:
        P = np.linalg.solve(A.T @ A, A.T)
    except np.linalg.LinAlgError:
        return a, b, np.full((2, 2), np.inf), (0.0, 0.0, 0)
    pn = P @ noise
    resid, resid_noise = y - (a * x + b), noise - A @ pn
    scatter = (float(resid @ resid), float(np.sum(resid_noise**2)), max(int(resid.size) - 2, 0))
    return a, b, (pn @ pn.T) * _scatter_scale(resid, resid_noise), scatter


def pooled_timing_scale(verdicts: Sequence[Verdict]) -> float:
    """The factor (<= 1) on the assumed timing noise that the residual scatter of all the trials' free return-map
    fits together supports: sqrt(sum r'r / sum expectation), pooled over the trials of one wheel (one lab, one
    rate), when they have at least `POOL_MIN_PAIRS` pairs beyond their fits' parameters; 1 otherwise. Never
    above 1 (each trial's own scatter still inflates its fit) and never below `TIMING_SIGMA_FLOOR_S`'s share."""
    rr = sum(v.timing_scatter[0] for v in verdicts)
    expected = sum(v.timing_scatter[1] for v in verdicts)
    dof = sum(v.timing_scatter[2] for v in verdicts)
    if expected <= 0 or dof < POOL_MIN_PAIRS:
        return 1.0
    return min(math.sqrt(rr / expected), 1.0)


def trial_verdicts(trials: list[Any], params: Any = None) -> list[Verdict]:
    """Verdicts of several trials of one wheel: each trial's return map is fitted alone, the slopes a of the
    trials that determine it are pooled (inverse-variance mean, scatter-inflated: a is the wheel's
    step-to-step factor, the same on every slope), and every trial is then decided with the pooled a. A
    trial released far from its gait extrapolates a long way to e*: the pooled a makes that extrapolation
    sharp. With fewer than two trials determining a, the single fits stand. The assumed timing noise (a tenth of
    a frame per impact) is lowered to what the residual scatter of all the trials' fits together supports
    (`pooled_timing_scale`: one lab's impacts, pooled over tens of pairs), never raised: each fit's own larger
    scatter still inflates it."""
    first = [trial_verdict(t, params) for t in trials]
    ok = [
        (v.a_free, v.a_free_se)
        for v in first
        if math.isfinite(v.a_free) and 0.0 < v.a_free < A_MAX and 0 < v.a_free_se < 0.5 and not v.stalled
    ]
    scale = pooled_timing_scale(first)
    if len(ok) < 2:
        return first if scale == 1.0 else [trial_verdict(t, params, timing_scale=scale) for t in trials]
    # each trial's a_free se at the pooled timing noise: its covariance goes as the noise squared, times its own
    # scatter factor max(r'r / expected, 1) at that noise
    ratio = {id(v): (v.timing_scatter[0] / v.timing_scatter[1] if v.timing_scatter[1] > 0 else 0.0) for v in first}
    ok = [
        (v.a_free, v.a_free_se * math.sqrt(scale**2 * max(ratio[id(v)] / scale**2, 1.0) / max(ratio[id(v)], 1.0)))
        for v in first
        if math.isfinite(v.a_free) and 0.0 < v.a_free < A_MAX and 0 < v.a_free_se < 0.5 and not v.stalled
    ]
    a = np.array([x for x, _ in ok])
    w = 1.0 / np.array([s for _, s in ok]) ** 2
    mean = float(np.sum(w * a) / np.sum(w))
    chi2 = float(np.sum(w * (a - mean) ** 2)) / (a.size - 1)
    se = math.sqrt(max(chi2, 1.0) / float(np.sum(w)))
    out = [trial_verdict(t, params, shared_slope=(mean, se), timing_scale=scale) for t in trials]
    for i, (v, f) in enumerate(zip(out, first)):
        if v.verdict == "undetermined" and f.verdict != "undetermined":
            out[i] = f  # never lose a verdict the trial gives on its own
    return out


def trial_verdict(
    trial: Any, params: Any = None, *, shared_slope: tuple[float, float] | None = None, timing_scale: float = 1.0
) -> Verdict:
    """The verdict of one imported trial (`rimless.analysis.io.trial.Trial` or anything with its public fields:
    ``step_period_s``, ``impact_time_s``, ``meta.slope_deg``, ``meta.rate_hz``, ``time_s``); ``timing_scale``
    (<= 1): the factor on the assumed timing noise that the wheel's trials together support
    (`pooled_timing_scale`)."""
    from rimless.sim.model.params import WheelParams

    params = params or WheelParams()
    meta = trial.meta
    slope_deg = float(meta.slope_deg)
    chains = consecutive_periods(trial)
    rate = float(getattr(meta, "rate_hz", 0.0) or 0.0)
    # impact times come from sub-frame fits: about a tenth of a frame each (at most; `timing_scale` lowers it to
    # what the trials of one wheel show together), two per period
    sig_t = max(TIMING_SIGMA_FLOOR_S, timing_scale * 0.1 * math.sqrt(2.0) / rate) if rate > 0 else None
    if not (math.isfinite(slope_deg) and 0.0 < slope_deg < math.degrees(params.alpha / 2)):
        n = int(sum(c.size for c in chains))
        v = Verdict(
            "undetermined",
            f"slope {slope_deg:.3f} deg outside (0, {math.degrees(params.alpha / 2):.1f}) "
            "deg: a wrong slope estimate? (give --slope-deg)",
            n,
            slope_deg,
        )
        v.slope_sigma_deg, v.slope_sigma_source = trial_slope_sigma_deg(meta)
        return v
    pend = StancePendulum.from_params(params, math.radians(slope_deg))
    v = verdict_from_periods(
        chains,
        pend,
        slope_deg=slope_deg,
        stalled=_trial_stalled(trial),
        timing_sigma_s=sig_t,
        shared_slope=shared_slope,
    )
    v.slope_sigma_deg, v.slope_sigma_source = trial_slope_sigma_deg(meta)
    return v
