"""`rimless sim fixed-point`, `gaits` and `critical-slope`: parse, call rimless.sim.studies.gaits, print."""

import math
from typing import Annotated, Any

import typer

from rimless.cli_rules import fail, print_json, user_facing
from rimless.errors import ParameterError
from rimless.progress import progress_bar
from rimless.sim.cli.app import (
    Backend,
    BackendOpt,
    ElectronicsPowerOpt,
    GaitOpt,
    GuessOpt,
    HoldPowerOpt,
    JsonOpt,
    Model,
    ModelOpt,
    ModelOrRigid,
    RtolOpt,
    StrictOpt,
    SwitchEnergyOpt,
    ThetaGuessOpt,
    VeElectronicsOpt,
    clutch_power,
    option_given,
    start_slope,
    wheel_params,
)
from rimless.sim.cli.output import console, table


@user_facing
@wheel_params
def fixed_point_cmd(
    params: Any,
    model: ModelOpt = Model.er,
    theta_dot_guess: GuessOpt = None,
    theta_plus_guess: ThetaGuessOpt = None,
    gait: GaitOpt = None,
    strict_contact: StrictOpt = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
    clutch_hold_power_w: HoldPowerOpt = 0.0,
    clutch_switch_energy_j: SwitchEnergyOpt = 0.0,
    electronics_power_w: ElectronicsPowerOpt = 0.0,
    ve_electronics: VeElectronicsOpt = False,
) -> None:
    """Period-1 gait: the fixed point of the Poincaré map, its eigenvalues, period and contact diagnostics."""
    from rimless.sim.api.wheel import Wheel

    power = clutch_power(clutch_hold_power_w, clutch_switch_energy_j, electronics_power_w, ve_electronics)
    wheel = Wheel(params, model.value, backend=backend.value, rtol=rtol)
    with progress_bar("period-1 gait", json_out=json_out) as bar:
        out = wheel.fixed_point(
            theta_dot_guess=theta_dot_guess,
            theta_plus_guess=theta_plus_guess,
            gait=gait,
            strict_contact=strict_contact,
            progress=lambda i, n: bar.update(i, n, "finding the gaits"),
            power=power,
        ).to_dict()
    if json_out:
        print_json(out)
        return
    mf = out["min_normal_force_N"]
    rows = [
        ("model / mass model", f"{model.value} / {params.mass_model}"),
        ("slope (deg)", params.slope_deg),
        ("k (N/m), c (N s/m)", f"{params.k:g}, {params.c:g}"),
        ("theta+ (rad)", out["theta_plus_rad"]),
        ("theta'+ (rad/s)", out["theta_dot_plus_rad_s"]),
        ("step period (s)", out["step_period_s"]),
        ("eigenvalues", ", ".join(f"{re:.5f}{im:+.5f}j" for re, im in out["eigenvalues"])),
        ("max |eigenvalue|", out["max_abs_eigenvalue"]),
        ("orbitally stable (max |eig| < 1)", "yes" if out["stable"] else "no"),
        ("contact valid (unilateral)", "yes" if out["contact_valid"] else "NO"),
        ("energy ratio E+/E-", out["energy_ratio"]),
        ("phase durations (s)", ", ".join(f"{k} {v:.4f}" for k, v in out["phase_durations_s"].items())),
        ("min normal force b in DLSP (N)", mf["dlsp_leading_b"]),
        ("min normal force b in SLSP (N)", min(v for v in (mf["slsp_free"], mf["slsp_clutched"]) if v == v)),
        ("trailing foot lowest point (mm)", out["trailing_foot_min_height_m"] * 1e3),
        (
            "friction needed at impact (b, a)",
            f"{out['friction_required']['b']:.3f}, {out['friction_required']['a']:.3f}",
        ),
        ("relabel snap energy (J)", f"{out['relabel_energy_J']:+.3g}"),
        *(
            [
                ("guide friction F_c (N)", params.guide_friction_n),
                ("friction work per step (J)", out["friction_work_per_step_j"]),
                (
                    "stuck time stance, trailing (s)",
                    f"{out['stick_time_s']['stance']:.4f}, {out['stick_time_s']['trailing']:.4f}",
                ),
            ]
            if params.guide_friction_n > 0.0
            else []
        ),
        ("residual |P(z)-z|", out["residual"]),
        (
            "found by",
            "Newton from the default guess"
            if out["found_by"] == "newton"
            else "the gaits search (Newton from the default guess failed)",
        ),
        ("step length along the slope (m)", out["step_length_m"]),
        ("clutched time per step (s)", out["clutched_time_s"]),
        ("mechanical CoT (= tan phi)", out["mechanical_cot"]),
        ("electrical energy per step (J)", out["electrical_energy_per_step_j"]),
        ("system CoT (M g s_z + E_el)/(M g s_x)", out["system_cot"]),
    ]
    con = console()
    con.print(table("period-1 gait", rows))
    con.print(out["contact_note"])  # prose: wrapped at the terminal's width
    con.print(out["relabel_note"])


@user_facing
@wheel_params
def gaits_cmd(
    params: Any,
    model: ModelOpt = Model.ve,
    theta_dot_min: Annotated[float, typer.Option(help="Smallest theta'+ guess scanned, rad/s.")] = 0.8,
    theta_dot_max: Annotated[float, typer.Option(help="Largest theta'+ guess scanned, rad/s.")] = 6.0,
    guesses: Annotated[int, typer.Option(min=2, max=200, help="Number of theta'+ guesses.")] = 14,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
) -> None:
    """Every period-1 gait at one slope: scan initial conditions, solve, de-duplicate."""
    from rich.table import Table

    from rimless.sim.api.wheel import Wheel

    wheel = Wheel(params, model.value, backend=backend.value, rtol=rtol)
    with progress_bar("scanning guesses", guesses, json_out=json_out) as bar:
        out = wheel.gaits(
            theta_dot_min=theta_dot_min,
            theta_dot_max=theta_dot_max,
            guesses=guesses,
            progress=lambda i, n: bar.update(i),
        ).to_dict()
    if not out["gaits"]:
        fail(
            f"no period-1 gait of the {model.value} wheel at {params.slope_deg:.4f} deg for theta'+ guesses in "
            f"[{theta_dot_min:g}, {theta_dot_max:g}] rad/s"
        )
    if json_out:
        print_json(out)
        return
    items = out["gaits"]
    listing = Table(title=f"period-1 gaits of the {model.value} wheel at {params.slope_deg:.4f} deg")
    listing.box = None
    listing.pad_edge = False
    for col in ("#", "theta+ rad", "theta'+ rad/s", "period s", "max|eig|", "stable", "valid", "Fmin N", "E+/E-"):
        listing.add_column(col, justify="right", no_wrap=True)
    for i, it in enumerate(items):
        fmin = it["contact"]["min_stance_force_single_support_N"] if it["contact"] else float("nan")
        listing.add_row(
            str(i + 1),
            f"{it['theta_plus_rad']:.5f}",
            f"{it['theta_dot_plus_rad_s']:.5f}",
            f"{it['step_period_s']:.4f}",
            f"{it['max_abs_eigenvalue']:.4f}",
            "yes" if it["stable"] else "no",
            "yes" if it["contact_valid"] else "NO",
            f"{fmin:.3g}",
            f"{it['energy_ratio']:.4f}",
        )
    con = console()
    con.print(listing)
    con.print(
        "stable: max |eig| < 1; valid: unilateral contact (stance force >= 0 in single support, "
        "impulses > 0; a gait that is not was found with the stance foot held); Fmin: smallest stance "
        "force in single support; theta'+: post-impact angular velocity"
    )
    for i, it in enumerate(items):
        if it["contact_reason"]:
            con.print(f"gait {i + 1}: {it['contact_reason']}")


@user_facing
@wheel_params
def critical_slope_cmd(
    params: Any,
    model: Annotated[ModelOrRigid, typer.Option("--model", help="er, ve or rigid (closed form).")] = ModelOrRigid.er,
    theta_dot_guess: GuessOpt = None,
    theta_plus_guess: ThetaGuessOpt = None,
    gait: GaitOpt = None,
    step_rad: Annotated[float, typer.Option(min=1e-5, max=0.01, help="Algorithm 1 slope step, rad.")] = 0.001,
    start_slope_rad: Annotated[
        float | None,
        typer.Option(help="Slope where the continuation starts, rad [the wheel's slope: --slope-deg, 0.05 rad]."),
    ] = None,
    strict_contact: StrictOpt = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
    clutch_hold_power_w: HoldPowerOpt = 0.0,
    clutch_switch_energy_j: SwitchEnergyOpt = 0.0,
    electronics_power_w: ElectronicsPowerOpt = 0.0,
    ve_electronics: VeElectronicsOpt = False,
) -> None:
    """Critical slope and minimum cost of transport: Algorithm 1 and the refined end of the branch."""
    from rimless.sim.api.wheel import Wheel

    if model != ModelOrRigid.rigid:
        start_slope_rad = start_slope(params, start_slope_rad)
    elif start_slope_rad is not None or option_given("slope_deg") or option_given("slope_rad"):
        raise ParameterError(
            "--model rigid is the closed form: it takes no slope (drop --slope-deg, --slope-rad and --start-slope-rad)"
        )
    if model == ModelOrRigid.rigid and params.guide_friction_n > 0.0:
        raise ParameterError("--model rigid has no sliding legs: --guide-friction-n does not apply to it")
    power = clutch_power(clutch_hold_power_w, clutch_switch_energy_j, electronics_power_w, ve_electronics)
    with progress_bar("continuation in slope", json_out=json_out) as bar:
        out = (
            Wheel(params, model.value, backend=backend.value, rtol=rtol)
            .critical_slope(
                theta_dot_guess=theta_dot_guess,
                theta_plus_guess=theta_plus_guess,
                gait=gait,
                step_rad=step_rad,
                start_slope_rad=start_slope_rad,
                strict_contact=strict_contact,
                gaits_progress=lambda i, n: bar.update(description=f"finding the gaits {i}/{n}"),
                progress=lambda s: bar.update(description=f"slope {math.degrees(s):.4f} deg"),
                power=power,
            )
            .to_dict()
        )
    if json_out:
        print_json(out)
        return
    if model == ModelOrRigid.rigid:
        e8 = out["eight_leg_consistent"]
        console().print(
            table(
                "rigid rimless wheel (Coleman)",
                [
                    ("critical slope (deg), paper convention M = m_H", f"{out['critical_slope_deg']:.3f}"),
                    ("critical slope (rad)", out["critical_slope_rad"]),
                    ("CoT = tan(phi_c)", out["cot"]),
                    ("beta, eigenvalue beta^2", f"{out['beta']:.5f}, {out['eigenvalue']:.5f}"),
                    ("eight-leg-consistent critical slope (deg)", f"{e8['critical_slope_deg']:.3f}"),
                    ("eight-leg-consistent critical slope (rad)", e8["critical_slope_rad"]),
                ],
            )
        )
        return
    at = out["at_critical"]
    console().print(
        table(
            f"critical slope, {model.value} wheel",
            [
                ("critical slope (deg)", out["critical_slope_deg"]),
                ("critical slope (rad)", out["critical_slope_rad"]),
                ("CoT = tan(phi_c)", out["cot"]),
                ("branch ends by", out["reason"]),
                ("located by", f"{out['method']} ({out['map_evaluations']} map evaluations)"),
                ("Algorithm 1 slope (rad), step", f"{out['algorithm1_slope_rad']:.6f}, {out['algorithm1_step_rad']:g}"),
                (
                    "branch followed from",
                    f"theta'+ = {out['branch']['start_theta_dot_plus_rad_s']:.4f} rad/s, period "
                    f"{out['branch']['start_step_period_s']:.4f} s at {start_slope_rad} rad",
                ),
                ("at critical: period (s), max |eig|", f"{at['step_period_s']:.4f}, {at['max_abs_eigenvalue']:.4f}"),
                (
                    "contact valid at critical",
                    ("yes" if at["contact"]["contact_valid"] else "NO") if "contact" in at else "-",
                ),
                ("at critical: electrical energy per step (J)", out.get("electrical_energy_per_step_j", "-")),
                ("at critical: system CoT", out.get("system_cot", "-")),
                ("least system CoT along the branch", out["min_system_cot"]),
                (
                    "  at slope (deg)",
                    f"{out['min_system_cot_slope_deg']:.5f}"
                    + (
                        f" (on the branch's bound: {out['min_system_cot_at_bound']})"
                        if out["min_system_cot_at_bound"]
                        else ""
                    ),
                ),
                ("  located by", out["min_system_cot_method"]),
            ],
        )
    )
    console().print(f"why: {out['detail']}")
