"""System cost of transport along a gait branch: the slope of least system CoT and the break-even clutch power.

With electrical power (rimless.sim.model.electrical.ClutchPower) the system CoT of a period-1 gait at slope phi is
    tan(phi) + E_el(phi) / (M g s_x(phi)),  M = m_H + 8 m,
and near the ER stall the step period and the clutched time, hence E_el, grow without bound: the least system CoT
of a branch lies above its critical slope. It is found over the branch's stable, valid slope range
[critical slope, start slope] in two stages: the system CoT at every fixed point the continuation recorded (the
discrete minimum), then a bounded Brent minimisation (scipy `minimize_scalar`, xatol = SLOPE_TOL_RAD) on the
bracket of the neighbouring recorded points, each evaluation a Newton solve of the fixed point from the
nearest recorded one. This assumes one minimum between neighbouring recorded points (they are 1e-3 rad or one
arclength step apart). A slope where the fixed point cannot be solved counts as +inf and is reported.

Break-even powers: the ER least system CoT grows monotonically with the holding power (and with the switching
energy), the VE branches' least does not depend on them; the break-even value is the root of their difference
(scipy `brentq`, relative tolerance BREAK_EVEN_RTOL), None when ER does not beat VE even at zero power.
Slopes in rad (and deg where the key says so), powers W, energies J.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from rimless.sim.model.electrical import ClutchPower, ClutchPowerChanges
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.params import WheelParams
from rimless.sim.step.cot import StepTransport, cot_of, step_transport

SLOPE_TOL_RAD = 1e-6
BREAK_EVEN_RTOL = 1e-6
HOLD_POWER_FIGURE_W = (0.0, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)


@dataclass
class BranchCot:
    """The system CoT along one branch's stable, valid part [lo_rad, hi_rad], from its recorded fixed points.

    make_map(params) -> a Poincaré map at those parameters; jacobian(pmap) -> a jacobian callable or None."""

    model: str
    params: WheelParams  # any slope: replaced per evaluation
    points: list[tuple[float, np.ndarray]]  # (slope rad, fixed point z), the continuation's
    make_map: Callable[[WheelParams], Any]
    jacobian: Callable[[Any], Any] | None = None
    label: str = ""
    lo_tol_rad: float = 0.0  # how well the lower end (the critical slope) is located, rad
    guessed: frozenset[float] = frozenset()  # slopes of `points` whose z is only a guess (solved on use)
    _cache: dict[float, StepTransport | None] = field(default_factory=dict)
    failed: int = 0

    def __post_init__(self) -> None:
        self.points = sorted(((float(s), np.asarray(z, dtype=float)) for s, z in self.points), key=lambda q: q[0])
        if not self.points:
            raise ValueError("a branch needs at least one fixed point")

    @property
    def lo_rad(self) -> float:
        return self.points[0][0]

    @property
    def hi_rad(self) -> float:
        return self.points[-1][0]

    def transport(self, slope_rad: float) -> StepTransport | None:
        """The step's travel and timing at this slope (None when the fixed point cannot be solved)."""
        key = float(slope_rad)
        if key in self._cache:
            return self._cache[key]
        from rimless.sim.step.poincare import solve_fixed_point

        q = self.params.replace(slope_rad=key)
        pmap = self.make_map(q)
        z0 = min(self.points, key=lambda pt: abs(pt[0] - key))[1]
        known = key not in self.guessed and any(s == key for s, _ in self.points)
        try:
            if not known:
                fp = solve_fixed_point(pmap, z0, jacobian=self.jacobian(pmap) if self.jacobian else None, record=False)
                z0 = fp.z
            tr: StepTransport | None = step_transport(pmap.step(z0), q)
        except StepFailure:
            tr = None
            self.failed += 1
        self._cache[key] = tr
        return tr

    def system_cot(self, slope_rad: float, power: ClutchPower) -> float:
        tr = self.transport(slope_rad)
        if tr is None:
            return math.inf
        return cot_of(tr, self.params.replace(slope_rad=float(slope_rad)), self.model, power)["system_cot"]

    def minimise(self, power: ClutchPower, tol_rad: float = SLOPE_TOL_RAD) -> dict[str, Any]:
        """min_system_cot and min_system_cot_slope_deg/_rad over [lo_rad, hi_rad] (see module docstring)."""
        if power.energy_per_step_j(self.model, 1.0, 1.0) == 0.0:
            s = self.lo_rad  # no electrical energy: system CoT = tan(phi), least at the branch's lowest slope
            return self._result(s, math.tan(s), power, "closed form: no electrical energy, system CoT = tan(phi)")
        from scipy.optimize import minimize_scalar

        slopes = [s for s, _ in self.points]
        values = [self.system_cot(s, power) for s in slopes]
        i = int(np.argmin(values))
        if not math.isfinite(values[i]):
            return self._result(math.nan, math.nan, power, "no fixed point on the branch could be evaluated")
        if len(slopes) == 1:
            return self._result(slopes[0], values[0], power, "one fixed point only")
        a, b = slopes[max(i - 1, 0)], slopes[min(i + 1, len(slopes) - 1)]
        res = minimize_scalar(
            lambda s: self.system_cot(s, power), bounds=(a, b), method="bounded", options={"xatol": tol_rad}
        )
        s_best, v_best = (float(res.x), float(res.fun)) if res.fun < values[i] else (slopes[i], values[i])
        how = (
            f"bounded Brent on [{a:.6f}, {b:.6f}] rad around the least of {len(slopes)} recorded fixed points, "
            f"xatol {tol_rad:g} rad"
        )
        if not res.success:
            how += f" (stopped: {res.message})"
        return self._result(s_best, v_best, power, how, tol_rad)

    def _result(self, s: float, v: float, power: ClutchPower, how: str, tol: float = 0.0) -> dict[str, Any]:
        tr = self.transport(s) if math.isfinite(s) else None
        at = cot_of(tr, self.params.replace(slope_rad=s), self.model, power) if tr is not None else {}
        near = 2 * tol + 1e-12
        bound = (
            "critical-slope"
            if math.isfinite(s) and s - self.lo_rad <= near
            else "start-slope"
            if math.isfinite(s) and self.hi_rad - s <= near
            else ""
        )
        return {
            "min_system_cot": v,
            "min_system_cot_slope_rad": s,
            "min_system_cot_slope_deg": math.degrees(s) if math.isfinite(s) else math.nan,
            "min_system_cot_slope_tol_rad": tol,
            "min_system_cot_at_bound": bound,
            "min_system_cot_step_period_s": tr.period_s if tr is not None else math.nan,
            "min_system_cot_clutched_time_s": tr.clutched_s if tr is not None else math.nan,
            "min_system_cot_electrical_energy_per_step_j": at.get("electrical_energy_per_step_j", math.nan),
            "min_system_cot_method": how,
            "min_system_cot_failed_evaluations": self.failed,
            "slope_range_rad": [self.lo_rad, self.hi_rad],
        }


def branch_factory(model: str, backend: str, rtol: float, held: bool = False) -> tuple[Callable, Callable | None]:
    from rimless.sim.step.backend import jacobian_factory, make_map
    from rimless.sim.step.poincare import bilateral_map

    def factory(q: WheelParams) -> Any:
        m = make_map(q, model, backend=backend, rtol=rtol)
        return bilateral_map(m) if held else m

    return factory, (None if held else jacobian_factory(backend))


def critical_slope_branch(cs: Any, params: WheelParams, backend: str, rtol: float) -> BranchCot:
    """The stable, valid part of an Algorithm 1 result (rimless.sim.continuation.algorithm1.CriticalSlope)."""
    crit = cs.critical_slope_rad
    pts = [(bp.slope_rad, bp.z) for bp in cs.branch if bp.slope_rad > crit]
    end_z = cs.end.point.z if cs.end is not None else cs.fixed_point.z
    pts.append((crit, end_z))
    factory, jac = branch_factory(cs.model, backend, rtol)
    tol = cs.located_to_rad if cs.located_to_rad is not None else cs.refine_tol_rad
    return BranchCot(cs.model, params, pts, factory, jac, label=cs.model, lo_tol_rad=tol)


def gait_branch_cot(gb: Any, backend: str, rtol: float) -> BranchCot | None:
    """The stable, valid part of a traced gait branch (rimless.sim.continuation.branches.GaitBranch), or None
    when the gait is not stable and valid at the start slope."""
    crit = gb.critical_slope_rad
    if crit is None or gb.branch is None:
        return None
    pts = [(pt.p, pt.z) for pt in gb.branch.points if pt.p > crit]
    pts.append((crit, gb.end.point.z))
    held = bool(gb.start.facts is not None and gb.start.facts.bilateral)
    factory, jac = branch_factory(gb.model, backend, rtol, held)
    tol = abs(gb.end.bracket_p[1] - gb.end.bracket_p[0])
    return BranchCot(gb.model, gb.params, pts, factory, jac, label=gb.label, lo_tol_rad=tol)


def _least(branches: Sequence[BranchCot], power: ClutchPower) -> tuple[float, BranchCot | None, dict[str, Any]]:
    best: tuple[float, BranchCot | None, dict[str, Any]] = (math.inf, None, {})
    for br in branches:
        r = br.minimise(power)
        if r["min_system_cot"] < best[0]:
            best = (r["min_system_cot"], br, r)
    return best


def break_even(
    er: Sequence[BranchCot],
    ve: Sequence[BranchCot],
    power: ClutchPower,
    field_name: str,
    *,
    rtol: float = BREAK_EVEN_RTOL,
    interval: bool = False,
) -> dict[str, Any]:
    """The value of `field_name` (hold_power_w or switch_energy_j) at which ER's least system CoT equals the VE
    branches' least, the other powers as in `power` (for switch_energy_j the holding power is set to 0: a
    bistable clutch). ER wins below it. None (with a reason) when ER loses even at 0 or no branch exists, and
    a tie (`tie` true, no value) when at zero power the two least CoTs differ by no more than they are known
    (`cot_resolution`). interval: also the roots with ER's least shifted by -/+ that resolution (`interval`)."""
    from scipy.optimize import brentq

    base = power.replace(**cast(ClutchPowerChanges, {field_name: 0.0}))  # field_name: one of its power fields
    if field_name == "switch_energy_j":
        base = base.replace(hold_power_w=0.0)
    ve_best, ve_br, _ = _least(ve, base)
    out: dict[str, Any] = {
        "quantity": field_name,
        "value": None,
        "ve_least_system_cot": ve_best,
        "ve_branch": ve_br.label if ve_br else "",
        "reason": "",
    }
    if not er or ve_br is None:
        out["reason"] = "no stable, valid " + ("ER" if not er else "VE") + " branch"
        return out

    def gap(x: float) -> float:
        return _least(er, base.replace(**cast(ClutchPowerChanges, {field_name: x})))[0] - ve_best

    g0 = gap(0.0)
    out["er_least_system_cot_at_zero"] = g0 + ve_best
    # how well the two least CoTs are known: each critical slope to its location tolerance (bracket, rtol), and
    # ER's least with power on to the minimiser's slope tolerance (d tan(phi)/d phi = sec^2 phi, about 1)
    er_br = min(er, key=lambda b: b.lo_rad)
    resolution = max(b.lo_tol_rad for b in er) + ve_br.lo_tol_rad + SLOPE_TOL_RAD / math.cos(er_br.lo_rad) ** 2
    out["cot_resolution"] = resolution
    out["cot_difference_at_zero"] = g0
    if abs(g0) <= resolution:
        out["tie"], out["resolved"] = True, False
        out["reason"] = (
            f"tie: at zero {field_name} ER and VE ({ve_br.label}) differ by {g0:+.2g} in least CoT, within the "
            f"location tolerance {resolution:.2g} (critical slopes' brackets and rtol shifts, the minimiser's "
            f"{SLOPE_TOL_RAD:g} rad): no break-even is resolved"
        )
        return out
    out["tie"] = False
    if not g0 < 0.0:
        out["reason"] = "ER's least system CoT is not below VE's even at zero " + field_name
        return out
    hi = 0.1 if field_name == "hold_power_w" else 0.01
    while gap(hi) < 0.0:
        hi *= 4.0
        if hi > 1e6:
            out["reason"] = f"ER stays below VE up to {field_name} = 1e6"
            return out
    x = brentq(gap, 0.0, hi, rtol=rtol, xtol=1e-12)
    out["value"] = float(x)
    out["er_least_system_cot"] = gap(x) + ve_best
    out["reason"] = f"root of ER least - VE least (brentq, rtol {rtol:g})"
    out["resolved"] = True
    if interval:  # the roots with ER's least shifted by -/+ the resolution
        lo = brentq(lambda v: gap(v) + resolution, 0.0, x, rtol=rtol, xtol=1e-12)
        top = hi
        while gap(top) - resolution < 0.0 and top < 1e6:
            top *= 4.0
        up = brentq(lambda v: gap(v) - resolution, x, top, rtol=rtol, xtol=1e-12) if top < 1e6 else math.inf
        out["interval"] = [float(lo), float(up)]
        out["reason"] += f"; {lo:.3g}-{up:.3g} with the least CoTs shifted by their resolution {resolution:.2g}"
    return out


def sweep_system_cot(
    rows: list[dict[str, Any]], points: list[dict[str, Any]], power: ClutchPower, *, backend: str, rtol: float
) -> list[dict[str, Any]]:
    """The sweep's rows with mechanical_cot, electrical_energy_per_step_j and system_cot of the gait at the start
    slope and the least system CoT along its stable, valid part (min_system_cot, min_system_cot_slope_deg), from
    the branch points the sweep recorded (`points`, rimless.sim.continuation.branches.GaitBranch.point_rows).
    With no electrical power these are closed forms (tan of the start slope; the critical slope) and nothing is
    computed."""
    from rimless.sim.model.params import WheelParams

    out = []
    for r in rows:
        r = dict(r)
        model = str(r.get("model", "")).lower()
        start = r.get("start_slope_rad", math.nan)
        crit = r.get("critical_slope_rad", math.nan)
        has_gait = model in ("er", "ve") and r.get("branch") and isinstance(start, float) and start == start
        if not has_gait:
            out.append(r)
            continue
        if power.energy_per_step_j(model, 1.0, 1.0) == 0.0:
            r.update(
                {"mechanical_cot": math.tan(start), "electrical_energy_per_step_j": 0.0, "system_cot": math.tan(start)}
            )
            if isinstance(crit, float) and crit == crit:
                r.update(
                    {
                        "min_system_cot": math.tan(crit),
                        "min_system_cot_slope_rad": crit,
                        "min_system_cot_slope_deg": math.degrees(crit),
                    }
                )
            out.append(r)
            continue
        params = WheelParams(
            hub_mass_kg=r["hub_mass_kg"],
            leg_mass_kg=r["leg_mass_kg"],
            stiffness_n_per_m=r["k"],
            damping_ns_per_m=r["c"],
            mass_model=r["mass_model"],
            slope_rad=start,
        )
        mine = [
            (pt["slope_rad"], np.array([pt["theta_plus_rad"], pt["theta_dot_plus_rad_s"]]))
            for pt in points
            if pt["model"] == r["model"]
            and pt["branch"] == r["branch"]
            and pt["k"] == r["k"]
            and pt["c"] == r["c"]
            and pt["mass_model"] == r["mass_model"]
            and pt.get("hub_mass_kg", r["hub_mass_kg"]) == r["hub_mass_kg"]
            and pt.get("leg_mass_kg", r["leg_mass_kg"]) == r["leg_mass_kg"]
        ]
        mine.append((start, np.array([r["theta_plus_rad"], r["theta_dot_plus_rad_s"]])))
        factory, jac = branch_factory(model, backend, rtol, r.get("contact_model") == "bilateral")
        at_start = BranchCot(model, params, mine, factory, jac)
        tr = at_start.transport(start)
        if tr is not None:
            r.update(
                {
                    k: v
                    for k, v in cot_of(tr, params, model, power).items()
                    if k in ("mechanical_cot", "electrical_energy_per_step_j", "system_cot")
                }
            )
        if isinstance(crit, float) and crit == crit:
            part = [(s, z) for s, z in mine if s > crit]
            near = min(mine, key=lambda q: abs(q[0] - crit))[1]
            br = BranchCot(model, params, part + [(crit, near)], factory, jac, guessed=frozenset({float(crit)}))
            m = br.minimise(power)
            r.update(
                {
                    k: m[k]
                    for k in (
                        "min_system_cot",
                        "min_system_cot_slope_rad",
                        "min_system_cot_slope_deg",
                        "min_system_cot_at_bound",
                    )
                }
            )
        out.append(r)
    return out
