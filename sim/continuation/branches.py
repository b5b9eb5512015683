"""Every period-1 gait at a start slope, each continued down in slope to the end of its stable, valid part.

For one wheel (ER or VE, one parameter set): find the gaits at the start slope (rimless.sim.step.poincare.find_gaits),
record each one's contact facts (rimless.sim.continuation.arclength.ContactFacts), and follow each by pseudo-arclength
continuation in the slope, decreasing, until its first special point (fold, period doubling,
Neimark-Sacker, loss of contact validity, stall or the end of the branch). For a gait stable and valid
at the start, that point is the branch's critical slope (model.md section 7: the smallest slope of the
followed branch with a stable, valid period-1 gait); for an unstable or invalid one it is where the branch
first changes character.

One start slope misses gaits: a stable, valid segment of a branch need not reach the start slope (at k = 2000 N/m
the VE "medium" gait walks from 0.0224 rad up to a fold at 0.0477 rad, so a search at 0.05 rad never meets it).
`search_slopes_rad` names further slopes at which gaits are searched again (search_slopes gives the default set);
each gait stable and contact-valid there, not already on a traced branch, is followed down to the end of its
stable, valid part too (rows with `found_at_slope_rad` = that slope). Assumption, carried in the rows: a stable,
valid segment that contains none of the search slopes is not found (the spacing of the slopes is the limit).
Slopes in rad; forces N; periods s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from rimless.sim.continuation.arclength import ArclengthContinuation, Branch, BranchPoint, SpecialPoint
from rimless.sim.continuation.contact import ContactFacts, contact_facts
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import WheelParams

START_SLOPE_RAD = 0.05
MIN_SLOPE_RAD = 1e-4
#: where gaits are searched again below the start slope, as fractions of it (0.05 rad: 0.04, 0.03, 0.024, 0.022 and
#: 0.0205 rad; the critical slopes of Table 1's neighbourhood lie at 0.020-0.027 rad)
SEARCH_SLOPE_FRACTIONS = (0.8, 0.6, 0.48, 0.44, 0.41)
#: theta'+ guesses per search slope over SEARCH_THETA_DOT_RAD_S: 14 guesses over the start slope's 0.8-6 rad/s
#: missed the stable VE "slow" gait at k = 3000 N/m, 0.022 rad (theta'+ 1.98 rad/s), that 40 over 0.8-6 find; the
#: gaits near the critical slopes start their step at 1.8-2.7 rad/s
SEARCH_GUESSES = 20
SEARCH_THETA_DOT_RAD_S = (1.0, 3.5)
#: a gait found at a search slope lies on an already traced branch when its section point is this close (rad,
#: rad/s, max norm) to the branch interpolated at that slope; distinct gaits differ by 0.1 rad/s and more
SAME_BRANCH_TOL = 0.02


def search_slopes(start_slope_rad: float, fractions: tuple[float, ...] = SEARCH_SLOPE_FRACTIONS) -> tuple[float, ...]:
    """The default slopes (rad) below `start_slope_rad` at which gaits are searched again."""
    return tuple(float(start_slope_rad) * f for f in fractions)


def branch_label(model: str, period_s: float, stable: bool, k: float = 2700.0) -> str:
    """A readable name of a gait: `er`; for VE `fast`/`medium`/`slow` when stable, else `unstable`.

    VE names go by the step period scaled to Table 1's stiffness, T sqrt(k / 2700 N/m): the fast gait's step
    lasts about one leg oscillation, so its period scales like 1/sqrt(k) (about 0.25 s scaled over
    k = 1500..3500), the medium gait's does not (about 0.39-0.41 s scaled); model.md section 9."""
    if model == "er":
        return "er" if stable else "er-unstable"
    if not stable:
        return "unstable"
    scaled = period_s * (k / 2700.0) ** 0.5
    return "fast" if scaled < 0.33 else ("medium" if scaled < 0.5 else "slow")


def contact_reason(facts: ContactFacts | None) -> str:
    """Why a gait is not contact-valid, with the size of the violation ('' when it is valid)."""
    if facts is None:
        return "the step could not be recorded"
    reasons = []
    if not facts.min_stance_force_single_support_N >= 0.0:
        txt = f"stance-lift-off: the stance foot pulls in single support (min {facts.min_stance_force_single_support_N:.3g} N"
        if facts.min_stance_force_time_s == facts.min_stance_force_time_s:
            txt += f" at t = {facts.min_stance_force_time_s:.4f} s"
        if facts.negative_stance_force_s > 0.0:
            txt += f", below 0 for {facts.negative_stance_force_s * 1e3:.1f} ms"
        reasons.append(txt + ")")
    if not facts.min_impulse_N_s > 0.0:
        reasons.append(f"negative-impulse: a normal impact impulse <= 0 ({facts.min_impulse_N_s:.3g} N s)")
    if not reasons and facts.unilateral_failure:
        reasons.append(f"the unilateral map fails at this gait ({facts.unilateral_failure})")
    if reasons and facts.bilateral:
        reasons.append("found with the stance foot held (bilateral contact)")
    return "; ".join(reasons)


@dataclass
class GaitBranch:
    """One gait at the start slope and its branch followed down in slope."""

    id: str
    label: str
    model: str
    params: WheelParams  # at the start slope
    start: BranchPoint
    branch: Branch | None
    end: SpecialPoint | None
    error: str = ""
    found_by: str = "start-slope"  # or "search at a lower slope" (a gait the start slope does not have)

    @property
    def stable_at_start(self) -> bool:
        return self.start.stable

    @property
    def contact_valid_at_start(self) -> bool:
        return self.start.facts is not None and self.start.facts.contact_valid

    @property
    def critical_slope_rad(self) -> float | None:
        """The end of the stable, valid part (None when the gait is not stable and valid at the start)."""
        if not (self.stable_at_start and self.contact_valid_at_start) or self.end is None:
            return None
        return self.end.p

    @property
    def reason(self) -> str:
        if self.error:
            return "solver"
        if not self.stable_at_start:
            return "unstable-at-start"
        if not self.contact_valid_at_start:
            return "contact-invalid-at-start"
        return self.end.kind if self.end is not None else "min-slope"

    def row(self) -> dict[str, Any]:
        """One tidy row (keys are a contract: add, never rename)."""
        p = self.params
        f = self.start.facts
        crit = self.critical_slope_rad
        end_pt = self.end.point if self.end is not None else None
        pts = self.branch.points if self.branch is not None else [self.start]
        # along the part followed up to the first special point (the stable, valid part for a stable gait)
        limit = end_pt.arclength if end_pt is not None else math.inf
        along = [pt for pt in pts if pt.arclength <= limit] or [self.start]
        end_facts = end_pt.facts if end_pt is not None else None
        return {
            "model": self.model.upper(),
            "k": p.k,
            "c": p.c,
            "mass_model": p.mass_model,
            "hub_mass_kg": p.hub_mass_kg,
            "leg_mass_kg": p.leg_mass_kg,
            "start_slope_rad": p.slope_rad,
            "found_at_slope_rad": p.slope_rad,
            "found_by": self.found_by,
            "branch": self.id,
            "branch_label": self.label,
            "theta_plus_rad": float(self.start.z[0]),
            "theta_dot_plus_rad_s": float(self.start.z[1]),
            "step_period_s": self.start.period_s,
            "stable_at_start": self.stable_at_start,
            "max_abs_eigenvalue_at_start": self.start.max_abs_eigenvalue,
            "contact_valid_at_start": self.contact_valid_at_start,
            "contact_reason": contact_reason(f),
            "contact_violation": f.violation if f else "unknown",
            "contact_model": "bilateral" if f is not None and f.bilateral else "unilateral",
            "min_stance_force_time_s": f.min_stance_force_time_s if f else math.nan,
            "negative_stance_force_s": f.negative_stance_force_s if f else math.nan,
            "min_stance_force_single_support_N": f.min_stance_force_single_support_N if f else math.nan,
            "min_impulse_N_s": f.min_impulse_N_s if f else math.nan,
            "leading_foot_tension_N": f.leading_foot_tension_N if f else math.nan,
            "leading_foot_tension_s": f.leading_foot_tension_s if f else math.nan,
            "trailing_foot_min_height_m": f.trailing_foot_min_height_m if f else math.nan,
            "friction_required": f.friction_required if f else math.nan,
            "energy_ratio": f.energy_ratio if f else math.nan,
            "relabel_energy_J": f.relabel_energy_J if f else math.nan,
            "critical_slope_rad": crit if crit is not None else math.nan,
            "critical_slope_deg": math.degrees(crit) if crit is not None else math.nan,
            "cot": math.tan(crit) if crit is not None else math.nan,
            "reason": self.reason,
            "detail": self.error or (self.end.detail if self.end is not None else ""),
            "end_slope_rad": self.end.p if self.end is not None else math.nan,
            "end_location_tol_rad": abs(self.end.bracket_p[1] - self.end.bracket_p[0])
            if self.end is not None
            else math.nan,
            "end_theta_plus_rad": float(end_pt.z[0]) if end_pt is not None else math.nan,
            "end_theta_dot_plus_rad_s": float(end_pt.z[1]) if end_pt is not None else math.nan,
            "end_max_abs_eigenvalue": end_pt.max_abs_eigenvalue if end_pt is not None else math.nan,
            "end_step_period_s": end_pt.period_s if end_pt is not None else math.nan,
            "end_energy_ratio": end_facts.energy_ratio if end_facts is not None else math.nan,
            "end_min_stance_force_N": end_facts.min_stance_force_single_support_N
            if end_facts is not None
            else math.nan,
            "end_contact_valid": bool(end_facts.contact_valid) if end_facts is not None else None,
            "max_abs_eigenvalue": max(pt.max_abs_eigenvalue for pt in along),
            "period_min_s": min(pt.period_s for pt in along),
            "period_max_s": max(pt.period_s for pt in along),
            "energy_ratio_min": min((pt.facts.energy_ratio for pt in along if pt.facts), default=math.nan),
            "energy_ratio_max": max((pt.facts.energy_ratio for pt in along if pt.facts), default=math.nan),
            **self._valid_part(),
            "branch_points": len(pts),
            "map_evaluations": self.branch.map_evaluations if self.branch else 0,
            "continuation_s": self.branch.seconds if self.branch else 0.0,
        }

    def location_tolerance(self, backend: str, rtol: float, factor: float = 10.0) -> dict[str, float]:
        """How well the critical slope is known (rad): the final bracket of its location, and how far it moves
        when the map is integrated with rtol x `factor` (re-traced down from the branch point just above it).
        critical_slope_tol_rad is the larger; NaN keys when the gait has no critical slope or the re-trace fails."""
        nan = {"critical_slope_bracket_rad": math.nan, "critical_slope_rtol_shift_rad": math.nan}
        crit = self.critical_slope_rad
        if crit is None or self.end is None or self.branch is None:
            return {**nan, "critical_slope_tol_rad": math.nan}
        from rimless.sim.step.backend import make_map

        bracket = abs(self.end.bracket_p[1] - self.end.bracket_p[0])
        above = [pt for pt in self.branch.points if pt.p > crit and pt.arclength < self.end.point.arclength]
        shift = math.nan
        if above:
            pt = above[-1]
            q = self.params.replace(slope_rad=pt.p)
            held = bool(self.start.facts is not None and self.start.facts.bilateral)

            def factory(w: WheelParams) -> Any:
                from rimless.sim.step.poincare import bilateral_map

                m = make_map(w, self.model, backend=backend, rtol=rtol * factor)
                return bilateral_map(m) if held else m

            try:
                br = ArclengthContinuation(factory, q, self.model, "slope", max_points=60).trace(
                    pt.z, direction=-1.0, p_min=MIN_SLOPE_RAD, stop_at_first_loss=True
                )
                sp = br.first_loss()
                if sp is not None and sp.kind == self.end.kind:
                    shift = abs(sp.p - crit)
            except StepFailure:
                pass
        tol = max(bracket, shift) if shift == shift else bracket
        return {
            "critical_slope_bracket_rad": bracket,
            "critical_slope_rtol_shift_rad": shift,
            "critical_slope_tol_rad": tol,
        }

    def _valid_part(self) -> dict[str, Any]:
        """For a gait stable but not contact-valid at the start slope: the slope below which it is valid (its
        stance force or impulse through 0 going down) and where that valid part ends (its next special point)."""
        out = {"valid_from_slope_rad": math.nan, "valid_end_slope_rad": math.nan, "valid_end_reason": ""}
        if self.branch is None or self.contact_valid_at_start or not self.stable_at_start:
            return out
        sps = self.branch.special
        i = next((i for i, sp in enumerate(sps) if sp.kind in ("stance-force", "impulse")), None)
        if i is None:
            return out
        out["valid_from_slope_rad"] = sps[i].p
        nxt = next((sp for sp in sps[i + 1 :]), None)
        if nxt is not None:
            out["valid_end_slope_rad"], out["valid_end_reason"] = nxt.p, nxt.kind
        return out

    def point_rows(self) -> list[dict[str, Any]]:
        """The traced branch point by point (slope, state, period, max |eig|, stability, validity)."""
        if self.branch is None:
            return []
        out = []
        for pt in self.branch.points:
            out.append(
                {
                    "model": self.model.upper(),
                    "k": self.params.k,
                    "c": self.params.c,
                    "mass_model": self.params.mass_model,
                    "branch": self.id,
                    "branch_label": self.label,
                    "slope_rad": pt.p,
                    "slope_deg": math.degrees(pt.p),
                    "theta_plus_rad": float(pt.z[0]),
                    "theta_dot_plus_rad_s": float(pt.z[1]),
                    "step_period_s": pt.period_s,
                    "max_abs_eigenvalue": pt.max_abs_eigenvalue,
                    "stable": pt.stable,
                    "energy_ratio": pt.facts.energy_ratio if pt.facts else math.nan,
                    "contact_valid": pt.contact_valid,
                    "min_stance_force_single_support_N": pt.facts.min_stance_force_single_support_N
                    if pt.facts
                    else math.nan,
                }
            )
        return out


def _start_point(pmap: Any, fp: Any, model: str) -> BranchPoint:
    from rimless.sim.continuation.arclength import eigen_tests

    facts = None
    try:
        facts = contact_facts(pmap, fp.z, 5e-4)
    except StepFailure:
        pass
    return BranchPoint(
        pmap.params.slope_rad,
        np.asarray(fp.z),
        np.asarray(fp.jacobian),
        fp.step.period_s,
        0.0,
        eigen_tests(np.asarray(fp.jacobian)),
        facts,
        facts.contact_valid if facts else None,
    )


def _on_traced_branch(branches: list[GaitBranch], slope_rad: float, z: np.ndarray) -> GaitBranch | None:
    """The traced branch through (slope_rad, z), if any: z within SAME_BRANCH_TOL of the branch linearly
    interpolated between two neighbouring points that straddle the slope (or of a point at it)."""
    z = np.asarray(z, dtype=float)
    for gb in branches:
        pts = gb.branch.points if gb.branch is not None else [gb.start]
        for a, b in zip(pts, pts[1:] or pts):
            lo, hi = sorted((a.p, b.p))
            if not lo - 1e-12 <= slope_rad <= hi + 1e-12:
                continue
            w = 0.0 if hi - lo < 1e-15 else (slope_rad - a.p) / (b.p - a.p)
            if float(np.max(np.abs(a.z + w * (b.z - a.z) - z))) < SAME_BRANCH_TOL:
                return gb
    return None


def _trace_one(
    fp: Any,
    gid: str,
    model: str,
    start_params: WheelParams,
    pmap: Any,
    *,
    backend: str,
    rtol: float,
    to_end: bool,
    max_points: int,
    found_by: str = "start-slope",
) -> GaitBranch:
    """One gait (a FixedPoint at start_params.slope_rad) followed down in slope (see trace_gait_branches)."""
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import bilateral_map

    held = getattr(fp, "bilateral", False)  # violates unilateral contact: followed with the foot held
    start = _start_point(bilateral_map(pmap) if held else pmap, fp, model)
    label = branch_label(model, start.period_s, start.stable, start_params.k)
    gid = f"{gid}-{label}"

    def factory(q: WheelParams) -> Any:
        m = make_map(q, model, backend=backend, rtol=rtol)
        return bilateral_map(m) if held else m

    cont = ArclengthContinuation(factory, start_params, model, "slope", max_points=max_points)
    # a gait invalid at the start may become valid lower down: followed (foot held) past that point until
    # it stops being stable, so the row can say where its valid part lies
    held_stable = held and start.stable and not to_end
    try:
        br = cont.trace(
            fp.z,
            direction=-1.0,
            p_min=MIN_SLOPE_RAD,
            stop_at_first_loss=not (to_end or held_stable),
            start_facts=start.facts,
            stop=(lambda pt: not pt.stable) if held_stable else None,
        )
    except StepFailure as err:
        return GaitBranch(gid, label, model, start_params, start, None, None, error=str(err), found_by=found_by)
    end = next(iter(br.special), None)
    return GaitBranch(gid, label, model, start_params, start, br, end, found_by=found_by)


def trace_gait_branches(
    params: WheelParams,
    model: str,
    *,
    backend: str = "auto",
    rtol: float = 1e-10,
    start_slope_rad: float = START_SLOPE_RAD,
    n_guesses: int = 14,
    gaits: list[Any] | None = None,
    to_end: bool = False,
    max_points: int = 200,
    progress: Callable[[str], None] | None = None,
    search_slopes_rad: tuple[float, ...] = (),
    search_guesses: int = SEARCH_GUESSES,
) -> list[GaitBranch]:
    """Every period-1 gait at start_slope_rad and its branch down in slope (see module docstring).

    to_end: continue past the first special point to the end of the branch (or max_points) instead of
    stopping there. search_slopes_rad: further slopes (rad, below the start slope) at which gaits are searched
    again (search_guesses theta'+ guesses over SEARCH_THETA_DOT_RAD_S each); each stable, contact-valid one not on a branch already traced is
    followed down too (rows after those of the start slope, `found_by` "search at a lower slope").
    """
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import find_gaits

    start_params = params.replace(slope_rad=start_slope_rad)
    pmap = make_map(start_params, model, backend=backend, rtol=rtol)
    if gaits is None:
        gaits = find_gaits(pmap, n_guesses=n_guesses, include_invalid=True)
    out: list[GaitBranch] = []
    for i, fp in enumerate(sorted(gaits, key=lambda g: g.step.period_s)):
        if progress:
            progress(f"{model} k={params.k:g}: branch {i + 1} at {start_slope_rad:.5f} rad")
        gb = _trace_one(
            fp,
            f"{model}-{i + 1}",
            model,
            start_params,
            pmap,
            backend=backend,
            rtol=rtol,
            to_end=to_end,
            max_points=max_points,
        )
        out.append(gb)
    n = len(out)
    for slope in sorted((float(x) for x in search_slopes_rad if 0 < x < start_slope_rad), reverse=True):
        q = params.replace(slope_rad=slope)
        qmap = make_map(q, model, backend=backend, rtol=rtol)
        try:
            # unilateral gaits only: a candidate must be valid
            found = find_gaits(qmap, theta_dot_range=SEARCH_THETA_DOT_RAD_S, n_guesses=search_guesses)
        except StepFailure:
            continue
        for fp in sorted(found, key=lambda g: g.recorded_step.period_s):
            if not fp.stable or _on_traced_branch(out, slope, fp.z) is not None:
                continue
            n += 1
            if progress:
                progress(f"{model} k={params.k:g}: branch {n} found at {slope:.5f} rad")
            gb = _trace_one(
                fp,
                f"{model}-{n}",
                model,
                q,
                qmap,
                backend=backend,
                rtol=rtol,
                to_end=to_end,
                max_points=max_points,
                found_by="search at a lower slope",
            )
            if not (gb.stable_at_start and gb.contact_valid_at_start) or _same_end(out, gb):
                n -= 1
                continue
            out.append(gb)
    return out


def _same_end(branches: list[GaitBranch], gb: GaitBranch) -> bool:
    """gb's stable, valid part ends where one of `branches` ends (the same segment, found from another slope)."""
    if gb.end is None:
        return False
    for other in branches:
        if other.end is None or other.end.kind != gb.end.kind:
            continue
        tol = max(abs(other.end.bracket_p[1] - other.end.bracket_p[0]), abs(gb.end.bracket_p[1] - gb.end.bracket_p[0]))
        if (
            abs(other.end.p - gb.end.p) <= 10 * tol + 1e-9
            and float(np.max(np.abs(other.end.point.z - gb.end.point.z))) < SAME_BRANCH_TOL
        ):
            return True
    return False
