"""The trial's slope from every source there is, each with an honest 95 % interval, and the one used.

Sources, best first: a static ramp in the file (``ramp``), the user's value (``given``), then the estimates from
the motion (``estimated``), each a line of height against the horizontal distance along the travel:

* ``contacts``: the line through the stance-foot contact points (`contacts.slope_from_contacts`; no-slip: a
  stance foot does not move). With three or more, its standard error is the weighted line's, its stated
  height errors scaled by their scatter about the line (the reduced chi-square: each contact's stated error is
  the spread of its stance's pivots, not the error of their median, 2-20 times too large in variance on the
  coverage study's truths), with Student t (n - 2 degrees of freedom: the scale is estimated), the scaled errors
  never below `contacts.CONTACT_FLOOR_M`; the stated errors (normal) when they give the narrower interval
  (they bound the scale: with three or four contacts the t quantile is 4-13); plus the legs' drift of the
  contact heights (`LegCompliance`). Two contacts cannot show their scatter: their errors are floored at
  `TWO_CONTACT_SD_M` each (a foot is no point and a leg compresses: the pivot moves that much).
* ``impact line``: the line through the hub at the CoM-height minima (impacts), which lie on a line parallel to
  the slope when every impact looks alike; its standard error from the scatter about the line (Student t), plus
  the legs' drift of the minima depth (`LegCompliance`: a compliant leg compresses more when the wheel speeds
  up, a trend that looks like slope), plus the hub's standard error when the stance feet placed it (the error
  turns with the wheel and a line through a few impacts reads part of it as slope; propagated exactly).
* ``path``: the robust line through the whole hub path, used only when neither of the others exists; the hub
  rises and falls once a step, so its scatter counts as one sample a step (Student t).

The legs' drift: a spring leg's compression at impact changes by about dv_n sqrt(m / k) when the impact normal
speed v_n changes by dv_n, and the minima depth and the contacts the importer finds move with it. The trial shows
dv_n (its hub speed from impact to impact, `speed_change_m_s`); the wheel (``wheel=``) says whether its legs are
compliant and how stiff (`leg_compliance`: a rigid model has no drift; the stated k and masses: the allowance is
a standard deviation, so it takes their values, not the ends of their 95 % intervals).
The allowance (1 sigma) over the trial is `MINIMA_DRIFT_PER_IMPULSE` (impact line) or
`CONTACT_DRIFT_PER_IMPULSE` (contacts) times dv_n sqrt(m / k); without the wheel, sqrt(m / k) is bounded by
`UNKNOWN_LEG_TIME_S`; when the trial shows no speed change (fewer than three impacts), the constants
`MINIMA_DRIFT_M` and `CONTACT_DRIFT_M` are allowed. (The stance feet's distance from the hub, from the contact
fit, would measure the compression itself, but it scatters 0.3-0.6 mm from stance to stance at 0.3 mm of marker
noise, as much as the drift it would measure: not used.)

The estimate used is the best conditioned (narrowest interval), combined with the others that agree with it by
the least-variance weights under their covariance (they come from different data, stance pivots and impact
cusps, so their own errors are independent; the drift, ``common_half_rad``, is counted as shared: it is not
averaged down, and the weights favour the estimate it moves least; `_covariance`). When two estimates disagree by
more than their combined uncertainty, one of them is wrong and the data cannot say which: the interval of the
best conditioned is widened to span the other's, and a warning says so. Angles in rad, lengths in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import t as student_t

from rimless.analysis.kinematics.contacts import CONTACT_FLOOR_M

__all__ = [
    "SlopeEvidence",
    "LegCompliance",
    "leg_compliance",
    "speed_change_m_s",
    "slope_evidence",
    "choose_slope",
    "GIVEN_SLOPE_HALF_WIDTH_DEG",
    "RAMP_SLOPE_HALF_WIDTH_DEG",
    "MIN_ESTIMATE_HALF_WIDTH_DEG",
    "OFFSET_BOUND_M",
    "TWO_CONTACT_SD_M",
    "MINIMA_DRIFT_M",
    "CONTACT_DRIFT_M",
    "CONTACT_CHI2_FLOOR",
    "MINIMA_DRIFT_PER_IMPULSE",
    "CONTACT_DRIFT_PER_IMPULSE",
    "UNKNOWN_LEG_TIME_S",
    "Z95",
]

#: Half width of the 95 % interval of a slope given by the user (an inclinometer reading), deg.
GIVEN_SLOPE_HALF_WIDTH_DEG = 0.1
#: Half width of the 95 % interval of a static ramp's tilt (how well its axis or markers define the plane), deg.
RAMP_SLOPE_HALF_WIDTH_DEG = 0.05
#: Least half width of an estimated slope's 95 % interval, deg.
MIN_ESTIMATE_HALF_WIDTH_DEG = 0.01
Z95 = 1.959964
#: How far an object origin may lie from the hub, m (bounds the slope error when the hub is not determined).
OFFSET_BOUND_M = 0.05
#: Least height error (1 sigma) of each of only two contact points, m: the pivot of a rounded, compressing foot
#: moves this much within a stance (the contacts of the independent ER truth scatter 0.2-0.6 mm about their line).
TWO_CONTACT_SD_M = 0.5e-3
#: Drift (1 sigma) of the CoM-minima depth from the first impact to the last, m, allowed when the trial shows no
#: speed change (fewer than three impacts): the constant allowance sized before the drift followed the speed
#: change (with `CONTACT_DRIFT_M`: the tests' compliant truth's slope interval held the truth in 77 of 80 walks,
#: measured on that truth before 88dc178, its uncompressed hold).
MINIMA_DRIFT_M = 0.4e-3
#: Least factor on the contact heights' stated errors (squared) when they are scaled by their scatter about the
#: line: none since session 17 (it was 0.25, "successive pivots share the rotation's errors, which the scatter
#: does not show"; measured against the truth, the floor held in 77-89 % of the walks and the contact line's
#: rms z was 0.69-0.79; scaled by the scatter alone, with Student t, 0.81-0.90: nothing shared showed). The
#: scaled errors stay at or above `contacts.CONTACT_FLOOR_M` each.
CONTACT_CHI2_FLOOR = 0.0
#: Drift (1 sigma) of the contact heights from the first stance to the last, m, allowed when the trial shows no
#: speed change (see `MINIMA_DRIFT_M`).
CONTACT_DRIFT_M = 0.35e-3
#: The minima depth's drift (1 sigma) over the trial per dv_n sqrt(m / k) (see the module doc), with the wheel's
#: stated k and masses: the simulator's ER wheel (k 1600-3800 N/m, c 4-19 N s/m, released at 0.8-1.4 times its
#: gait's speed) drifts 0.09-0.13 times that (rms about 0.11); regressed on the signed speed change over the
#: slope-coverage study's 38 ER walks (seed 0), the impact line's error is 0.108 times it (correlation 0.47);
#: on the tests' compliant truth (released at 2-3 rad/s, k 1500-4000 N/m, told its k +- 10 %) the factor that
#: gave rms z 1.00 was 0.10 on k's 95 % low end and the masses' high end, 0.11 on the stated values (measured
#: on that truth before 88dc178, its uncompressed hold). (It was 0.12 on the low end until session 17: 0.135 here.)
MINIMA_DRIFT_PER_IMPULSE = 0.11
#: The contact heights' drift (1 sigma) over the trial per dv_n sqrt(m / k): the pivot the importer finds moves
#: with the compression within the stance. The two compliant truths differ: regressed on the signed speed
#: change, the contact line's error on the slope-coverage study's 28 ER walks with contacts (seed 0) is 0.05
#: times it (correlation 0.22), while on the tests' compliant truth (40 walks, seed 5, told the wheel) the
#: contact and impact lines share a shallow error of 0.015 deg in the mean. 0.09 makes the contact line's rms z
#: 1.00 over both (0.87 on the ER walks, 1.12 on the tests' truth; 0.055: 0.92 and 1.25; 0.11: 0.85 and 1.06;
#: the tests' truth measured before 88dc178, its uncompressed hold, which biased both lines shallow).
#: (It was 0.12, as the minima's, on k's 95 % low end until session 17.)
CONTACT_DRIFT_PER_IMPULSE = 0.09
#: sqrt(m / k) of a wheel the importer is not told about, s: the heaviest on the softest legs it is validated
#: on (3.0 kg on 1500 N/m: 0.045 s; Table 1: 2.19 kg on 2700 N/m, 0.028 s). ASSUMED, a bound, not measured.
UNKNOWN_LEG_TIME_S = 0.045


@dataclass(frozen=True)
class LegCompliance:
    """What the importer knows of the legs' spring: ``time_s`` = sqrt(m / k) (s; 0: rigid legs) and where it
    came from (``source``, in words)."""

    time_s: float
    source: str


def leg_compliance(wheel: Any = None) -> LegCompliance:
    """The legs' sqrt(m / k) from the wheel (a `rimless.sim.Wheel` or a wheel input: ``params`` with
    ``uncertainty`` or ``entries``; None: not told, `UNKNOWN_LEG_TIME_S`). A rigid model (``model`` "rigid")
    has no spring: 0. Otherwise the stated mass and stiffness (the drift allowance is a standard deviation: its
    expected square takes E[m / k] = m / k (1 + (sd_k / k)^2) to second order, 1 % above m / k at Table 1's
    10 %; the ends of their 95 % intervals would add 12 % to sqrt(m / k)); a stiffness whose 95 %
    interval reaches zero is not known: the bound."""
    if wheel is None:
        return LegCompliance(
            UNKNOWN_LEG_TIME_S,
            f"wheel not given: sqrt(m/k) up to {UNKNOWN_LEG_TIME_S * 1e3:.0f} ms assumed (3 kg on 1500 N/m legs)",
        )
    if getattr(wheel, "model", None) == "rigid":
        return LegCompliance(0.0, "rigid legs (the wheel's model): no drift")
    p = wheel.params

    def sd(name: str) -> float:
        unc = getattr(wheel, "uncertainty", None)
        if isinstance(unc, dict) and name in unc:
            return float(unc[name])
        entries = getattr(wheel, "entries", None)
        if isinstance(entries, dict) and name in entries:
            return float(entries[name].sd)
        return 0.0

    k, sd_k = float(p.stiffness_n_per_m), sd("stiffness_n_per_m")
    fitted = getattr(getattr(wheel, "input", wheel), "fit", ())
    if "stiffness_n_per_m" in tuple(fitted or ()):
        return LegCompliance(UNKNOWN_LEG_TIME_S, "the wheel's k is to be fitted, not known: the bound assumed")
    mass = float(p.hub_mass_kg) + 8 * float(p.leg_mass_kg)
    k_lo = k - Z95 * sd_k
    if not (math.isfinite(k_lo) and k_lo > 0 and math.isfinite(mass) and mass > 0):
        return LegCompliance(
            UNKNOWN_LEG_TIME_S, f"the wheel's k = {k:.0f} +- {sd_k:.0f} N/m is not known: the bound assumed"
        )
    sd_m = math.hypot(sd("hub_mass_kg"), 8 * sd("leg_mass_kg"))
    # E[m / k] to second order in the relative sds (k's and m's errors independent): the drift's expected square
    rel = 1.0 + (sd_k / k) ** 2
    return LegCompliance(
        math.sqrt(mass / k * rel),
        f"the wheel's legs: k = {k:.0f} +- {sd_k:.0f} N/m, m = {mass:.2f} +- {sd_m:.2f} kg",
    )


def speed_change_m_s(
    impact_along_m: np.ndarray | None, impact_time_s: np.ndarray | None, alpha_rad: float
) -> float | None:
    """The change of the impact normal speed over the trial, m/s: the range of the hub's mean speed from impact
    to impact (distance along the travel / time) times cos(alpha / 2) (the hub's velocity, square to the old
    leg, against the new leg). None with fewer than three impacts (no two steps to compare)."""
    if impact_along_m is None or impact_time_s is None:
        return None
    s, t = np.asarray(impact_along_m, float), np.asarray(impact_time_s, float)
    if s.size != t.size or s.size < 3 or not (np.isfinite(s).all() and np.isfinite(t).all()):
        return None
    dt = np.diff(t)
    if (dt <= 0).any():
        return None
    return float(np.ptp(np.diff(s) / dt)) * math.cos(alpha_rad / 2)


def _drift_m(factor: float, fallback_m: float, legs: LegCompliance, dv_m_s: float | None) -> tuple[float, str]:
    """The drift allowed over the trial (1 sigma, m) and how it was found (in words)."""
    if dv_m_s is None:
        return fallback_m, f"{fallback_m * 1e3:.2f} mm of drift allowed (no speed change seen: fewer than 3 impacts)"
    if legs.time_s <= 0:
        return 0.0, f"no drift: {legs.source}"
    d = factor * dv_m_s * legs.time_s
    return d, (
        f"{d * 1e3:.3f} mm of drift allowed ({factor:g} x the impact speed change {dv_m_s * 1e3:.0f} mm/s x "
        f"sqrt(m/k) {legs.time_s * 1e3:.1f} ms; {legs.source})"
    )


@dataclass(frozen=True)
class SlopeEvidence:
    """One source of the trial's slope: ``source`` ramp | given | estimated, the slope and its 95 % interval
    (rad), how it was obtained (``method``, in words) and ``kind`` (ramp, given, contacts, impact line, path)."""

    source: str
    slope_rad: float
    ci_rad: tuple[float, float]
    method: str
    kind: str = ""
    #: the part of the half width (rad, 95 %) from a drift every estimate of the trial shares (a compliant leg's
    #: compression changing with the speed): combining estimates does not reduce it
    common_half_rad: float = 0.0

    @property
    def half_rad(self) -> float:
        """Half the interval's width, rad."""
        return (self.ci_rad[1] - self.ci_rad[0]) / 2


def _interval(slope_rad: float, half_rad: float) -> tuple[float, float]:
    return (slope_rad - half_rad, slope_rad + half_rad)


def _quantile(dof: int) -> float:
    """Two-sided 95 % quantile of Student's t with ``dof`` degrees of freedom (normal for none)."""
    return Z95 if dof <= 0 else float(student_t.ppf(0.975, dof))


def _contact_chi2(cs) -> float:
    """Reduced chi-square of the contact heights about their weighted line (against the distance along the
    line from the first contact to the last)."""
    c = np.array([k.c_m for k in cs])
    w = 1.0 / np.array([k.sd_m for k in cs]) ** 2
    u = c[-1, :2] - c[0, :2]
    s = (c[:, :2] - c[0, :2]) @ (u / max(float(np.linalg.norm(u)), 1e-12))
    z = c[:, 2]
    sm, zm = (w * s).sum() / w.sum(), (w * z).sum() / w.sum()
    sxx = float((w * (s - sm) ** 2).sum())
    if sxx <= 0:
        return 1.0
    b = float((w * (s - sm) * (z - zm)).sum()) / sxx
    r = z - zm - b * (s - sm)
    return float((w * r**2).sum()) / (len(cs) - 2)


def _hub_offset_sd(
    along: np.ndarray,
    hub_sd_m: float | None,
    step_m: float,
    alpha_rad: float,
    height_cov_m2: np.ndarray | None = None,
) -> float:
    """1-sigma slope error (rad) of the line through the hub at the impacts from an error of the hub offset: the
    error turns with the wheel, so the heights at the impacts carry a sinusoid a line may read as slope. Its
    least-squares slope, propagated exactly: through ``height_cov_m2`` (k, k), the heights' covariance at the
    impacts from the offset's covariance and the body's rotations there, when given; else ``hub_sd_m`` on each axis
    in the wheel plane, the error turning alpha a step."""
    if along.size < 2:
        return 0.0
    s = along - along.mean()
    sxx = float(s @ s)
    if sxx <= 0:
        return 0.0
    w = s / sxx
    if height_cov_m2 is not None and np.shape(height_cov_m2) == (along.size, along.size):
        return math.sqrt(max(float(w @ np.asarray(height_cov_m2, float) @ w), 0.0))
    if hub_sd_m is None or not math.isfinite(hub_sd_m) or hub_sd_m <= 0:
        return 0.0
    turn = alpha_rad * np.round((along - along[0]) / max(step_m, 1e-6))
    return hub_sd_m * math.hypot(float(w @ np.cos(turn)), float(w @ np.sin(turn)))


def _contact_evidence(
    contacts,
    contact_slope: tuple[float, float, float],
    floor: float,
    legs: LegCompliance,
    dv_m_s: float | None,
) -> SlopeEvidence:
    """The contact line's evidence: the contacts' height errors (two contacts: at least `TWO_CONTACT_SD_M` each,
    they cannot show their scatter; three or more: scaled by their scatter, `CONTACT_CHI2_FLOOR`) and the legs'
    drift over the contacts' run (`CONTACT_DRIFT_PER_IMPULSE`; `CONTACT_DRIFT_M` without a speed change)."""
    phi, se, rms = contact_slope
    cs = contacts.contacts
    n = len(cs)
    c = np.array([k.c_m for k in cs])
    run = max(float(np.ptp((c[:, :2] - c[0, :2]) @ _unit(c[-1, :2] - c[0, :2]))), 1e-3)
    drift_m, drift_how = _drift_m(CONTACT_DRIFT_PER_IMPULSE, CONTACT_DRIFT_M, legs, dv_m_s)
    drift = Z95 * math.atan(drift_m / run)
    if n == 2:
        sd = [max(k.sd_m, TWO_CONTACT_SD_M) for k in cs]
        se = max(se, math.hypot(*sd) / run * math.cos(phi) ** 2)
        how = (
            f"line through 2 stance-foot contact points (walking window; no-slip: a stance foot does not move), "
            f"each height +- {max(sd) * 1e3:.2f} mm (two points show no scatter: at least "
            f"{TWO_CONTACT_SD_M * 1e3:.1f} mm assumed, which covers their drift)"
        )
        half = max(Z95 * se, floor)
        return SlopeEvidence("estimated", phi, _interval(phi, half), how, "contacts", min(drift, half))
    chi2 = _contact_chi2(cs)
    # the scaled errors no smaller than a contact's own floor (a foot is no point): the least scale
    least = CONTACT_FLOOR_M / float(np.median([k.sd_m for k in cs]))
    scale = math.sqrt(max(chi2, CONTACT_CHI2_FLOOR, least**2))
    stated = se / math.sqrt(max(chi2, 1.0))  # the line's error from the stated errors (chi2 undone when above 1)
    # the scatter's scale with its Student t, or the stated errors' (normal: they bound the scale), the narrower
    dof = n - 2 if _quantile(n - 2) * scale < Z95 * max(scale, 1.0) else 0
    se = stated * (scale if dof else max(scale, 1.0))
    half = max(math.hypot(_quantile(dof) * se, drift), floor)
    how = (
        f"line through {n} stance-foot contact points (walking window; no-slip: a stance foot does not "
        f"move), scatter {rms * 1e3:.2f} mm (reduced chi-square {chi2:.2f}: "
        + (
            f"their stated height errors scaled by {scale:.2f}; Student t with {dof} degrees of freedom)"
            if dof
            else "their stated height errors, which bound the scale, too few contacts to narrow them)"
        )
        + f", and {drift_how.replace('drift allowed', 'drift of the contact heights allowed', 1)}"
    )
    return SlopeEvidence("estimated", phi, _interval(phi, half), how, "contacts", min(drift, half))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def slope_evidence(
    ramp_deg: float | None,
    ramp_src: str | None,
    given_deg: float | None,
    contact_slope: tuple[float, float, float] | None,
    contacts,
    hub_line,
    frame0,
    n_minima: int,
    *,
    hub_unknown: bool = False,
    travel_m: float = 1.0,
    step_m: float = 0.18,
    impact_along_m: np.ndarray | None = None,
    hub_sd_m: float | None = None,
    alpha_rad: float = math.pi / 4,
    impact_time_s: np.ndarray | None = None,
    legs: LegCompliance | None = None,
    hub_height_cov_m2: np.ndarray | None = None,
) -> list[SlopeEvidence]:
    """Every slope source of the trial: ramp, given, then the estimates (contacts, impact line, or the whole
    path when neither exists). ``hub_line`` and ``frame0`` are `slope.SlopeFrame` fits (the hub at the CoM
    minima, the whole path); ``travel_m`` the distance walked along the slope, ``step_m`` the hub's travel per step;
    ``impact_along_m`` the impacts' horizontal distances along the travel (the points of ``hub_line``), ``hub_sd_m``
    the standard error of the hub the stance feet or the height placed (None when the hub was given),
    ``hub_height_cov_m2`` (k, k) the covariance of the hub's heights at those impacts from the offset's error, m^2
    (the height fit's covariance carried through the body's rotations; replaces ``hub_sd_m``'s term when given),
    ``alpha_rad`` the angle between legs; ``impact_time_s`` the impacts' times (s, with ``impact_along_m``: the
    speed change, `speed_change_m_s`), ``legs`` the legs' spring (`leg_compliance`; None: the wheel not given)."""
    legs = leg_compliance(None) if legs is None else legs
    dv = speed_change_m_s(impact_along_m, impact_time_s, alpha_rad)
    out = []
    if ramp_deg is not None and math.isfinite(ramp_deg):
        r = math.radians(ramp_deg)
        out.append(
            SlopeEvidence(
                "ramp",
                r,
                _interval(r, math.radians(RAMP_SLOPE_HALF_WIDTH_DEG)),
                f"{ramp_src} (95 % interval +- {RAMP_SLOPE_HALF_WIDTH_DEG} deg assumed)",
                "ramp",
            )
        )
    if given_deg is not None:
        g = math.radians(given_deg)
        out.append(
            SlopeEvidence(
                "given",
                g,
                _interval(g, math.radians(GIVEN_SLOPE_HALF_WIDTH_DEG)),
                f"given by the user (95 % interval +- {GIVEN_SLOPE_HALF_WIDTH_DEG} deg assumed)",
                "given",
            )
        )
    floor = math.radians(MIN_ESTIMATE_HALF_WIDTH_DEG)
    estimates = []
    if contact_slope is not None:
        estimates.append(_contact_evidence(contacts, contact_slope, floor, legs, dv))
    if hub_line is not None and math.isfinite(hub_line.se_rad):
        dof = hub_line.n_points - 2
        along = None if impact_along_m is None else np.asarray(impact_along_m, float)
        if along is not None and not np.isfinite(along).all():
            along = None  # (not expected: then the drift over the whole travel, and no hub term)
        span = float(np.ptp(along)) if along is not None and along.size > 1 else travel_m
        drift_m, drift_how = _drift_m(MINIMA_DRIFT_PER_IMPULSE, MINIMA_DRIFT_M, legs, dv)
        drift = Z95 * math.atan(drift_m / max(span, 1e-3))
        hub_rad = _hub_offset_sd(along, hub_sd_m, step_m, alpha_rad, hub_height_cov_m2) if along is not None else 0.0
        half = max(math.hypot(_quantile(dof) * hub_line.se_rad, drift, Z95 * hub_rad), floor)
        how = (
            f"{hub_line.source} (walking window; scatter {hub_line.residual_m * 1e3:.2f} mm, Student t with {dof} "
            f"degrees of freedom, and {drift_how.replace('drift allowed', 'drift of the minima depth allowed', 1)}"
            + (
                f"; the hub's standard error {hub_sd_m * 1e3:.2f} mm carried ({math.degrees(hub_rad):.4f} deg)"
                if hub_rad > 0 and hub_sd_m is not None
                else ""
            )
            + ")"
        )
        if hub_unknown:
            half = max(half, math.atan(2 * OFFSET_BOUND_M / max(travel_m, 1e-3)))
            how += (
                f"; the hub is not determined: the interval allows an origin up to {OFFSET_BOUND_M * 1e3:.0f} mm off it"
            )
        estimates.append(
            SlopeEvidence(
                "estimated",
                hub_line.slope_rad,
                _interval(hub_line.slope_rad, half),
                how,
                "impact line",
                min(drift, half),
            )
        )
    if not estimates and (given_deg is None and ramp_deg is None or hub_line is not None):
        line = hub_line if hub_line is not None else frame0
        half = max(Z95 * line.se_rad, floor) if math.isfinite(line.se_rad) else math.radians(45.0)
        how = f"{line.source} (walking window; {n_minima} CoM minima, 3 needed for the impact line)"
        if hub_line is None and math.isfinite(line.residual_m) and travel_m > 0:
            # The hub rises and falls once a step: its residuals are not independent samples. One per step:
            # the standard error of a line through n_steps points spread evenly over the travel.
            n_steps = max(travel_m / max(step_m, 1e-3), 1.0)
            se_steps = line.residual_m * math.sqrt(12.0 / n_steps) / travel_m
            half = max(half, _quantile(max(int(n_steps) - 2, 1)) * se_steps)
            how += f"; the hub's rise and fall counted once a step ({n_steps:.1f} steps)"
        if hub_unknown:
            # An origin up to OFFSET_BOUND_M off an unknown hub rises and falls by up to twice that along the path.
            half = max(half, math.atan(2 * OFFSET_BOUND_M / max(travel_m, 1e-3)))
            how += (
                "; the hub is not determined (fewer than two stance feet seen, too little rotation): the "
                f"interval allows an origin up to {OFFSET_BOUND_M * 1e3:.0f} mm off the hub"
            )
        estimates.append(SlopeEvidence("estimated", line.slope_rad, _interval(line.slope_rad, half), how, "path"))
    estimates.sort(key=lambda e: e.half_rad)  # the best conditioned first
    return out + estimates


def _disagree(a: SlopeEvidence, b: SlopeEvidence) -> bool:
    return abs(a.slope_rad - b.slope_rad) > math.hypot(a.half_rad, b.half_rad)


def _covariance(group: list[SlopeEvidence]) -> np.ndarray:
    """The estimates' covariance in squared 95 % half widths (rad^2): each its own half width squared on the
    diagonal; off it, the legs' drift (``common_half_rad``) counted as fully shared, the rest independent.

    Measured (session 17, told the wheel, `rimless trials slope-coverage --series 40 --seed 0` and the tests'
    compliant truth, `import_truth_study.py slope --draws 40 --seed 5 --wheel-given`): the contact and impact
    lines' errors correlate -0.08 on the rigid truth (no drift: their own parts are independent), -0.06 on the
    ER truth (sum of the products of their errors -0.05 urad^2 against 0.35 if the drift were shared) and share
    about half the drift on the tests' compliant truth (1.68 against 3.29 urad^2; the mean product of their z
    0.71; measured on that truth before 88dc178, its uncompressed hold, which biased both lines shallow: after it
    they correlate +0.28). Counting the drift as shared is the reading that covers every truth; the hub's term (2-7 % of the
    impact line's standard deviation with the converged hub fit) is in the impact line's own part."""
    h = np.array([e.half_rad for e in group])
    c = np.array([min(e.common_half_rad, e.half_rad) for e in group])
    cov = np.outer(c, c)
    np.fill_diagonal(cov, h**2)
    return cov


def _combination_weights(cov: np.ndarray) -> np.ndarray:
    """Weights (summing to 1, none negative) of the least-variance combination of estimates with covariance
    ``cov``: generalised least squares, an estimate whose weight would be negative dropped (a negative weight
    extrapolates along the shared drift, trusting its sharing exactly; the data show it partly shared)."""
    n = cov.shape[0]
    active = list(range(n))
    while True:
        sub = cov[np.ix_(active, active)]
        w = np.linalg.pinv(sub) @ np.ones(len(active))
        total = float(w.sum())
        if not (math.isfinite(total) and total > 0):  # (not expected: the narrowest alone)
            out = np.zeros(n)
            out[int(np.argmin(np.diag(cov)))] = 1.0
            return out
        w = w / total
        if (w >= 0).all() or len(active) == 1:
            out = np.zeros(n)
            out[active] = np.clip(w, 0.0, None) / np.clip(w, 0.0, None).sum()
            return out
        del active[int(np.argmin(w))]


def choose_slope(evidence: list[SlopeEvidence]) -> tuple[list[SlopeEvidence], list[str], list[str]]:
    """(evidence with the one used first, warnings, notes): the first source is used (ramp, given, else the best
    conditioned estimate); an estimate used that disagrees with another estimate gets an interval spanning both;
    every pair that disagrees is warned about."""
    if not evidence:
        return evidence, [], []
    warnings: list[str] = []
    notes: list[str] = []
    used = evidence[0]
    for i, a in enumerate(evidence):
        for b in evidence[i + 1 :]:
            if not _disagree(a, b):
                continue
            h = math.hypot(a.half_rad, b.half_rad)
            diff = abs(a.slope_rad - b.slope_rad)
            what = (
                f"the {a.source} slope {math.degrees(a.slope_rad):.3f} deg"
                if a.kind in ("ramp", "given")
                else f"the slope from the {a.kind} {math.degrees(a.slope_rad):.3f} deg"
            )
            other = (
                f"the {b.source} slope {math.degrees(b.slope_rad):.3f} deg"
                if b.kind in ("ramp", "given")
                else f"the slope from the {b.kind} {math.degrees(b.slope_rad):.3f} deg"
            )
            warnings.append(
                f"{what} and {other} disagree by {math.degrees(diff):.3f} deg, more than their uncertainty "
                f"({math.degrees(h):.3f} deg at 95 %); {used.source}"
                + (f" ({used.kind})" if used.source == "estimated" else "")
                + " is used"
            )
    if used.source == "estimated":
        others = [e for e in evidence[1:] if e.source == "estimated" and _disagree(used, e)]
        if others:
            lo = min([used.ci_rad[0]] + [e.ci_rad[0] for e in others])
            hi = max([used.ci_rad[1]] + [e.ci_rad[1] for e in others])
            used = replace(
                used,
                ci_rad=(lo, hi),
                method=used.method
                + "; the interval spans the disagreeing "
                + ", ".join(e.kind for e in others)
                + " estimate (the data cannot say which is wrong)",
            )
        agreeing = [e for e in evidence[1:] if e.source == "estimated" and not _disagree(used, e)]
        if agreeing and not others:
            # consistent estimates from different data (stance pivots, impact cusps): the least-variance
            # combination under their covariance (`_combination_weights`)
            group = [used] + agreeing
            cov = _covariance(group)
            w = _combination_weights(cov)
            mean = float(w @ np.array([e.slope_rad for e in group]))
            half = math.sqrt(max(float(w @ cov @ w), 0.0))
            used = SlopeEvidence(
                "estimated",
                mean,
                _interval(mean, half),
                "least-variance combination of the consistent estimates (their own errors independent, the legs' "
                "drift counted as shared; weights "
                + ", ".join(f"{wi:.2f}" for wi in w)
                + "): "
                + "; ".join(f"{e.method} -> {math.degrees(e.slope_rad):.3f} deg" for e in group),
                "combined " + " and ".join(e.kind for e in group),
                float(w @ np.array([e.common_half_rad for e in group])),
            )
        rest = [e for e in evidence[1:] if e.source == "estimated"]
        if rest:
            notes.append(
                f"slope from the {used.kind}; also estimated: "
                + "; ".join(
                    f"{e.kind} {math.degrees(e.slope_rad):.3f} deg [{math.degrees(e.ci_rad[0]):.3f}, "
                    f"{math.degrees(e.ci_rad[1]):.3f}]"
                    for e in rest
                )
            )
    return [used] + evidence[1:], warnings, notes
