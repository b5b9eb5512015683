"""The step-to-step return map from the trials: its multiplier, corrected for the noise bias, beside the model's.

**The section.** Each observed impact k gives one section point: the wheel's angular speed x_k (rad/s) just
after the impact. The importer places impacts on the rotation (the wheel angle ``phase + k alpha``); a
quadratic in time is fitted to the wheel angle over the frames between `WINDOW_FRACTION` of a step past that
angle (post-impact frames only: the speed jumps at the impact), and x_k is its slope where it crosses the
impact angle (`SECTION_FRACTION` of a step past it: 0, the post-impact state itself; a section inside the
stance would mix the next step's disturbance into x_k). The variance v_k of each x_k comes from the
recording: the residuals of the trial's fits (pooled) through the fit's covariance (delta method, the
crossing's timing included).

**The map.** ``x_{k+1} - x* = a (x_k - x*) + w_k`` over consecutive observed impacts, pooled over the trials of
one slope (one intercept, one multiplier a per slope group). Measurement noise u_k on x_k biases the
ordinary least-squares slope toward 0 by the reliability ratio ``var(x) / (var(x) + var(u))`` (errors in
variables). Two corrections, both reported:

- ``corrected`` (the estimate): the method of moments with the noise variance measured from the recording,
  ``a = m_xy / (m_xx - mean v)`` (Fuller, Measurement Error Models, 1987, section 1.2), with Fuller's variance
  (Theorem 1.2.1) and a Student t interval on n - 2 degrees of freedom;
- ``lagged`` (the check): x_{k-1} as the instrument, ``a = cov(x_{k+1}, x_{k-1}) / cov(x_k, x_{k-1})``, the
  ratio of the lag-2 and lag-1 autocovariances, which measurement noise does not bias (the lagged-covariance
  idea of Ahn and Hogan, "Improved assessment of orbital stability of rhythmic motion with noise", PLoS ONE
  10(3): e0119596, 2015); its standard error is Newey-West with one lag (the equation's error is MA(1)).

**What is refused or flagged.** A trial without the wheel's rotation (no orientation), with fewer than
`MIN_TRIAL_POINTS` consecutive section points (too short), or whose section points follow one trend (rank
correlation with the step number of `TRANSIENT_RANK` or more) by more than the noise (transient-only: it never wandered about its gait; the map's slope along a long
transient is not the slope at the fixed point) gives no pairs, with the reason. A slope group with fewer
than `MIN_PAIRS` pairs, or whose walk does not wander beyond the measurement noise (reliability below
`MIN_RELIABILITY`: the slope is not identifiable), gets no estimate, with the reason.

**The model.** The dominant eigenvalue of the model's Poincaré map (dP/dz at its fixed point, z = (theta+,
theta'+)) at the group's slope, with the held parameters' uncertainty carried by
`rimless.analysis.inference.held.sensitivities` (finite differences at +-1 sd, in quadrature; a parameter at its
bound, F_c = 0, as its normal truncated there, `held.carry_rows`: ``eigenvalue_with_held``, ``held_shift``, the
interval centred there) and the slope's uncertainty added the same way. For the compliant wheel the other eigenvalue is small (about 0.1 for ER): the
one-dimensional map of the measured speed follows the dominant one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "SectionPoints",
    "MultiplierEstimate",
    "FloquetResult",
    "section_points",
    "estimate_multiplier",
    "model_multiplier",
    "run_floquet",
    "MIN_PAIRS",
    "MIN_TRIAL_POINTS",
]

SECTION_FRACTION = 0.0  # section angle past the impact, in steps (alpha)
WINDOW_FRACTION = (0.04, 0.40)  # frames fitted per impact: wheel angle past the impact, in steps
MIN_FIT_FRAMES = 5  # frames a section point's quadratic needs
MIN_TRIAL_POINTS = 3  # consecutive section points a trial needs (two pairs)
MIN_PAIRS = 8  # pairs a slope group needs for an estimate
MIN_RELIABILITY = 0.5  # var(true x) / var(measured x) below this: the walk does not wander beyond the noise
TRANSIENT_Z = 4.0  # a trial whose section points move one way by this many noise sds ...
TRANSIENT_RANK = 0.9  # ... with a rank correlation with the step number this strong is transient-only
Z95 = 1.959963984540054

METHOD = (
    "return map x_{k+1} = x* + a (x_k - x*) of the post-impact angular speed, pooled per slope; the regression's "
    "noise bias corrected with the noise variance measured from the recording (Fuller 1987, method of moments, "
    "t interval); check: x_{k-1} as the instrument (lag-2 over lag-1 autocovariance, after Ahn and Hogan, "
    "PLoS ONE 2015, e0119596)"
)
SECTION = (
    "wheel angular speed at each impact angle (the importer's phase + k alpha) from a quadratic in time fitted to "
    f"the wheel angle {WINDOW_FRACTION[0]:g}-{WINDOW_FRACTION[1]:g} step past it (post-impact frames)"
    + (f", read {SECTION_FRACTION:g} step past it" if SECTION_FRACTION else "")
)


def _num(v: Any) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


# ------------------------------------------------------------------------------------------ the section


@dataclass
class SectionPoints:
    """One trial's section points: impact number ``step``, angular speed ``speed_rad_s`` and its measurement
    variance ``var_rad2_s2`` (NaN where the point could not be read); ``status`` used | flagged with ``reason``."""

    file: str
    slope_deg: float
    slope_sd_deg: float
    step: np.ndarray
    speed_rad_s: np.ndarray
    var_rad2_s2: np.ndarray
    angle_noise_rad: float = math.nan
    status: str = "used"
    reason: str = ""

    def runs(self) -> list[np.ndarray]:
        """Indices of the runs of consecutive impacts with a finite section point (each in step order)."""
        ok = np.isfinite(self.speed_rad_s)
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            return []
        breaks = np.flatnonzero(np.diff(self.step[idx]) != 1) + 1
        return [r for r in np.split(idx, breaks) if r.size]

    def pairs(self) -> int:
        return sum(max(r.size - 1, 0) for r in self.runs())

    def row(self, group: int | None) -> dict[str, Any]:
        ok = np.isfinite(self.speed_rad_s)
        return {
            "file": self.file,
            "slope_deg": self.slope_deg,
            "group": group,
            "status": self.status,
            "reason": self.reason,
            "section_points": int(ok.sum()),
            "pairs": self.pairs() if self.status == "used" else 0,
            "angle_noise_rad": _num(self.angle_noise_rad),
            "speed_rad_s": [_num(v) for v in self.speed_rad_s],
            "speed_sd_rad_s": [_num(math.sqrt(v)) if math.isfinite(v) else None for v in self.var_rad2_s2],
        }


def _fit_point(t: np.ndarray, a: np.ndarray, t0: float, section: float) -> tuple[float, float, np.ndarray, float]:
    """(speed at the section angle, d speed / d coefficients, design inverse (X'X)^-1, RSS) of a quadratic
    a(t) = c0 + c1 s + c2 s^2, s = t - t0."""
    s = t - t0
    X = np.column_stack([np.ones_like(s), s, s * s])
    coef, *_ = np.linalg.lstsq(X, a, rcond=None)
    rss = float(np.sum((a - X @ coef) ** 2))
    c0, c1, c2 = coef
    # the crossing of the section angle: c0 + c1 s + c2 s^2 = section, the root nearest s = 0
    disc = c1 * c1 - 4 * c2 * (c0 - section)
    if abs(c2) < 1e-12 or disc < 0:
        s_x = (section - c0) / c1
    else:
        s_x = (-c1 + math.copysign(math.sqrt(disc), c1)) / (2 * c2)
    speed = c1 + 2 * c2 * s_x
    # d speed / d c: through s_x (d s_x / d c = -[1, s_x, s_x^2] / speed) and directly
    ds = -np.array([1.0, s_x, s_x * s_x]) / speed
    grad = np.array([0.0, 1.0, 2 * s_x]) + 2 * c2 * ds
    return float(speed), grad, np.linalg.inv(X.T @ X), rss


def section_points(trial: Any, name: str) -> SectionPoints:
    """The section points of one `rimless.analysis.io.trial.Trial` (see the module doc)."""
    from rimless.analysis.inference.sustained import trial_slope_sigma_deg

    meta = trial.meta
    sd, _ = trial_slope_sigma_deg(meta)
    empty = np.zeros(0)
    pts = SectionPoints(name, float(meta.slope_deg), sd, np.zeros(0, np.int64), empty, empty)
    if "wheel_angle" not in trial.series.data:
        pts.status, pts.reason = "flagged", "no wheel rotation (orientation unknown): the section needs the wheel angle"
        return pts
    alpha = float(meta.alpha_rad)
    t_all = np.asarray(trial.time_s, float)
    ang_all = np.asarray(trial.series["wheel_angle"], float)
    obs = np.isfinite(ang_all)
    if "interpolated" in trial.series.data:
        obs &= ~np.asarray(trial.series["interpolated"], bool)
    t, ang = t_all[obs], ang_all[obs]
    impacts = np.asarray(trial.impact_time_s, float)
    steps = np.asarray(trial.impact_step, np.int64)
    if impacts.size == 0 or t.size < MIN_FIT_FRAMES:
        why = getattr(meta, "step_refused", None)
        pts.status = "flagged"
        pts.reason = f"no impacts: the import found none ({why})" if why else "too short: no impact observed"
        return pts
    ends = np.append(impacts[1:], math.inf)
    speed = np.full(impacts.size, math.nan)
    grads: list[Any] = [None] * impacts.size
    inv: list[Any] = [None] * impacts.size
    rss_sum, dof = 0.0, 0
    direction = 1.0 if ang[-1] >= ang[0] else -1.0
    for i, (t0, t1) in enumerate(zip(impacts, ends)):
        a0 = float(np.interp(t0, t, ang))
        rel = direction * (ang - a0)
        sel = (t > t0) & (t < t1) & (rel >= WINDOW_FRACTION[0] * alpha) & (rel <= WINDOW_FRACTION[1] * alpha)
        if sel.sum() < MIN_FIT_FRAMES:
            continue
        tt = t[sel]
        if np.any(np.diff(tt) > 2.5 * np.median(np.diff(t))):  # a gap inside the window
            continue
        v, g, xi, rss = _fit_point(tt, direction * ang[sel], t0, direction * a0 + SECTION_FRACTION * alpha)
        if not (math.isfinite(v) and v > 0):
            continue
        speed[i], grads[i], inv[i] = v, g, xi
        rss_sum += rss
        dof += int(sel.sum()) - 3
    if dof < 3:
        pts.status, pts.reason = "flagged", "too short: fewer than 3 impacts with a section point"
        return pts
    sigma2 = rss_sum / dof
    var = np.array(
        [
            float(grads[i] @ inv[i] @ grads[i]) * sigma2 if grads[i] is not None else math.nan
            for i in range(impacts.size)
        ]
    )
    pts.step, pts.speed_rad_s, pts.var_rad2_s2, pts.angle_noise_rad = steps, speed, var, math.sqrt(sigma2)
    longest = max((r.size for r in pts.runs()), default=0)
    if longest < MIN_TRIAL_POINTS:
        pts.status = "flagged"
        pts.reason = f"too short: {longest} consecutive section point(s), need {MIN_TRIAL_POINTS}"
        return pts
    if _transient_only(pts):
        pts.status = "flagged"
        pts.reason = (
            f"transient-only: the post-impact speed follows one trend (rank correlation with the step number "
            f"{TRANSIENT_RANK:g} or more, a change over {TRANSIENT_Z:g} noise sds): the walk never wandered about its "
            "gait (the map's slope along a transient is not its slope at the gait)"
        )
    return pts


def _transient_only(pts: SectionPoints) -> bool:
    """The section points follow one trend: rank correlation with the impact number of at least
    `TRANSIENT_RANK` in size, and a change from first to last of more than `TRANSIENT_Z` noise sds."""
    ok = np.isfinite(pts.speed_rad_s)
    x, k = pts.speed_rad_s[ok], pts.step[ok].astype(float)
    if x.size < MIN_TRIAL_POINTS:
        return False
    rx, rk = np.argsort(np.argsort(x)), np.argsort(np.argsort(k))
    rho = float(np.corrcoef(rx, rk)[0, 1])
    noise = math.sqrt(float(np.nanmean(pts.var_rad2_s2)))
    return abs(rho) >= TRANSIENT_RANK and abs(float(x[-1] - x[0])) > TRANSIENT_Z * noise * math.sqrt(2)


# --------------------------------------------------------------------------------------- the estimate


@dataclass
class MultiplierEstimate:
    """The return map's slope from pairs (x_k, x_{k+1}) with the regressor's noise variance v_k."""

    n_pairs: int
    multiplier: float
    se: float
    ci95: tuple[float, float]
    ols: float
    ols_ci95: tuple[float, float]
    lagged: float | None
    lagged_se: float | None
    lagged_ci95: tuple[float, float] | None
    n_triples: int
    noise_sd: float
    wander_sd: float
    reliability: float
    fixed_point: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "pairs": self.n_pairs,
            "multiplier": self.multiplier,
            "se": self.se,
            "ci95": list(self.ci95),
            "ols_multiplier": self.ols,
            "ols_ci95": list(self.ols_ci95),
            "lagged_multiplier": self.lagged,
            "lagged_se": self.lagged_se,
            "lagged_ci95": None if self.lagged_ci95 is None else list(self.lagged_ci95),
            "lagged_triples": self.n_triples,
            "noise_sd_rad_s": self.noise_sd,
            "wander_sd_rad_s": self.wander_sd,
            "reliability": self.reliability,
            "fixed_point_rad_s": self.fixed_point,
        }


class NotIdentifiable(ValueError):
    """The pairs do not determine the multiplier (the message says why)."""


def _group_reason(members: list[SectionPoints], err: NotIdentifiable) -> str:
    """Why a slope group gives no multiplier: too few pairs, and the trials flagged by kind (the start of each
    one's reason: transient-only, too short, no impacts)."""
    flagged = [p for p in members if p.status != "used"]
    if not flagged:
        return str(err)
    kinds: dict[str, int] = {}
    for p in flagged:
        kind = p.reason.split(":", 1)[0]
        kinds[kind] = kinds.get(kind, 0) + 1
    what = ", ".join(f"{n} {k}" for k, n in kinds.items())
    if len(flagged) < len(members):
        return f"{err}; {len(flagged)} of {len(members)} trial(s) flagged ({what})"
    if set(kinds) == {"transient-only"}:
        return f"no trial reached steady walking (all {len(members)} transient-only: see each trial's reason)"
    return f"no trial gives pairs of section points ({what}: see each trial's reason)"


def estimate_multiplier(
    x: np.ndarray, y: np.ndarray, v: np.ndarray, triples: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
) -> MultiplierEstimate:
    """The corrected slope of y on x (x, y: section points k and k+1; v: x's measurement variance) with its
    95 % interval, the uncorrected OLS slope and, from ``triples`` (x_{k-1}, x_k, x_{k+1}), the lagged check.
    Raises `NotIdentifiable`."""
    from scipy.stats import t as student

    x, y, v = (np.asarray(a, float) for a in (x, y, v))
    n = x.size
    if n < MIN_PAIRS:
        raise NotIdentifiable(f"too short: {n} pairs of consecutive section points, need {MIN_PAIRS}")
    xc, yc = x - x.mean(), y - y.mean()
    mxx, mxy = float(xc @ xc) / (n - 1), float(xc @ yc) / (n - 1)
    suu = float(np.mean(v))
    big_mxx = mxx - suu
    reliability = big_mxx / mxx if mxx > 0 else 0.0
    if reliability < MIN_RELIABILITY:
        raise NotIdentifiable(
            f"the walk does not wander beyond the measurement noise (spread {math.sqrt(max(mxx, 0)):.3g} rad/s, "
            f"noise {math.sqrt(suu):.3g} rad/s: reliability {reliability:.2f} < {MIN_RELIABILITY}); the map's "
            "slope is not identifiable"
        )
    tq = float(student.ppf(0.975, n - 2))
    a = mxy / big_mxx
    svv = float(np.sum((yc - a * xc) ** 2)) / (n - 2)
    var = (svv / big_mxx + (suu * svv + a * a * suu * suu) / big_mxx**2) / (n - 1)
    se = math.sqrt(var)
    b_ols = mxy / mxx
    s_ols = math.sqrt(float(np.sum((yc - b_ols * xc) ** 2)) / (n - 2) / float(xc @ xc))
    fixed = float(y.mean() - a * x.mean()) / (1 - a) if a != 1 else math.nan
    lagged = lag_se = lag_ci = None
    nt = 0
    if triples is not None and triples[0].size >= MIN_PAIRS:
        z, x2, y2 = (np.asarray(a_, float) for a_ in triples)
        nt = z.size
        zc, x2c, y2c = z - z.mean(), x2 - x2.mean(), y2 - y2.mean()
        den = float(zc @ x2c)
        if den > 0:
            lagged = float(zc @ y2c) / den
            e = y2c - lagged * x2c
            g = zc * e
            s = float(g @ g) + float(g[1:] @ g[:-1])  # Newey-West, one lag (weight 1/2, both sides)
            lag_se = math.sqrt(max(s, 0.0)) / den * math.sqrt(nt / max(nt - 2, 1))
            tl = float(student.ppf(0.975, nt - 2))
            lag_ci = (lagged - tl * lag_se, lagged + tl * lag_se)
    return MultiplierEstimate(
        n_pairs=n,
        multiplier=a,
        se=se,
        ci95=(a - tq * se, a + tq * se),
        ols=b_ols,
        ols_ci95=(b_ols - tq * s_ols, b_ols + tq * s_ols),
        lagged=lagged,
        lagged_se=lag_se,
        lagged_ci95=lag_ci,
        n_triples=nt,
        noise_sd=math.sqrt(suu),
        wander_sd=math.sqrt(big_mxx),
        reliability=reliability,
        fixed_point=fixed,
    )


def group_data(
    members: Sequence[SectionPoints],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Pairs (x_k, x_{k+1}, v_k) and triples (x_{k-1}, x_k, x_{k+1}) over the used members' runs."""
    xs, ys, vs, t0, t1, t2 = [], [], [], [], [], []
    for p in members:
        if p.status != "used":
            continue
        for r in p.runs():
            s, var = p.speed_rad_s[r], p.var_rad2_s2[r]
            xs.append(s[:-1])
            ys.append(s[1:])
            vs.append(var[:-1])
            t0.append(s[:-2])
            t1.append(s[1:-1])
            t2.append(s[2:])

    def cat(a: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(a) if a else np.zeros(0)

    return cat(xs), cat(ys), cat(vs), (cat(t0), cat(t1), cat(t2))


# ------------------------------------------------------------------------------------------ the model


def model_multiplier(params: Any, model: str, *, rtol: float = 1e-9) -> dict[str, Any]:
    """The dominant eigenvalue of the model's map at ``params`` (its slope), the eigenvalues and the fixed
    point; ``{"eigenvalue": None, "note": why}`` when there is no gait."""
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.step.poincare import default_guess, solve_fixed_point

    pmap = make_map(params, model, rtol=rtol)
    jf = jacobian_factory("auto")
    try:
        fp = solve_fixed_point(pmap, default_guess(params, model), jacobian=jf(pmap) if jf else None, record=False)
    except StepFailure as err:
        return {"eigenvalue": None, "note": f"no period-1 gait of the {model} model at this slope: {err}"}
    ev = np.asarray(fp.eigenvalues, complex)
    dom = ev[int(np.argmax(np.abs(ev)))]
    return {
        "eigenvalue": float(dom.real) if abs(dom.imag) < 1e-12 else float(abs(dom)),
        "complex": bool(abs(dom.imag) >= 1e-12),
        "eigenvalues": [[float(e.real), float(e.imag)] for e in ev],
        "fixed_point": [float(fp.z[0]), float(fp.z[1])],
        "note": "",
    }


def _model_with_uncertainty(win: Any, model: str, slope_deg: float, slope_sd_deg: float) -> dict[str, Any]:
    """`model_multiplier` at the group's slope with the held parameters' and the slope's uncertainty."""
    from rimless.analysis.inference.held import carry_rows, combine, sensitivities
    from rimless.errors import ParameterError

    slope = math.radians(slope_deg)
    base = model_multiplier(win.params.replace(slope_rad=slope), model)
    if base["eigenvalue"] is None:
        return base

    def f(p: Any) -> float | None:
        return model_multiplier(p.replace(slope_rad=slope), model)["eigenvalue"]

    _, rows = sensitivities(f, win, base=base["eigenvalue"])
    # a held parameter at its bound (F_c = 0): truncated normal
    shift = carry_rows(rows, win, base["eigenvalue"], "eigenvalue")
    contributions = [
        {
            "name": r["name"],
            "symbol": r["symbol"],
            "sd": r["sd"],
            "unit": r["unit"],
            "minus": r.get("minus_deg"),
            "plus": r.get("plus_deg"),
            "contribution": r["contribution_deg"],
            "note": r.get("note", ""),
            "shift": r["shift_deg"],
            "carried_as": r.get("carried_as", ""),
        }
        for r in rows
    ]
    for e in win.entries.values():  # a fitted parameter (source fitted): its standard error, the same way
        if e.source != "fitted" or not e.sd > 0:
            continue
        ends = []
        for sign in (1.0, -1.0):
            try:
                ends.append(f(win.params.replace(**{e.name: e.value + sign * e.sd})))
            except ParameterError:
                ends.append(None)
        hi, lo = ends
        c = abs(hi - lo) / 2 if hi is not None and lo is not None else None
        contributions.append(
            {
                "name": e.name,
                "symbol": e.symbol,
                "sd": e.sd,
                "unit": e.unit,
                "minus": lo,
                "plus": hi,
                "contribution": c,
                "note": "fitted on these trials: its standard error",
            }
        )
    if slope_sd_deg > 0:
        vals = [
            model_multiplier(win.params.replace(slope_rad=math.radians(slope_deg + s * slope_sd_deg)), model)[
                "eigenvalue"
            ]
            for s in (1.0, -1.0)
        ]
        hi, lo = vals
        c = abs(hi - lo) / 2 if hi is not None and lo is not None else None
        contributions.append(
            {
                "name": "slope_rad",
                "symbol": "phi",
                "sd": slope_sd_deg,
                "unit": "deg",
                "minus": lo,
                "plus": hi,
                "contribution": c,
                "note": "the trials' slope uncertainty",
            }
        )
    se, complete = combine([{"contribution_deg": r["contribution"]} for r in contributions])
    e = base["eigenvalue"]
    return {
        **base,
        "se_parameters": se,
        "eigenvalue_with_held": e + shift,
        "held_shift": shift,
        "ci95": [e + shift - Z95 * se, e + shift + Z95 * se],
        "complete": complete,
        "contributions": contributions,
    }


# ------------------------------------------------------------------------------------------ the result


@dataclass
class FloquetResult:
    """`rimless trials floquet`: per slope group the trials' multiplier with its 95 % interval beside the model's
    eigenvalue; per trial its section points and status. `to_dict()` is the command's ``--json`` object."""

    model: str
    groups: list[dict[str, Any]]
    trials: list[dict[str, Any]]
    parameters: list[dict[str, Any]] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    #: with ``calibrate_c``: c calibrated on the trials (`trials calibrate`'s estimate), or why not; else None
    calibration: dict[str, Any] | None = None

    @property
    def estimated(self) -> list[dict[str, Any]]:
        return [g for g in self.groups if g["status"] == "estimated"]

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": METHOD,
            "section": SECTION,
            "model": self.model,
            "groups": self.groups,
            "trials": self.trials,
            "parameters": self.parameters,
            "calibration": self.calibration,
            "refused": self.refused,
        }

    summary = to_dict

    def to_frame(self) -> Any:
        """One row per slope group: slope, pairs, multiplier and interval, the model's eigenvalue."""
        import pandas as pd

        return pd.DataFrame([_flat(g) for g in self.groups])

    def __repr__(self) -> str:
        parts = []
        for g in self.groups:
            if g["status"] == "estimated":
                lo, hi = g["ci95"]
                m = g["model"].get("eigenvalue")
                parts.append(
                    f"{g['slope_deg']:.2f} deg: {g['multiplier']:.3f} [{lo:.3f}, {hi:.3f}] "
                    + ("(no model eigenvalue)" if m is None else f"(model {self.model.upper()} {m:.3f})")
                )
            else:
                parts.append(f"{g['slope_deg']:.2f} deg: none ({g['reason']})")
        flagged = sum(t["status"] != "used" for t in self.trials)
        return (
            f"FloquetResult({len(self.trials)} trial(s){f', {flagged} flagged' if flagged else ''}; "
            + "; ".join(parts)
            + "; .to_dict(), .to_frame())"
        )

    def _repr_html_(self) -> str:
        return self.to_frame().to_html(index=False, float_format=lambda v: f"{v:.4g}")


def _flat(g: dict[str, Any]) -> dict[str, Any]:
    ci = g.get("ci95") or [None, None]
    mci = g["model"].get("ci95") or [None, None] if g.get("model") else [None, None]
    return {
        "slope_deg": g["slope_deg"],
        "trials": len(g["trials"]),
        "pairs": g.get("pairs"),
        "multiplier": g.get("multiplier"),
        "ci95_low": ci[0],
        "ci95_high": ci[1],
        "ols_multiplier": g.get("ols_multiplier"),
        "lagged_multiplier": g.get("lagged_multiplier"),
        "model_eigenvalue": (g.get("model") or {}).get("eigenvalue"),
        "model_ci95_low": mci[0],
        "model_ci95_high": mci[1],
        "status": g["status"],
        "reason": g["reason"],
    }


def run_floquet(
    trials: Sequence[Any],
    names: Sequence[str],
    win: Any,
    *,
    model: str = "er",
    group_tol_deg: float = 0.05,
    with_model: bool = True,
    calibrate_c: bool = False,
    progress: Callable[[str], None] | None = None,
) -> FloquetResult:
    """The multiplier per slope group of ``trials`` beside the model's eigenvalue at ``win``'s parameters
    (`rimless.sim.model.uncertain.WheelInput`, their uncertainty carried); ``calibrate_c``: the model's c first
    calibrated on the trials (`trials calibrate --fit c`, the held parameters not refitted), its standard error
    carried like a held parameter's."""
    from rimless.analysis.inference.critical_slope import group_slopes

    calibration = None
    if calibrate_c and with_model:
        win, calibration = _calibrated(trials, names, win, model, progress)

    pts = [section_points(t, n) for t, n in zip(trials, names)]
    slopes = group_slopes(np.array([p.slope_deg for p in pts]), group_tol_deg)
    keys = sorted(set(slopes.tolist()))
    groups, trial_rows = [], []
    for gi, s in enumerate(keys):
        members = [p for p, g in zip(pts, slopes) if g == s]
        sd = math.sqrt(sum(p.slope_sd_deg**2 for p in members)) / len(members)
        g: dict[str, Any] = {
            "slope_deg": float(s),
            "slope_sd_deg": sd,
            "trials": [p.file for p in members],
            "used_trials": [p.file for p in members if p.status == "used"],
        }
        x, y, v, triples = group_data(members)
        try:
            est = estimate_multiplier(x, y, v, triples)
            g.update(status="estimated", reason="", **est.as_dict())
        except NotIdentifiable as err:
            g.update(status="not_estimated", reason=_group_reason(members, err), pairs=int(x.size))
        if with_model:
            if progress:
                progress(f"model at {s:.2f} deg")
            g["model"] = _model_with_uncertainty(win, model, float(s), sd)
        else:
            g["model"] = {"eigenvalue": None, "note": "not computed"}
        me, ci = g["model"].get("eigenvalue"), g.get("ci95")
        g["model_inside_ci95"] = None if me is None or ci is None else bool(ci[0] <= me <= ci[1])
        groups.append(g)
        trial_rows += [p.row(gi) for p in members]
    order = {n: i for i, n in enumerate(names)}
    trial_rows.sort(key=lambda r: order.get(r["file"], 0))
    return FloquetResult(
        model=model, groups=groups, trials=trial_rows, parameters=win.parameters(), calibration=calibration
    )


def _calibrated(
    trials: Sequence[Any], names: Sequence[str], win: Any, model: str, progress: Callable[[str], None] | None
) -> tuple[Any, dict[str, Any]]:
    """``win`` with c calibrated on the trials (source ``fitted``), and what the JSON says of it."""
    from rimless.analysis.inference.calibrate import NoTrialCalibrated, calibrate
    from rimless.analysis.inference.runs import calibrated_input

    if progress:
        progress("calibrating c")
    try:
        cal = calibrate(
            list(trials),
            list(names),
            ["c"],
            params=win.params,
            model=model,
            progress=(lambda n: progress(f"calibrating c ({n} simulations)")) if progress else None,
        )
    except NoTrialCalibrated as err:
        return win, {"fit": ["c"], "calibrated": False, "note": str(err)}
    (p,) = cal.params
    used = p.identifiable or p.effective_only
    out = {
        "fit": ["c"],
        "calibrated": used,
        "c_ns_per_m": p.value,
        "se_ns_per_m": p.se,
        "identifiable": p.identifiable,
        "effective_only": p.effective_only,
        "converged": cal.summary().get("converged", True),
        "note": p.note,
    }
    return (calibrated_input(win, cal) if used else win), out


def shown(name: str) -> str:
    return Path(name).name
