"""Plain-dict summaries of simulator results (fixed point, critical slope, rigid wheel): what the commands print
and what --json emits. Keys are a contract: add, never rename."""

from __future__ import annotations

import math
from typing import Any

from rimless.sim.continuation.algorithm1 import CriticalSlope
from rimless.sim.model.params import WheelParams
from rimless.sim.model.rigid import RigidWheel
from rimless.sim.step.poincare import FixedPoint


def params_summary(p: WheelParams) -> dict[str, Any]:
    return {
        "slope_rad": p.slope_rad,
        "slope_deg": p.slope_deg,
        "k": p.stiffness_n_per_m,
        "c": p.damping_ns_per_m,
        "mass_model": p.mass_model,
        "guide_friction_n": p.guide_friction_n,
    }


def fixed_point_summary(fp: FixedPoint, p: WheelParams, model: str, *, guess: Any = None) -> dict[str, Any]:
    """The `rimless sim fixed-point` JSON object (keys are a contract: add, never rename)."""
    step = fp.recorded_step
    imp = step.impact
    d = step.diagnostics or {}
    mu_b, mu_a = imp.friction_required
    out: dict[str, Any] = {
        "model": model,
        **params_summary(p),
        "theta_plus_rad": float(fp.z[0]),
        "theta_dot_plus_rad_s": float(fp.z[1]),
        "step_period_s": step.period_s,
        "eigenvalues": [[float(ev.real), float(ev.imag)] for ev in fp.eigenvalues],
        "max_abs_eigenvalue": fp.max_abs_eigenvalue,
        "stable": fp.stable,
        "energy_ratio": imp.energy_ratio,
        "energy_ratio_relabelled": imp.energy_ratio_relabelled,
        "relabel_loss_J": imp.relabel_loss,
        "relabel_energy_J": -imp.relabel_loss,
        "min_normal_force_N": {
            "dlsp_leading_b": d.get("min_normal_force_b_dlsp_N"),
            "dlsp_trailing_a": d.get("min_normal_force_a_dlsp_N"),
            "slsp_free": d.get("min_normal_force_b_slsp_free_N"),
            "slsp_clutched": d.get("min_normal_force_b_slsp_clutched_N"),
        },
        "leading_foot_tension_s": d.get("leading_foot_tension_s"),
        "trailing_foot_min_height_m": d.get("trailing_foot_min_height_m"),
        "impact_impulse_N_s": {
            "b_x": imp.impulse[0],
            "b_y": imp.impulse[1],
            "a_x": imp.impulse[2],
            "a_y": imp.impulse[3],
        },
        "friction_required": {"b": mu_b, "a": mu_a},
        "phase_durations_s": step.phase_durations_s,
        "residual": fp.residual,
        "newton_iterations": fp.iterations,
        "jacobian_method": fp.jacobian_method,
        # guide friction (beyond the paper): its work per step and how long each leg was stuck (0 without it)
        "friction_work_per_step_j": step.friction_work_J,
        "stick_time_s": {"stance": step.stick_s[0], "trailing": step.stick_s[1]},
    }
    out.update(contact_validity(out))
    out["relabel_note"] = relabel_note(-imp.relabel_loss, p.mass_model)
    if guess is not None:
        out["guess"] = {"theta_plus_rad": float(guess[0]), "theta_dot_plus_rad_s": float(guess[1])}
    return out


def special_point_summary(sp: Any) -> dict[str, Any]:
    """A located special point (rimless.sim.continuation.arclength.SpecialPoint) as plain data."""
    pt = sp.point
    out = {
        "kind": sp.kind,
        "parameter_value": sp.p,
        "bracket": list(sp.bracket_p),
        "test_function_at_bracket": list(sp.bracket_values),
        "theta_plus_rad": float(pt.z[0]),
        "theta_dot_plus_rad_s": float(pt.z[1]),
        "step_period_s": pt.period_s,
        "eigenvalues": [[float(ev.real), float(ev.imag)] for ev in pt.eigenvalues],
        "max_abs_eigenvalue": pt.max_abs_eigenvalue,
        "detail": sp.detail,
    }
    if pt.facts is not None:
        out["contact"] = pt.facts.as_dict()
    return out


def contact_validity(fp_out: dict[str, Any]) -> dict[str, Any]:
    """Unilateral-contact facts beside stability: valid = stance force >= 0 in single support and both normal
    impulses > 0; the leading foot's tension at the start of double support (a rigid-contact artefact the
    paper discusses) is reported with its size and duration, and the friction the impact needs."""
    mf = fp_out["min_normal_force_N"]
    single = [v for v in (mf["slsp_free"], mf["slsp_clutched"]) if v is not None and v == v]
    stance_min = min(single) if single else float("nan")
    imp = fp_out["impact_impulse_N_s"]
    valid = bool(stance_min >= 0.0 and imp["b_y"] > 0.0 and imp["a_y"] > 0.0)
    lead = mf["dlsp_leading_b"]
    tension = min(0.0, lead) if lead is not None and lead == lead else 0.0
    mu = max(fp_out["friction_required"]["b"], fp_out["friction_required"]["a"])
    note = (
        f"contact: {'valid' if valid else 'NOT valid'} under unilateral contact (smallest stance force in single "
        f"support {stance_min:.3g} N, normal impulses {imp['b_y']:.3g} and {imp['a_y']:.3g} N s); leading-foot "
        f"tension in double support {tension:.3g} N for {1e3 * (fp_out.get('leading_foot_tension_s') or 0.0):.1f} ms "
        f"(rigid-contact artefact, rejected only with --strict-contact); friction needed {mu:.2f}"
    )
    return {
        "contact_valid": valid,
        "contact_note": note,
        "min_stance_force_single_support_N": stance_min,
        "leading_foot_tension_N": tension,
        "friction_required_max": mu,
    }


def relabel_note(energy_J: float, mass_model: str) -> str:
    """What the relabelling snap of the old trailing leg does to the energy (sign and size)."""
    verb = "adds" if energy_J > 0 else "removes"
    return (
        f"relabel snap: snapping the old trailing leg to L0 with zero relative velocity at touchdown {verb} "
        f"{abs(energy_J):.3g} J per step ({mass_model} mass model; positive relabel_energy_J adds energy)"
    )


def critical_slope_summary(cs: CriticalSlope, p: WheelParams) -> dict[str, Any]:
    """The `rimless sim critical-slope` JSON object for a compliant model."""
    fp = cs.fixed_point
    if cs.end is not None:
        pt = cs.end.point
        at = {
            "theta_plus_rad": float(pt.z[0]),
            "theta_dot_plus_rad_s": float(pt.z[1]),
            "step_period_s": pt.period_s,
            "max_abs_eigenvalue": pt.max_abs_eigenvalue,
            "eigenvalues": [[float(ev.real), float(ev.imag)] for ev in pt.eigenvalues],
        }
        if pt.facts is not None:
            at["contact"] = pt.facts.as_dict()
    else:
        at = {
            "theta_plus_rad": float(fp.z[0]),
            "theta_dot_plus_rad_s": float(fp.z[1]),
            "step_period_s": fp.recorded_step.period_s,
            "max_abs_eigenvalue": fp.max_abs_eigenvalue,
            "eigenvalues": [[float(ev.real), float(ev.imag)] for ev in fp.eigenvalues],
        }
    return {
        "model": cs.model,
        "critical_slope_rad": cs.critical_slope_rad,
        "critical_slope_deg": cs.critical_slope_deg,
        "cot": cs.cot,
        "reason": cs.reason,
        "detail": cs.detail,
        "definition": "smallest slope of the followed branch with a stable, valid period-1 gait, located to "
        f"{cs.located_to_rad if cs.located_to_rad is not None else cs.refine_tol_rad:.3g} rad "
        f"(asked: {cs.refine_tol_rad:g} rad)",
        "method": cs.method,
        "algorithm1_slope_rad": cs.algorithm1_slope_rad,
        "algorithm1_step_rad": cs.algorithm1_step_rad,
        "algorithm1_definition": "last slope where Newton converged, continuing down from the start slope in fixed steps",
        "refine_tol_rad": cs.refine_tol_rad,
        "located_to_rad": cs.located_to_rad if cs.located_to_rad is not None else cs.refine_tol_rad,
        "map_evaluations": cs.map_evaluations,
        "branch": {
            "start_slope_rad": cs.branch[0].slope_rad,
            "start_theta_plus_rad": float(cs.branch[0].z[0]),
            "start_theta_dot_plus_rad_s": float(cs.branch[0].z[1]),
            "start_step_period_s": cs.branch[0].period_s,
            "points": len(cs.branch),
        },
        "at_critical": at,
        "special_points": [special_point_summary(sp) for sp in cs.special_points],
        "k": p.stiffness_n_per_m,
        "c": p.damping_ns_per_m,
        "mass_model": p.mass_model,
        "guide_friction_n": p.guide_friction_n,
    }


def rigid_summary(p: WheelParams) -> dict[str, Any]:
    """Rigid wheel: Coleman's critical slope with the paper's mass convention and the eight-leg one."""
    paper = RigidWheel.from_params(p, "paper")
    eight = RigidWheel.from_params(p, "eight-leg")
    phi_p = paper.critical_slope_rad()
    phi_e = eight.critical_slope_rad()
    return {
        "model": "rigid",
        "critical_slope_rad": phi_p,
        "critical_slope_deg": math.degrees(phi_p),
        "cot": math.tan(phi_p),
        "reason": "coleman-closed-form",
        "mass_convention": "paper: M = m_H, inertia I_c (Coleman's formula as in the paper)",
        "beta": paper.beta,
        "eigenvalue": paper.eigenvalue(),
        "eight_leg_consistent": {
            "critical_slope_rad": phi_e,
            "critical_slope_deg": math.degrees(phi_e),
            "cot": math.tan(phi_e),
            "mass_convention": "M = m_H + 8 m, inertia I_c + 8 m L0^2",
            "beta": eight.beta,
        },
    }
