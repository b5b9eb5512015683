"""The paper's simulation section regenerated: every figure as PNG (150 dpi) with its data as CSV, a table of
the paper's headline numbers beside ours, and an index page.

Figures (paper section "Numerical Simulation"):
1. typical gaits, ER and VE side by side: leg lengths, CoM height, stick diagrams with the phases;
2. slope-normal ground reaction forces of both, the leading leg's tensile transient marked;
3. energy transition ratio E+/E- over steps for several k, from a perturbed post-impact state;
4. max |eig| against slope for several k, both models, every stable branch (unit circle dashed);
5. CoT = tan(critical slope) against k: ER, every VE branch, the rigid wheel; contact-valid points filled;
6. the headline table (CSV and Markdown).
Figures 4-6 come from a sweep over k (rimless.sim.studies.sweep), so they run on Dask and use its cache.
"""

from __future__ import annotations

import contextlib
import html
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from rimless.sim.model.params import WheelParams
from rimless.sim.studies.paper_figures import (
    EIGEN_K,
    PERTURBATION,
    figure_cot,
    figure_eigenvalues,
    figure_energy_ratio,
    figure_forces,
    figure_typical_gaits,
    missing_eigen_curves,
    write_csv,
)
from rimless.sim.studies.paper_mfpt import metastability_paper

K_GRID = tuple(range(1500, 3501, 250))
ENERGY_K = (2000.0, 2500.0, 3000.0, 3500.0)
ENERGY_STEPS = 20


class _PaperNumbers(TypedDict):
    rigid_critical_deg: float
    ve_critical_deg: tuple[float, float]
    er_energy_ratio: float
    ve_energy_ratio: tuple[float, float]
    er_max_eig: tuple[float, float]
    max_cot_reduction_pct: float
    max_cot_reduction_k: float
    rigid_cot: float


PAPER: _PaperNumbers = {
    "rigid_critical_deg": 2.80,
    "ve_critical_deg": (1.27, 1.30),
    "er_energy_ratio": 0.85,
    "ve_energy_ratio": (0.79, 0.81),
    "er_max_eig": (0.75, 0.80),
    "max_cot_reduction_pct": 16.13,
    "max_cot_reduction_k": 2500.0,
    "rigid_cot": 0.048,
}


@dataclass
class PaperResult:
    out_dir: Path
    files: list[Path] = field(default_factory=list)
    table: list[dict[str, Any]] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)
    sweep: Any = None
    system_cot: list[dict[str, Any]] = field(default_factory=list)  # rimless.sim.studies.paper_system_cot rows
    notes: list[str] = field(default_factory=list)  # requested points a figure could not show, and why


def _fixed_point(params: WheelParams, model: str, backend: str, rtol: float) -> Any:
    """(map, fixed point): Newton from the default guess, the gaits search when that fails."""
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import default_guess
    from rimless.sim.studies.gaits import solve_or_search

    pmap = make_map(params, model, backend=backend, rtol=rtol)
    fp, _ = solve_or_search(pmap, default_guess(params, model), jacobian=getattr(pmap, "jacobian", None))
    return pmap, fp


def _typical(params: WheelParams, backend: str, rtol: float, steps: int = 2) -> dict[str, Any]:
    """Figures 1 and 2's walks, both models from their period-1 gait; RunFailure when a model has none."""
    from rimless.errors import RunFailure
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.gait import simulate_steps

    out = {}
    for model in ("er", "ve"):
        try:
            _, fp = _fixed_point(params, model, backend, rtol)
        except StepFailure as err:
            raise RunFailure(
                f"figures 1-2: no period-1 gait of the {model.upper()} wheel at "
                f"{params.slope_deg:.4f} deg, k = {params.k:g} N/m, c = {params.c:g} N s/m "
                f"(Newton and the gaits search): {err}"
            ) from None
        out[model] = simulate_steps(
            params, model, fp.z, steps, make_integrator(backend, rtol), record_dt=1e-3, forces=True
        )
    return out


def energy_ratio_series(
    params: WheelParams, backend: str, rtol: float, ks: tuple[float, ...] = ENERGY_K, steps: int = ENERGY_STEPS
) -> list[dict[str, Any]]:
    """E+/E- of each step from a perturbed start (theta'+ x PERTURBATION of the fixed point), per k and model;
    each row names the gait it starts from (`branch_label`, `gait_period_s`): for VE, Newton from the default
    guess (or the gaits search) may land on the fast gait at one k and the medium one at another."""
    from rimless.sim.model.failures import StepFailure

    rows = []
    for model in ("er", "ve"):
        for k in ks:
            p = params.replace(stiffness_n_per_m=float(k))
            try:
                pmap, fp = _fixed_point(p, model, backend, rtol)
            except StepFailure as err:  # kept as a row: the figure and the output name the missing curve
                rows.append(
                    {
                        "model": model.upper(),
                        "k": k,
                        "step": 0,
                        "energy_ratio": math.nan,
                        "failure": f"no period-1 gait: {err.reason.value}",
                    }
                )
                continue
            from rimless.sim.continuation.branches import branch_label

            period = fp.recorded_step.period_s
            label = branch_label(model, period, fp.stable, float(k))  # which VE gait the curve starts from
            z = np.array([fp.z[0], fp.z[1] * PERTURBATION])
            n0 = len(rows)
            for i in range(steps):
                try:
                    st = pmap.step(z)
                except StepFailure as err:
                    rows.append(
                        {
                            "model": model.upper(),
                            "k": k,
                            "step": i + 1,
                            "energy_ratio": math.nan,
                            "failure": err.reason.value,
                        }
                    )
                    break
                rows.append(
                    {
                        "model": model.upper(),
                        "k": k,
                        "step": i + 1,
                        "energy_ratio": st.impact.energy_ratio,
                        "failure": "",
                    }
                )
                z = np.array([st.y_plus[2], st.y_plus[7]])
            for r in rows[n0:]:
                r.update(
                    {"branch_label": label, "gait_period_s": period, "gait_max_abs_eigenvalue": fp.max_abs_eigenvalue}
                )
    return rows


def cot_rows(rows: list[dict[str, Any]], params: WheelParams) -> list[dict[str, Any]]:
    """CoT per (k, branch) with validity, plus the rigid wheel (closed form, paper convention)."""
    from rimless.sim.model.rigid import RigidWheel

    out = []
    for r in rows:
        c = r.get("critical_slope_rad", math.nan)
        if not (isinstance(c, float) and c == c):
            continue
        out.append(
            {
                "model": r["model"],
                "k": r["k"],
                "branch": r["branch"],
                "branch_label": r["branch_label"],
                "critical_slope_deg": r["critical_slope_deg"],
                "cot": r["cot"],
                "reason": r["reason"],
                "contact_valid": bool(r.get("contact_valid_at_start")) and r.get("end_contact_valid") is not False,
                "contact_valid_at_start": bool(r.get("contact_valid_at_start")),
                "min_stance_force_single_support_N": r.get("min_stance_force_single_support_N", math.nan),
            }
        )
    for r in rows:  # a gait invalid at the start slope whose valid part (lower down) ends at a stable end
        c = r.get("valid_end_slope_rad", math.nan)
        if not (isinstance(c, float) and c == c) or r.get("valid_end_reason") not in ("fold", "stall"):
            continue
        out.append(
            {
                "model": r["model"],
                "k": r["k"],
                "branch": r["branch"],
                "branch_label": r["branch_label"],
                "critical_slope_deg": math.degrees(c),
                "cot": math.tan(c),
                "reason": r["valid_end_reason"],
                "contact_valid": True,
                "contact_valid_at_start": False,
                "valid_part_only": True,
                "valid_from_slope_deg": math.degrees(r["valid_from_slope_rad"]),
                "min_stance_force_single_support_N": r.get("min_stance_force_single_support_N", math.nan),
            }
        )
    phi_r = RigidWheel.from_params(params, "paper").critical_slope_rad()
    for k in sorted({r["k"] for r in rows}):
        out.append(
            {
                "model": "rigid",
                "k": k,
                "branch": "rigid",
                "branch_label": "rigid",
                "critical_slope_deg": math.degrees(phi_r),
                "cot": math.tan(phi_r),
                "reason": "coleman-closed-form",
                "contact_valid": True,
                "contact_valid_at_start": True,
                "min_stance_force_single_support_N": math.nan,
            }
        )
    return out


def curve_starts(rows: list[dict[str, Any]], params: WheelParams) -> list[dict[str, Any]]:
    """One start per stable branch label (ER; VE fast, medium, ...): its row at the grid k nearest Table 1's."""
    done: set[tuple[str, str]] = set()
    out = []
    for r in sorted(rows, key=lambda r: abs(r["k"] - params.k)):
        key = (r["model"], r.get("branch_label", ""))
        crit = r.get("critical_slope_rad")
        if key in done or not (isinstance(crit, float) and crit == crit) or r["reason"] not in ("stall", "fold"):
            continue
        done.add(key)
        out.append(r)
    return out


def boundary_curve(
    row: dict[str, Any], params: dict[str, Any], backend: str, rtol: float, k_range: tuple[float, float]
) -> list[dict[str, Any]]:
    """The critical slope of one branch as a curve over k, traced by two-parameter continuation
    (rimless.sim.continuation.boundary): a VE branch's fold curve, the ER stall curve (each point the located stall).
    Plain data in and out (runs as a Dask task)."""
    from rimless.sim.continuation.boundary import BoundaryContinuation, start_on_boundary
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import make_map

    model = row["model"].lower()
    test = "stall" if row["reason"] == "stall" else "fold"
    base = WheelParams(**params).replace(stiffness_n_per_m=float(row["k"]), slope_rad=row["start_slope_rad"])

    def factory(q: WheelParams) -> Any:
        return make_map(q, model, backend=backend, rtol=rtol)

    try:
        z, s0 = start_on_boundary(
            factory, base, model, np.array([row["theta_plus_rad"], row["theta_dot_plus_rad_s"]]), test
        )
        bc = BoundaryContinuation(factory, base.replace(slope_rad=s0), model, "k", test, max_points=60)
        curve = bc.trace(z, s0, mu_min=k_range[0], mu_max=k_range[1])
    except StepFailure:
        return []
    name = "ER stall" if model == "er" else f"VE {row['branch_label']} fold"
    return [
        {
            "curve": name,
            "model": row["model"],
            "branch_label": row["branch_label"],
            "test": test,
            "k": pt.mu,
            "slope_rad": pt.slope_rad,
            "slope_deg": pt.slope_deg,
            "cot": math.tan(pt.slope_rad),
            "step_period_s": pt.period_s,
            "max_abs_eigenvalue": float(np.max(np.abs(pt.eigenvalues))),
            "curve_end": curve.end_reason,
            "curve_seconds": curve.seconds,
            "curve_map_evaluations": curve.map_evaluations,
        }
        for pt in curve.points
        if k_range[0] - 1e-9 <= pt.mu <= k_range[1] + 1e-9
    ]


def validity_range(
    row: dict[str, Any], params: dict[str, Any], backend: str, rtol: float, k_range: tuple[float, float]
) -> dict[str, Any]:
    """How far in k the gait of `row` stays stable and contact-valid at its start slope: pseudo-arclength
    continuation in k both ways with the contact facts at every point, to the first special point (a
    stance force or impulse through 0, a fold, ...) or the end of k_range. The map holds the stance foot
    (bilateral contact, where the backend has it), so a stance force through 0 is a located sign change of
    its test function rather than the end of the branch. Plain data (runs as a Dask task)."""
    from rimless.sim.continuation.arclength import ArclengthContinuation
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.backend import make_map
    from rimless.sim.step.poincare import bilateral_map

    model = row["model"].lower()
    base = WheelParams(**params).replace(stiffness_n_per_m=float(row["k"]), slope_rad=row["start_slope_rad"])
    z0 = np.array([row["theta_plus_rad"], row["theta_dot_plus_rad_s"]])
    out: dict[str, Any] = {
        "model": row["model"],
        "branch_label": row["branch_label"],
        "from_k": row["k"],
        "slope_rad": row["start_slope_rad"],
    }

    def factory(q: WheelParams) -> Any:  # the stance foot held, so the stance force's sign change is bracketed
        m = make_map(q, model, backend=backend, rtol=rtol)
        return bilateral_map(m) or m

    for side, direction, limit in (("low", -1.0, k_range[0]), ("high", 1.0, k_range[1])):
        # facts (the recorded step) every 5th point; the held map's stance force and impulses at every point
        cont = ArclengthContinuation(
            factory,
            base,
            model,
            "k",
            facts_every=5 if bilateral_map(make_map(base, model, backend=backend, rtol=rtol)) is not None else 1,
            max_points=60,
        )
        try:
            br = cont.trace(z0, direction=direction, p_min=k_range[0], p_max=k_range[1], stop_at_first_loss=True)
        except StepFailure as err:
            out[f"k_{side}"], out[f"k_{side}_reason"], out[f"k_{side}_detail"] = math.nan, "solver", str(err)
            continue
        sp = br.first_loss()
        if sp is None:
            out[f"k_{side}"], out[f"k_{side}_reason"], out[f"k_{side}_detail"] = limit, "grid-end", br.end_detail
        else:
            out[f"k_{side}"], out[f"k_{side}_reason"], out[f"k_{side}_detail"] = sp.p, sp.kind, sp.detail
    return out


def _finite(x: Any) -> bool:
    return isinstance(x, float) and math.isfinite(x)


def _tol(r: dict[str, Any]) -> float:
    """How well the row's critical slope is located, rad (0 when the row does not say)."""
    for key in ("critical_slope_tol_rad", "end_location_tol_rad"):
        v = r.get(key)
        if isinstance(v, float) and math.isfinite(v):
            return v
    return 0.0


def _ve_name(r: dict[str, Any]) -> str:
    """VE <label>, with the slope it was found at when that is not the start slope."""
    name = f"VE {r.get('branch_label', '')}"
    if r.get("found_by", "start-slope") != "start-slope":
        name += f" (found at {math.degrees(r['start_slope_rad']):.3f} deg)"
    return name


def _fmt_range(v: Any) -> str:
    return f"{v[0]}-{v[1]}" if isinstance(v, tuple) else f"{v}"


def headline_table(
    rows: list[dict[str, Any]],
    er_series: list[dict[str, Any]],
    params: WheelParams,
    ranges: list[dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """Every headline number of the paper beside ours, with the difference explained."""
    from rimless.sim.continuation.branches import search_slopes
    from rimless.sim.model.rigid import RigidWheel

    def pick(model: str, k: float, label: str | None = None) -> list[dict[str, Any]]:
        return [
            r
            for r in rows
            if r["model"] == model and abs(r["k"] - k) < 1e-9 and (label is None or r.get("branch_label") == label)
        ]

    table = []
    phi_r = RigidWheel.from_params(params, "paper").critical_slope_rad()
    table.append(
        {
            "quantity": "rigid wheel critical slope (deg)",
            "paper": "2.80",
            "ours": f"{math.degrees(phi_r):.3f}",
            "note": "Coleman's closed form with M = m_H, I_c (model.md section 7)",
        }
    )
    table.append(
        {"quantity": "rigid wheel CoT", "paper": "0.048", "ours": f"{math.tan(phi_r):.4f}", "note": "tan(2.799 deg)"}
    )
    ks_all = sorted({r["k"] for r in rows})
    k0 = min(ks_all, key=lambda k: abs(k - params.k)) if ks_all else params.k
    ve0 = [
        r
        for r in pick("VE", k0)
        if r.get("critical_slope_rad") == r.get("critical_slope_rad") and isinstance(r.get("critical_slope_rad"), float)
    ]
    ve_txt = (
        "; ".join(
            f"{r['branch_label']} {r['critical_slope_deg']:.3f} ({'valid' if r['contact_valid_at_start'] else 'INVALID'}, "
            f"{r['reason']})"
            for r in ve0
        )
        or "no stable VE branch"
    )
    table.append(
        {
            "quantity": f"VE critical slope at k = {k0:g} (deg)",
            "paper": "1.27-1.30 (k = 2700)",
            "ours": ve_txt,
            "note": "one value per VE branch (model.md section 9); the paper follows one branch",
        }
    )
    er0 = [r for r in pick("ER", k0) if r.get("branch")]
    er_eigs = [
        float(x["max_abs_eigenvalue"])
        for x in rows
        if x["model"] == "ER"
        and x.get("branch")
        and x.get("max_abs_eigenvalue", math.nan) == x.get("max_abs_eigenvalue")
    ]
    if er0:
        r = er0[0]
        table.append(
            {
                "quantity": f"ER critical slope at k = {k0:g} (deg)",
                "paper": "-",
                "ours": f"{r['critical_slope_deg']:.3f} ({r['reason']})",
                "note": "the ER branch ends in a stall (the wheel no longer clears mid-stance)",
            }
        )
        table.append(
            {
                "quantity": "ER energy ratio E+/E-",
                "paper": "about 0.85",
                "ours": f"{r.get('energy_ratio', math.nan):.3f}",
                "note": f"at the start slope, k = {k0:g}",
            }
        )
    else:
        table.append(
            {
                "quantity": f"ER critical slope at k = {k0:g} (deg)",
                "paper": "-",
                "ours": "no period-1 gait",
                "note": "; ".join(str(r.get("detail", "")) for r in pick("ER", k0)) or "no ER row at this k",
            }
        )
    if er_eigs:
        table.append(
            {
                "quantity": "ER max |eig|",
                "paper": "0.75-0.8",
                "ours": f"{min(er_eigs):.3f}-{max(er_eigs):.3f}",
                "note": "largest along each ER branch, over the k grid",
            }
        )
    ve_er = [
        r
        for r in pick("VE", k0)
        if r.get("branch") and r.get("energy_ratio", math.nan) == r.get("energy_ratio") and r.get("stable_at_start")
    ]
    table.append(
        {
            "quantity": "VE energy ratio E+/E-",
            "paper": "0.79-0.81",
            "ours": "; ".join(f"{r['branch_label']} {r['energy_ratio']:.3f}" for r in ve_er) or "no stable VE gait",
            "note": f"per VE gait at the start slope, k = {k0:g}",
        }
    )
    for k in ks_all:  # a k without any gait is a result, said in the table
        for model in ("ER", "VE"):
            if pick(model, k) and not [r for r in pick(model, k) if r.get("branch")]:
                table.append(
                    {
                        "quantity": f"{model} gaits at k = {k:g} N/m",
                        "paper": "-",
                        "ours": "no period-1 gait",
                        "note": "; ".join(dict.fromkeys(str(r.get("detail", "")) for r in pick(model, k))),
                    }
                )
    # ER against every stable, valid VE gait per k (gaits searched at the start slope and below)
    below, vs_least = [], []
    for k in ks_all:
        er_c = [r["critical_slope_rad"] for r in pick("ER", k) if _finite(r.get("critical_slope_rad"))]
        ve_rows = [r for r in pick("VE", k) if _finite(r.get("critical_slope_rad")) and r.get("contact_valid_at_start")]
        if not er_c or not ve_rows:
            continue
        er_min = min(er_c)
        least = min(ve_rows, key=lambda r: r["critical_slope_rad"])
        tol = _tol(least) + max(_tol(r) for r in pick("ER", k) if _finite(r.get("critical_slope_rad")))
        diff = er_min - least["critical_slope_rad"]
        verdict = (
            "tie"
            if abs(diff) <= tol
            else f"{100.0 * (math.tan(er_min) / math.tan(least['critical_slope_rad']) - 1):+.1f}%"
        )
        vs_least.append(f"k = {k:g}: {verdict} vs {_ve_name(least)}")
        for r in ve_rows:
            if r["critical_slope_rad"] < er_min - tol:
                below.append(
                    f"k = {k:g}: {_ve_name(r)} walks down to {r['critical_slope_deg']:.4f} deg "
                    f"({r['reason']}; max |eig| {r.get('max_abs_eigenvalue', math.nan):.3f} along it), "
                    f"below ER's {math.degrees(er_min):.4f} deg"
                )
    table.append(
        {
            "quantity": "ER CoT against the least stable, valid VE gait, per k",
            "paper": "ER lower at every k (16.13% at best)",
            "ours": "; ".join(vs_least) or "-",
            "note": "+: ER dearer; tie: the critical slopes differ by no more than their location tolerance "
            "(bracket and rtol shift); VE gaits searched at the start slope and at "
            + ", ".join(f"{math.degrees(x):.3f}" for x in (params.slope_rad, *search_slopes(params.slope_rad)))
            + " deg, each followed down to the end of its stable, valid part",
        }
    )
    table.append(
        {
            "quantity": "VE gaits that walk below ER's critical slope",
            "paper": "none",
            "ours": "; ".join(below) or "none",
            "note": "stable and contact-valid (unilateral contact) down to their critical slope; ER cannot walk "
            "there, so at these k recycling does not lower the least CoT",
        }
    )
    # CoT reduction per k and VE branch
    best = None
    for k in sorted({r["k"] for r in rows}):
        er = [r for r in pick("ER", k) if r["cot"] == r["cot"]]
        if not er:
            continue
        for ve in pick("VE", k):
            if not (ve["cot"] == ve["cot"]):
                continue
            red = 100.0 * (1.0 - er[0]["cot"] / ve["cot"])
            if best is None or red > best[0]:
                best = (red, k, ve)
    kp = PAPER["max_cot_reduction_k"]
    at_kp = []
    for ve in pick("VE", kp):
        er = pick("ER", kp)
        if er and ve["cot"] == ve["cot"] and er[0]["cot"] == er[0]["cot"]:
            red = 100.0 * (1.0 - er[0]["cot"] / ve["cot"])
            at_kp.append(f"vs {_ve_name(ve)} {red:+.1f}% ({'valid' if ve['contact_valid_at_start'] else 'INVALID'})")
    table.append(
        {
            "quantity": f"ER CoT reduction vs VE at k = {kp:g}",
            "paper": "16.13%",
            "ours": "; ".join(at_kp) or "-",
            "note": "depends on which VE branch is followed; valid = unilateral contact at the start slope",
        }
    )
    reds = []
    for ve in pick("VE", kp):
        er = pick("ER", kp)
        if er and ve["cot"] == ve["cot"] and er[0]["cot"] == er[0]["cot"]:
            reds.append((100.0 * (1.0 - er[0]["cot"] / ve["cot"]), ve))
    if reds:
        red, ve = min(reds, key=lambda rv: abs(rv[0] - PAPER["max_cot_reduction_pct"]))
        rng = next((v for v in ranges or [] if v["model"] == "VE" and v["branch_label"] == ve["branch_label"]), None)
        valid_txt = (
            "contact-valid at the start slope"
            if ve["contact_valid_at_start"]
            else f"NOT contact-valid ({ve.get('contact_reason', '')})"
        )
        if rng is not None:
            valid_txt += (
                f"; stable and contact-valid at {math.degrees(rng['slope_rad']):.3f} deg for k = "
                f"{rng['k_low']:.0f} ({rng['k_low_reason']}) to {rng['k_high']:.0f} ({rng['k_high_reason']})"
            )
        table.append(
            {
                "quantity": f"VE branch that reproduces the paper's 16.13 % at k = {kp:g}",
                "paper": "16.13%",
                "ours": f"{_ve_name(ve)}: {red:.2f}% ({valid_txt})",
                "note": "the VE branch whose CoT reduction is nearest the paper's; the others: "
                + ("; ".join(f"{_ve_name(o)} {r2:+.2f}%" for r2, o in reds if o is not ve) or "none"),
            }
        )
    if best is not None:
        red, k, ve = best
        table.append(
            {
                "quantity": "maximum ER CoT reduction over the k grid",
                "paper": "16.13% at k = 2500",
                "ours": f"{red:.2f}% at k = {k:g} vs {_ve_name(ve)} "
                f"({'valid' if ve['contact_valid_at_start'] else 'INVALID'})",
                "note": "the VE fast branch's stance force in single support approaches 0 as k grows",
            }
        )
    return table


def _write_table(table: list[dict[str, Any]], out: Path) -> list[Path]:
    import pandas as pd

    csv = write_csv(pd.DataFrame(table), out / "table6_headline.csv")
    md = ["| quantity | paper | ours | note |", "|---|---|---|---|"]
    cell = lambda v: str(v).replace("|", "\\|")  # noqa: E731
    md += [f"| {cell(r['quantity'])} | {cell(r['paper'])} | {cell(r['ours'])} | {cell(r['note'])} |" for r in table]
    path = out / "table6_headline.md"
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text("\n".join(md) + "\n")
    tmp.replace(path)
    return [csv, path]


CAPTIONS = {
    "fig1_typical_gaits": "Typical gaits of the viscoelastic (left) and energy-recycling (right) wheels: leg lengths, "
    "CoM height and a stick diagram of one step, phases coloured.",
    "fig2_ground_reaction_forces": "Ground reaction forces normal to the slope; red: the leading foot's tensile transient at the "
    "start of double support (a rigid-contact artefact).",
    "fig3_energy_ratio": "Energy transition ratio E+/E- over steps from a perturbed start, several k, each curve "
    "named by the gait it starts from (VE: fast or medium, by its step period; a k without a gait is named on "
    "the figure).",
    "fig4_eigenvalue_map": "Max |eigenvalue| against slope along every branch stable at the start slope, several k, "
    "down to the end of its stable, valid part; dashed with open markers: the gait violates "
    "unilateral contact (found with the stance foot held); black dashed: unit circle.",
    "fig5_cot": "CoT = tan(critical slope) against k for ER, every VE branch and the rigid wheel; open circles violate "
    "unilateral contact; open diamonds: a gait invalid at the start slope, the end of its valid part "
    "lower down; bars along the bottom: each branch's contact-valid range in k at the start slope.",
    "fig_system_cot_hold_power": "Least system cost of transport (M g s_z + E_el)/(M g s_x) along each stable, valid "
    "branch at k = 2500 N/m against the ER clutch's holding power (the other electrical "
    "powers as given); dashed: the break-even holding power against the least VE branch; "
    "hollow: the least lies at the start slope (the true least may lie higher). Per k: "
    "table7_system_cot.csv (break-even powers) and table7_system_cot_branches.csv.",
}


def _index(out: Path, table: list[dict[str, Any]], params: WheelParams, timings: dict[str, float]) -> Path:
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>rimless paper figures</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}img{max-width:100%}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px}</style></head><body>",
        f"<h1>Simulation figures</h1><p>mass model {html.escape(params.mass_model)}, Table 1 parameters "
        f"(k = {params.k:g} N/m, c = {params.c:g} N s/m) unless stated.</p>",
    ]
    for stem, cap in CAPTIONS.items():
        parts.append(
            f"<h2>{stem}</h2><p>{html.escape(cap)}</p><img src='{stem}.png' alt='{stem}'>"
            f"<p><a href='{stem}.csv'>{stem}.csv</a></p>"
        )
    parts.append("<h2>table6_headline</h2><table><tr><th>quantity</th><th>paper</th><th>ours</th><th>note</th></tr>")
    for r in table:
        parts.append(
            "<tr>"
            + "".join(f"<td>{html.escape(str(r[c]))}</td>" for c in ("quantity", "paper", "ours", "note"))
            + "</tr>"
        )
    parts.append(
        "</table><p><a href='table6_headline.csv'>table6_headline.csv</a> · "
        "<a href='table6_valid_k_ranges.csv'>table6_valid_k_ranges.csv</a> · <a href='sweep.csv'>sweep.csv</a> (every branch) · <a href='sweep-points.csv'>sweep-points.csv</a></p>"
    )
    parts.append(
        "<p>"
        + ", ".join(f"{k} {v:.1f}" + ("" if k.startswith("load") else " s") for k, v in timings.items())
        + f" on {os.cpu_count()} cores</p></body></html>"
    )
    path = out / "index.html"
    tmp = path.with_name(".index.html.tmp")
    tmp.write_text("\n".join(parts))
    tmp.replace(path)
    return path


class _Background:
    """fn() in a daemon thread; result() waits for it and returns its value or raises its exception. Unlike a
    ThreadPoolExecutor's thread, an interpreter leaving on Ctrl-C does not wait for it."""

    def __init__(self, fn: Callable[[], Any]) -> None:
        import threading

        self._value: Any = None
        self._error: BaseException | None = None

        def run() -> None:
            try:
                self._value = fn()
            except BaseException as err:  # noqa: BLE001 - handed to result()
                self._error = err

        self._thread = threading.Thread(target=run, name="rimless-paper-sweep", daemon=True)
        self._thread.start()

    def result(self) -> Any:
        while self._thread.is_alive():  # short waits keep the main thread responsive to Ctrl-C
            self._thread.join(0.1)
        if self._error is not None:
            raise self._error
        return self._value


def run_paper(
    out: Path,
    params: WheelParams = WheelParams(),  # noqa: B008
    *,
    ks: tuple[float, ...] = tuple(map(float, K_GRID)),  # not a generator: mypy 2.4 misreads its name there
    backend: str = "auto",
    rtol: float = 1e-10,
    scheduler: str = "local",
    workers: int | None = None,
    cache_dir: Path | None = None,
    energy_ks: tuple[float, ...] = ENERGY_K,
    eigen_ks: tuple[float, ...] = EIGEN_K,
    progress: Callable[[str], None] | None = None,
    power: Any = None,
) -> PaperResult:
    """Write every figure, CSV, the headline table and index.html into `out` (see module docstring)."""
    import os

    from rimless.sim.continuation.branches import search_slopes
    from rimless.sim.step.backend import resolve
    from rimless.sim.studies.sweep import SweepOptions, dask_client, grid_points, run_sweep, write_table

    say = progress or (lambda msg: None)
    out.mkdir(parents=True, exist_ok=True)
    res = PaperResult(out)
    res.timings_s["load_average_before"] = os.getloadavg()[0]
    backend = resolve(backend)
    t0 = time.perf_counter()
    stack = contextlib.ExitStack()
    client = stack.enter_context(dask_client(scheduler, workers)) if scheduler != "sync" else None
    with stack:
        say("sweep over k: every branch of both wheels")
        # the grid and the wheel's own k (the system CoT's headline); gaits searched at the start slope and below
        sweep_ks = sorted(set(ks) | {float(params.k)})
        pts = grid_points(params, ("er", "ve"), {"k": sweep_ks}, (params.mass_model,))
        options = SweepOptions(
            backend=backend,
            rtol=rtol,
            start_slope_rad=params.slope_rad,
            search_slopes_rad=search_slopes(params.slope_rad),
            locate_tolerance=True,
        )

        def sweep() -> Any:
            return run_sweep(
                pts,
                options,
                scheduler=scheduler,
                workers=workers,
                cache_dir=cache_dir,
                client=client,
                progress=lambda i, n: say(f"sweep over k: {i}/{n} grid points"),
            )

        # on a cluster the sweep's tasks run on the workers while this process draws figures 1-3 (the thread only
        # waits for results); in-process (sync) everything runs in turn
        pool = _Background(sweep) if client is not None else None  # a daemon: an interrupt never waits for it
        t1 = time.perf_counter()
        say("typical gaits and forces")
        trajs = _typical(params, backend, rtol)
        res.files += figure_typical_gaits(trajs, out)
        res.files += figure_forces(trajs, out)
        res.timings_s["gaits"] = time.perf_counter() - t1
        t2 = time.perf_counter()
        say("energy transition ratios")
        energy = energy_ratio_series(params, backend, rtol, energy_ks)
        res.notes += [
            f"figure 3: {r['model']} at k = {r['k']:g} N/m not shown ({r['failure']})" for r in energy if r["step"] == 0
        ]
        res.files += figure_energy_ratio(energy, out)
        res.timings_s["energy"] = time.perf_counter() - t2
        if pool is not None:
            sw = pool.result()
            res.timings_s["sweep"] = time.perf_counter() - t0
        else:  # in-process: after figures 1-3, so that a wheel without a gait fails in seconds
            t_sweep = time.perf_counter()
            sw = sweep()
            res.timings_s["sweep"] = time.perf_counter() - t_sweep
        res.sweep = sw
        meta = {"params": params.to_dict(), "ks": list(ks), "backend": backend, "rtol": rtol}
        res.files += write_table(sw.rows, out / "sweep", meta)
        if sw.points:
            res.files += write_table(sw.points, out / "sweep-points", meta)
        on_grid = [r for r in sw.rows if any(abs(r["k"] - k) < 1e-9 for k in ks)]  # figures 4-5, table 6
        grid_points_rows = [p for p in sw.points if any(abs(p["k"] - k) < 1e-9 for k in ks)]
        t1 = time.perf_counter()
        starts = curve_starts(on_grid, params)
        k_range = (min(ks), max(ks))
        futures = (
            [client.submit(boundary_curve, r, params.to_dict(), backend, rtol, k_range, pure=False) for r in starts]
            if client is not None
            else []
        )
        vfutures = (
            [client.submit(validity_range, r, params.to_dict(), backend, rtol, k_range, pure=False) for r in starts]
            if client is not None
            else []
        )
        say("boundary curves over k (two-parameter continuation)")
        if client is not None:
            curves = [row for f in futures for row in f.result()]
            ranges = [f.result() for f in vfutures]
        else:
            curves = [row for r in starts for row in boundary_curve(r, params.to_dict(), backend, rtol, k_range)]
            ranges = [validity_range(r, params.to_dict(), backend, rtol, k_range) for r in starts]
        res.timings_s["boundary_curves_wait"] = time.perf_counter() - t1
    t3 = time.perf_counter()
    say("eigenvalue map, cost of transport and the headline table")
    res.files += figure_eigenvalues(grid_points_rows, on_grid, out, eigen_ks)
    res.notes += [
        f"figure 4: {m} at k = {k:g} N/m not shown (no branch stable at the start slope)"
        for m, k in missing_eigen_curves(on_grid, eigen_ks)
    ]
    res.files += figure_cot(cot_rows(on_grid, params), out, curves, ranges)
    res.table = headline_table(on_grid, [], params, ranges)
    for v in ranges:
        name = "ER" if v["model"] == "ER" else f"VE {v['branch_label']}"
        res.table.append(
            {
                "quantity": f"{name} gait stable and contact-valid at {math.degrees(v['slope_rad']):.3f} deg "
                f"for k (N/m)",
                "paper": "-",
                "ours": f"{v['k_low']:.1f} ({v['k_low_reason']}) to {v['k_high']:.1f} ({v['k_high_reason']})",
                "note": "continuation in k from the gait at k = "
                f"{v['from_k']:g}; stance-force = its single-support stance force falls through 0",
            }
        )
    if ranges:
        import pandas as pd

        res.files.append(write_csv(pd.DataFrame(ranges), out / "table6_valid_k_ranges.csv"))
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.studies.paper_system_cot import system_cot_paper

    t4 = time.perf_counter()
    syscot = system_cot_paper(
        out,
        params,
        ks,
        power or ClutchPower(),
        backend=backend,
        rtol=rtol,
        progress=say,
        rows=sw.rows,
        points=sw.points,
    )
    res.files += syscot["files"]
    res.table += syscot["headline"]
    res.system_cot = syscot["rows"]
    res.timings_s["system_cot"] = time.perf_counter() - t4
    res.files += metastability_paper(out, params, ks, backend=backend, rtol=rtol, progress=say)["files"]
    res.files += _write_table(res.table, out)
    res.timings_s["figures"] = time.perf_counter() - t3
    res.timings_s["total"] = time.perf_counter() - t0
    res.timings_s["load_average_after"] = os.getloadavg()[0]
    res.files.append(_index(out, res.table, params, res.timings_s))
    return res


def paper_study(
    out: Path,
    params: WheelParams,
    *,
    ks: tuple[float, ...],
    backend: str = "auto",
    rtol: float = 1e-10,
    scheduler: str = "local",
    workers: int | None = None,
    cache_dir: Path | None = None,
    progress: Callable[[str], None] | None = None,
    power: Any = None,
) -> dict[str, Any]:
    """`rimless paper`: check the k grid (N/m) and the folder `out`, choose the k of figures 3 and 4 among
    `ks`, run_paper; returns the command's JSON object. An interrupted run removes the folder it created."""
    from rimless.errors import ParameterError, interrupted_by_user
    from rimless.output import writable_dir
    from rimless.sim.studies.sweep import worker_failure

    for k in ks:
        try:
            params.replace(stiffness_n_per_m=k)
        except ParameterError as err:
            raise ParameterError(f"--k {k:g}: {err}") from None
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {out}: exists and is not a folder")
    out_is_new = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ParameterError(f"--out {out}: cannot create the folder ({err.strerror})") from None
    if cache_dir is not None:
        writable_dir(cache_dir, option="--cache-dir")
    eigen_ks = tuple(k for k in EIGEN_K if k in ks) or ks[: min(3, len(ks))]
    energy_ks = tuple(k for k in ENERGY_K if k in ks) or ks[: min(4, len(ks))]
    try:
        res = run_paper(
            out,
            params,
            ks=ks,
            backend=backend,
            rtol=rtol,
            scheduler=scheduler,
            workers=workers,
            cache_dir=cache_dir,
            energy_ks=energy_ks,
            eigen_ks=eigen_ks,
            progress=progress,
            power=power,
        )
    except BaseException as err:
        if out_is_new:  # an interrupted or failed run leaves no half-filled folder behind
            import shutil

            shutil.rmtree(out, ignore_errors=True)
        if isinstance(err, ConnectionError):
            raise ParameterError(f"--scheduler: {err}") from None
        if isinstance(err, Exception) and not interrupted_by_user(err):
            worker_failure(err, scheduler)
        raise
    return {
        "out": str(out),
        "files": [str(f) for f in res.files],
        "table": res.table,
        "notes": res.notes,
        "timings_s": res.timings_s,
        "sweep": {"computed": res.sweep.computed, "cached": res.sweep.cached, "workers": res.sweep.workers},
        "system_cot": res.system_cot,
    }
