"""`rimless sim ...`: thin commands over the simulator library.

Every command takes the wheel parameters as options (defaults: the paper's Table 1) or from a TOML file
(`--params FILE`, options given on the command line win). Heavy imports happen inside the commands.
"""

import functools
import inspect
import math
from enum import Enum
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from rimless.cli_rules import print_json, user_facing
from rimless.errors import ParameterError

app = typer.Typer(no_args_is_help=True)


class Model(str, Enum):
    er = "er"
    ve = "ve"


class ModelOrRigid(str, Enum):
    er = "er"
    ve = "ve"
    rigid = "rigid"


class MassModel(str, Enum):
    eight_leg = "eight-leg"
    sliding_leg = "sliding-leg"
    active_feet = "active-feet"


class ClutchKind(str, Enum):
    ideal = "ideal"
    firmware = "firmware"


class Backend(str, Enum):
    auto = "auto"
    fast = "fast"
    reference = "reference"


_PARAM_OPTIONS: list[tuple[str, Any, str]] = [
    ("k", Optional[float], "Leg spring stiffness k, N/m [Table 1: 2700]."),
    ("c", Optional[float], "Leg damping c, N s/m [Table 1: 8]."),
    ("slope_deg", Optional[float], "Slope, degrees [Table 1: 0.05 rad = 2.865 deg]."),
    ("slope_rad", Optional[float], "Slope, rad [Table 1: 0.05]."),
    ("hub_mass_kg", Optional[float], "Hub (main body) mass m_H, kg [1.892]."),
    ("leg_mass_kg", Optional[float], "Mass of one leg m, kg [0.0378]."),
    ("inertia_kg_m2", Optional[float], "Hub inertia I_c, kg m^2 [0.036]."),
    ("leg_length_m", Optional[float], "Free leg length L0, m [0.237]."),
    ("g", Optional[float], "Gravity, m/s^2 [9.81]."),
    ("mass_model", Optional[MassModel], "How the legs' mass enters the model (model.md section 8) [eight-leg]."),
    ("params_file", Optional[Path], "TOML file of parameters (keys: k, c, slope_deg or slope_rad, m_H, m, I_c, L0, g, "
                                    "mass_model); command-line options win."),
]
_OPTION_NAMES = {"params_file": "--params", "g": "--g"}


def build_params(values: dict[str, Any]) -> Any:
    """WheelParams from the parameter options (validated; errors name the parameter)."""
    from rimless.sim.model.params import WheelParams, load_params, params_from_mapping

    base = WheelParams()
    if values.get("params_file") is not None:
        base = load_params(values["params_file"], base=base)
    if values.get("slope_deg") is not None and values.get("slope_rad") is not None:
        raise ParameterError("give the slope once: --slope-deg or --slope-rad, not both")
    mapping: dict[str, Any] = {}
    for key in ("k", "c", "slope_deg", "slope_rad", "hub_mass_kg", "leg_mass_kg", "inertia_kg_m2", "leg_length_m", "g"):
        if values.get(key) is not None:
            mapping[key] = values[key]
    if values.get("mass_model") is not None:
        mapping["mass_model"] = values["mass_model"].value
    try:
        return params_from_mapping(mapping, base=base, source="the command-line options")
    except ParameterError as err:
        if values.get("slope_deg") is not None and "slope" in str(err):
            from rimless.sim.model.params import SPOKE_ANGLE_RAD

            raise ParameterError(f"--slope-deg must be a finite slope in [0, {math.degrees(SPOKE_ANGLE_RAD / 2):g}) deg, "
                                 f"got {values['slope_deg']:g} deg") from None
        raise


def wheel_params(func: Any = None, *, exclude: tuple[str, ...] = ()) -> Any:
    """Add the parameter options to a command; the command receives `params: WheelParams`.

    exclude: parameter options the command defines itself (e.g. a sweep's `--k` grid)."""
    if func is None:
        return functools.partial(wheel_params, exclude=exclude)
    sig = inspect.signature(func)
    own = [p for p in sig.parameters.values() if p.name != "params"]
    options = [o for o in _PARAM_OPTIONS if o[0] not in exclude]
    extra = []
    for name, annotation, help_text in options:
        flag = _OPTION_NAMES.get(name, "--" + name.replace("_", "-"))
        opt = typer.Option(flag, help=help_text, rich_help_panel="Wheel parameters")
        extra.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=None,
                                       annotation=Annotated[annotation, opt]))

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {name: kwargs.pop(name, None) for name, _, _ in options}
        kwargs["params"] = build_params(values)
        return func(*args, **kwargs)

    params = own + extra
    wrapper.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    del wrapper.__wrapped__  # typer must read the new signature, not the wrapped one
    return wrapper


ModelOpt = Annotated[Model, typer.Option("--model", help="er: energy-recycling (spring-clutch legs); ve: viscoelastic.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of a table.")]
BackendOpt = Annotated[Backend, typer.Option("--backend", help="fast (compiled), reference (scipy solve_ivp) or auto.")]
RtolOpt = Annotated[float, typer.Option("--rtol", min=1e-13, max=1e-3, help="Integrator relative tolerance.")]
GuessOpt = Annotated[Optional[float], typer.Option("--theta-dot-guess", help="Initial guess of theta'+ (rad/s): picks the branch.")]
ThetaGuessOpt = Annotated[Optional[float], typer.Option("--theta-plus-guess", help="Initial guess of theta+ (rad), "
                                                        "the post-impact stance angle [-alpha/2 - 0.07].")]
GaitOpt = Annotated[Optional[int], typer.Option("--gait", min=1, max=200, metavar="N",
                                                help="Start from gait N of `rimless sim gaits` (same parameters, "
                                                     "numbered by step period) instead of a guess.")]
StrictOpt = Annotated[bool, typer.Option("--strict-contact", help="Reject gaits whose leading foot pulls on the ground in "
                                                                   "double support or whose lifted foot dips below the slope.")]


def _console():  # noqa: ANN202
    from rich.console import Console

    return Console()


def _guess(params: Any, model: str, theta_dot_guess: Optional[float], theta_plus_guess: Optional[float] = None) -> Any:
    from rimless.sim.model.params import SPOKE_ANGLE_RAD
    from rimless.sim.step.poincare import default_guess

    z = default_guess(params, model)
    if theta_dot_guess is not None:
        if not (math.isfinite(theta_dot_guess) and theta_dot_guess > 0):
            raise ParameterError(f"--theta-dot-guess must be a positive angular velocity in rad/s, got {theta_dot_guess}")
        z[1] = theta_dot_guess
    if theta_plus_guess is not None:
        if not (math.isfinite(theta_plus_guess) and -SPOKE_ANGLE_RAD < theta_plus_guess < 0):
            raise ParameterError(f"--theta-plus-guess must be a stance angle in (-{SPOKE_ANGLE_RAD:.4f}, 0) rad, "
                                 f"got {theta_plus_guess}")
        z[0] = theta_plus_guess
    return z


def _start_guess(params: Any, model: str, *, theta_dot_guess: Optional[float], theta_plus_guess: Optional[float],
                 gait: Optional[int], backend: str, rtol: float) -> Any:
    """The section point to start Newton from: gait N of the `gaits` scan, or the (overridden) default guess."""
    if gait is None:
        return _guess(params, model, theta_dot_guess, theta_plus_guess)
    if theta_dot_guess is not None or theta_plus_guess is not None:
        raise ParameterError("give either --gait or --theta-dot-guess/--theta-plus-guess, not both")
    from rich.progress import Progress

    from rimless.sim.integrate.backend import make_map
    from rimless.sim.step.poincare import find_gaits

    pmap = make_map(params, model, backend=backend, rtol=rtol)
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("finding the gaits", total=14)
        found = find_gaits(pmap, progress=lambda i, n: prog.update(task, completed=i, total=n), include_invalid=True)
    if not found:
        raise SimFailure(f"--gait {gait}: no period-1 gait of the {model} wheel at {params.slope_deg:.4f} deg")
    if gait > len(found):
        raise ParameterError(f"--gait {gait}: only {len(found)} gait(s) of the {model} wheel at "
                             f"{params.slope_deg:.4f} deg (see `rimless sim gaits`)")
    fp = found[gait - 1]
    if fp.bilateral:
        from rimless.sim.continuation.arclength import contact_facts
        from rimless.sim.continuation.branches import contact_reason
        from rimless.sim.step.poincare import bilateral_map

        raise SimFailure(f"--gait {gait}: that gait of the {model} wheel violates unilateral contact "
                         f"({contact_reason(contact_facts(bilateral_map(pmap), fp.z, 5e-4))}); it exists only "
                         "with the stance foot held")
    return fp.z.copy()


class SimFailure(Exception):
    """A failure that is not the user's mistake (no gait exists): one line on stderr, exit 1."""


def sim_failures(func: Any) -> Any:
    """Turn SimFailure into `error: ...` on stderr and exit code 1; Ctrl-C into exit 130 without a traceback."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except SimFailure as err:
            typer.echo(f"error: {err}", err=True)
            raise typer.Exit(1) from None
        except KeyboardInterrupt:
            typer.echo("interrupted", err=True)
            raise typer.Exit(130) from None

    return wrapper


def _table(title: str, rows: list[tuple[str, Any]]) -> Any:
    from rich.table import Table

    table = Table(title=title, show_header=True)
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for key, value in rows:
        if isinstance(value, float):
            value = f"{value:.6g}"
        table.add_row(key, str(value))
    return table


@app.command("fixed-point")
@user_facing
@sim_failures
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
) -> None:
    """Period-1 gait: the fixed point of the Poincaré map, its eigenvalues, period and contact diagnostics."""
    from rimless.sim.integrate.backend import jacobian_factory, make_map
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.poincare import solve_fixed_point
    from rimless.sim.step.summary import fixed_point_summary

    guess = _start_guess(params, model.value, theta_dot_guess=theta_dot_guess, theta_plus_guess=theta_plus_guess,
                         gait=gait, backend=backend.value, rtol=rtol)
    pmap = make_map(params, model.value, backend=backend.value, rtol=rtol)
    jf = jacobian_factory(backend.value)
    try:
        fp = solve_fixed_point(pmap, guess, jacobian=jf(pmap) if jf else None, diagnostics=True,
                               strict_contact=strict_contact)
    except StepFailure as err:
        raise SimFailure(f"no period-1 gait found for the {model.value} wheel from the guess "
                         f"theta+ = {guess[0]:.4f} rad, theta'+ = {guess[1]:.4f} rad/s: {err}") from None
    out = fixed_point_summary(fp, params, model.value, guess=guess)
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
        ("friction needed at impact (b, a)", f"{out['friction_required']['b']:.3f}, {out['friction_required']['a']:.3f}"),
        ("relabel snap energy (J)", f"{out['relabel_energy_J']:+.3g}"),
        ("residual |P(z)-z|", out["residual"]),
    ]
    con = _console()
    con.print(_table("period-1 gait", rows))
    con.print(out["contact_note"], soft_wrap=True)
    con.print(out["relabel_note"], soft_wrap=True)


@app.command("gaits")
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
    from rimless.sim.integrate.backend import make_map
    from rimless.sim.step.poincare import find_gaits

    if not 0 < theta_dot_min < theta_dot_max:
        raise ParameterError("need 0 < --theta-dot-min < --theta-dot-max (rad/s)")
    pmap = make_map(params, model.value, backend=backend.value, rtol=rtol)
    from rich.progress import Progress

    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("scanning guesses", total=guesses)
        found = find_gaits(pmap, theta_dot_range=(theta_dot_min, theta_dot_max), n_guesses=guesses,
                           progress=lambda i, n: prog.update(task, completed=i), include_invalid=True)
    from rimless.sim.continuation.arclength import contact_facts
    from rimless.sim.continuation.branches import contact_reason
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.poincare import bilateral_map

    items = []
    for fp in found:
        try:  # a gait found with the stance foot held is recorded that way too
            facts = contact_facts(bilateral_map(pmap) if fp.bilateral else pmap, fp.z, 5e-4)
        except StepFailure:
            facts = None
        items.append({
            "theta_plus_rad": float(fp.z[0]),
            "theta_dot_plus_rad_s": float(fp.z[1]),
            "step_period_s": fp.step.period_s,
            "eigenvalues": [[float(e.real), float(e.imag)] for e in fp.eigenvalues],
            "max_abs_eigenvalue": fp.max_abs_eigenvalue,
            "stable": fp.stable,
            "energy_ratio": fp.step.impact.energy_ratio,
            "contact_valid": bool(facts is not None and facts.contact_valid),
            "contact_reason": contact_reason(facts),
            "contact_violation": facts.violation if facts is not None else "unknown",
            "contact_model": "bilateral" if fp.bilateral else "unilateral",
            "contact": facts.as_dict() if facts is not None else None,
        })
    if json_out:
        print_json({"model": model.value, "slope_rad": params.slope_rad, "k": params.k, "c": params.c, "gaits": items})
        return
    from rich.table import Table

    table = Table(title=f"period-1 gaits of the {model.value} wheel at {params.slope_deg:.4f} deg")
    table.box = None
    table.pad_edge = False
    for col in ("#", "theta+ rad", "theta'+ rad/s", "period s", "max|eig|", "stable", "valid", "Fmin N", "E+/E-"):
        table.add_column(col, justify="right", no_wrap=True)
    for i, it in enumerate(items):
        fmin = it["contact"]["min_stance_force_single_support_N"] if it["contact"] else float("nan")
        table.add_row(str(i + 1), f"{it['theta_plus_rad']:.5f}", f"{it['theta_dot_plus_rad_s']:.5f}",
                      f"{it['step_period_s']:.4f}", f"{it['max_abs_eigenvalue']:.4f}", "yes" if it["stable"] else "no",
                      "yes" if it["contact_valid"] else "NO", f"{fmin:.3g}", f"{it['energy_ratio']:.4f}")
    _console().print(table)
    _console().print("stable: max |eig| < 1; valid: unilateral contact (stance force >= 0 in single support, "
                     "impulses > 0; a gait that is not was found with the stance foot held); Fmin: smallest stance "
                     "force in single support; theta'+: post-impact angular velocity", soft_wrap=True)
    for i, it in enumerate(items):
        if it["contact_reason"]:
            _console().print(f"gait {i + 1}: {it['contact_reason']}", soft_wrap=True)
    if not items:
        _console().print("no period-1 gait found in the scanned range")


@app.command("critical-slope")
@user_facing
@sim_failures
@wheel_params
def critical_slope_cmd(
    params: Any,
    model: Annotated[ModelOrRigid, typer.Option("--model", help="er, ve or rigid (closed form).")] = ModelOrRigid.er,
    theta_dot_guess: GuessOpt = None,
    theta_plus_guess: ThetaGuessOpt = None,
    gait: GaitOpt = None,
    step_rad: Annotated[float, typer.Option(min=1e-5, max=0.01, help="Algorithm 1 slope step, rad.")] = 0.001,
    start_slope_rad: Annotated[float, typer.Option(help="Slope where the continuation starts, rad.")] = 0.05,
    strict_contact: StrictOpt = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
) -> None:
    """Critical slope and minimum cost of transport: Algorithm 1 and the refined end of the branch."""
    from rimless.sim.step.summary import critical_slope_summary, rigid_summary

    if model == ModelOrRigid.rigid:
        out = rigid_summary(params)
        if json_out:
            print_json(out)
            return
        e8 = out["eight_leg_consistent"]
        _console().print(_table("rigid rimless wheel (Coleman)", [
            ("critical slope (deg), paper convention M = m_H", f"{out['critical_slope_deg']:.3f}"),
            ("critical slope (rad)", out["critical_slope_rad"]),
            ("CoT = tan(phi_c)", out["cot"]),
            ("beta, eigenvalue beta^2", f"{out['beta']:.5f}, {out['eigenvalue']:.5f}"),
            ("eight-leg-consistent critical slope (deg)", f"{e8['critical_slope_deg']:.3f}"),
            ("eight-leg-consistent critical slope (rad)", e8["critical_slope_rad"]),
        ]))
        return
    from rimless.sim.integrate.backend import jacobian_factory, make_map
    from rimless.sim.continuation.algorithm1 import critical_slope
    from rimless.sim.model.failures import StepFailure

    from rimless.sim.model.params import SPOKE_ANGLE_RAD

    if not 0 < start_slope_rad < SPOKE_ANGLE_RAD / 2:
        raise ParameterError(f"--start-slope-rad must be in (0, {SPOKE_ANGLE_RAD / 2:.4f}) rad, got {start_slope_rad}")
    start_params = params.replace(slope_rad=start_slope_rad)
    pmap = make_map(start_params, model.value, backend=backend.value, rtol=rtol)
    guess = _start_guess(start_params, model.value, theta_dot_guess=theta_dot_guess, theta_plus_guess=theta_plus_guess,
                         gait=gait, backend=backend.value, rtol=rtol)
    from rich.progress import Progress

    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("continuation in slope", total=None)
        try:
            cs = critical_slope(pmap, guess, start_slope_rad=start_slope_rad, step_rad=step_rad,
                                strict_contact=strict_contact, jacobian_factory=jacobian_factory(backend.value),
                                progress=lambda s: prog.update(task, description=f"slope {math.degrees(s):.4f} deg"))
        except StepFailure as err:
            raise SimFailure(f"critical slope of the {model.value} wheel: {err}") from None
    out = critical_slope_summary(cs, params)
    if json_out:
        print_json(out)
        return
    at = out["at_critical"]
    _console().print(_table(f"critical slope, {model.value} wheel", [
        ("critical slope (deg)", out["critical_slope_deg"]),
        ("critical slope (rad)", out["critical_slope_rad"]),
        ("CoT = tan(phi_c)", out["cot"]),
        ("branch ends by", out["reason"]),
        ("located by", f"{out['method']} ({out['map_evaluations']} map evaluations)"),
        ("Algorithm 1 slope (rad), step", f"{out['algorithm1_slope_rad']:.6f}, {out['algorithm1_step_rad']:g}"),
        ("branch followed from", f"theta'+ = {out['branch']['start_theta_dot_plus_rad_s']:.4f} rad/s, period "
                                 f"{out['branch']['start_step_period_s']:.4f} s at {start_slope_rad} rad"),
        ("at critical: period (s), max |eig|", f"{at['step_period_s']:.4f}, {at['max_abs_eigenvalue']:.4f}"),
        ("contact valid at critical", ("yes" if at["contact"]["contact_valid"] else "NO") if "contact" in at else "-"),
    ]))
    _console().print(f"why: {out['detail']}", soft_wrap=True)


@app.command("gait")
@user_facing
@sim_failures
@wheel_params
def gait_cmd(
    params: Any,
    model: ModelOpt = Model.er,
    theta_dot_guess: GuessOpt = None,
    theta_plus_guess: ThetaGuessOpt = None,
    gait: GaitOpt = None,
    steps: Annotated[int, typer.Option("--steps", min=1, max=10000, help="Number of steps to simulate.")] = 6,
    theta_dot: Annotated[Optional[float], typer.Option("--theta-dot", help="Start from this theta'+ (rad/s) just "
                                                       "after an impact instead of the fixed point.")] = None,
    theta_plus_rad: Annotated[Optional[float], typer.Option(help="With --theta-dot: post-impact stance angle, rad "
                                                            "[-alpha/2: both legs at rest length].")] = None,
    out: Annotated[Optional[Path], typer.Option("--out", help="Write the trajectory (.parquet or .csv).")] = None,
    plot: Annotated[Optional[Path], typer.Option("--plot", help="Write the gait figure (.png, .pdf, .svg).")] = None,
    forces: Annotated[bool, typer.Option("--forces", help="Also record the constraint forces (lambda, N) and plot "
                                         "the normal forces and a stick diagram.")] = False,
    sample_dt_s: Annotated[float, typer.Option(min=1e-5, max=0.05, help="Sampling interval of the trajectory, s.")] = 1e-3,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
    clutch: Annotated[ClutchKind, typer.Option("--clutch", help="ideal: lock at maximum compression, release at "
                                               "touchdown; firmware: the robot's controller in the loop (ER).",
                                               rich_help_panel="Firmware in the loop")] = None,  # type: ignore[assignment]
    rate_hz: Annotated[Optional[float], typer.Option("--rate-hz", help="Sensor sampling rate, Hz [300, or the "
                                                     "--robot-config's].", rich_help_panel="Firmware in the loop")]
    = None,
    robot_config: Annotated[Optional[Path], typer.Option("--robot-config", help="robot.toml whose detector, sensor "
                                                         "and rate settings the firmware runs with.",
                                                         rich_help_panel="Firmware in the loop")] = None,
    clutch_delay_ms: Annotated[float, typer.Option("--clutch-delay-ms", help="Clutch engage delay (pin on -> leg "
                                                   "locked), ms; also the release delay unless --release-delay-ms.",
                                                   rich_help_panel="Firmware in the loop")] = 5.0,
    release_delay_ms: Annotated[Optional[float], typer.Option("--release-delay-ms", help="Clutch release delay, ms.",
                                                              rich_help_panel="Firmware in the loop")] = None,
    noise_counts: Annotated[float, typer.Option("--noise-counts", help="ADNS-3080 position noise (sd), counts.",
                                                rich_help_panel="Firmware in the loop")] = 1.0,
    jitter_ms: Annotated[float, typer.Option("--jitter-ms", help="Sampling lateness (sd), ms.",
                                             rich_help_panel="Firmware in the loop")] = 0.05,
    holding_force_n: Annotated[float, typer.Option("--holding-force-n", help="Clutch holding force along the leg, N "
                                                   "(it slips beyond; inf: rigid).",
                                                   rich_help_panel="Firmware in the loop")] = 100.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sensor noise and sampling jitter.",
                                      rich_help_panel="Firmware in the loop")] = 0,
    bench: Annotated[bool, typer.Option("--bench", help="With --clutch firmware: print simulated steps per second "
                                        "at 300 Hz and 1 kHz beside the ideal clutch, and exit.",
                                        rich_help_panel="Firmware in the loop")] = False,
    critical_slope: Annotated[bool, typer.Option("--critical-slope", help="With --clutch firmware: bisect the lowest "
                                                 "slope that still walks (a walk of --steps per slope).",
                                                 rich_help_panel="Firmware in the loop")] = False,
    critical_low_deg: Annotated[float, typer.Option("--critical-low-deg", help="Low end of the bisection, deg.",
                                                    rich_help_panel="Firmware in the loop")] = 0.5,
    critical_tol_deg: Annotated[float, typer.Option("--critical-tol-deg", min=1e-4, max=1.0, help="Bisection "
                                                    "tolerance, deg.", rich_help_panel="Firmware in the loop")] = 0.05,
) -> None:
    """Simulate N steps from the fixed point (or from --theta-dot) and export or plot them."""
    if robot_config is not None:
        if not robot_config.is_file():
            raise ParameterError(f"--robot-config {robot_config}: no such file")
        if clutch is not ClutchKind.firmware:
            raise ParameterError("--robot-config needs --clutch firmware")
    if clutch is ClutchKind.firmware:
        from rimless.sim.cli import firmware as firmware_cli

        if model is not Model.er:
            raise ParameterError("--clutch firmware needs --model er (the viscoelastic wheel has no clutch)")
        if theta_dot is not None or gait is not None or out is not None or plot is not None:
            raise ParameterError("--clutch firmware starts from the ideal fixed point and writes no trajectory: "
                                 "drop --theta-dot, --gait, --out and --plot")
        if bench:
            firmware_cli.run_bench(params, json_out=json_out)
            return
        config = firmware_cli.build_config(rate_hz=rate_hz, clutch_delay_ms=clutch_delay_ms,
                                           release_delay_ms=release_delay_ms, noise_counts=noise_counts,
                                           jitter_ms=jitter_ms, holding_force_n=holding_force_n, seed=seed,
                                           robot_config=robot_config)
        if critical_slope:
            code = firmware_cli.run_critical(params, config, steps=max(steps, 6), low_deg=critical_low_deg,
                                             tol_deg=critical_tol_deg, json_out=json_out)
        else:
            code = firmware_cli.run_gait(params, config, steps=max(steps, 6), backend=backend.value, rtol=rtol,
                                         json_out=json_out)
        if code:
            raise typer.Exit(code)
        return
    import numpy as np

    from rimless.sim.integrate.backend import jacobian_factory, make_integrator, make_map
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.step.gait import simulate_steps
    from rimless.sim.model.mechanics import ALPHA
    from rimless.sim.step.poincare import solve_fixed_point

    for path, exts in ((out, (".parquet", ".csv")), (plot, (".png", ".pdf", ".svg"))):
        if path is not None and path.suffix.lower() not in exts:
            raise ParameterError(f"{path}: the file must end in {' or '.join(exts)}")
    if theta_dot is not None:
        if not (math.isfinite(theta_dot) and theta_dot > 0):
            raise ParameterError(f"--theta-dot must be a positive angular velocity in rad/s, got {theta_dot}")
        z0 = np.array([-ALPHA / 2 if theta_plus_rad is None else theta_plus_rad, theta_dot])
        start = "given"
    else:
        pmap = make_map(params, model.value, backend=backend.value, rtol=rtol)
        jf = jacobian_factory(backend.value)
        guess = _start_guess(params, model.value, theta_dot_guess=theta_dot_guess, theta_plus_guess=theta_plus_guess,
                             gait=gait, backend=backend.value, rtol=rtol)
        try:
            fp = solve_fixed_point(pmap, guess, jacobian=jf(pmap) if jf else None)
        except StepFailure as err:
            raise SimFailure(f"no fixed point to start from ({err}); give --theta-dot") from None
        z0 = fp.z
        start = "fixed point"
    from rich.progress import Progress

    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("simulating steps", total=steps)
        traj = simulate_steps(params, model.value, z0, steps, make_integrator(backend.value, rtol), record_dt=sample_dt_s,
                              forces=forces, progress=lambda k: prog.update(task, completed=k))
    if out is not None:
        from rimless.sim.step.gait import write_trajectory

        write_trajectory(traj, out, {"start": start, "backend": backend.value, "rtol": rtol})
    if plot is not None and traj.steps:
        from rimless.sim.studies.figures import plot_gait, save_figure

        save_figure(plot_gait(traj, None, forces=forces), plot)
    summary = {
        "model": model.value,
        "slope_rad": params.slope_rad,
        "k": params.k,
        "c": params.c,
        "start": start,
        "theta_plus_rad": float(z0[0]),
        "theta_dot_plus_rad_s": float(z0[1]),
        "steps_done": len(traj.steps),
        "steps_requested": steps,
        "step_periods_s": [s.period_s for s in traj.steps],
        "energy_ratios": [s.impact.energy_ratio for s in traj.steps],
        "failure": None if traj.failure is None else {"reason": traj.failure.reason.value, "message": str(traj.failure)},
        "out": str(out) if out else None,
        "plot": str(plot) if plot and traj.steps else None,
    }
    if json_out:
        print_json(summary)
    else:
        con = _console()
        con.print(_table(f"{model.value} gait from the {start}", [
            ("steps", f"{len(traj.steps)} of {steps}"),
            ("step periods (s)", ", ".join(f"{p:.4f}" for p in summary["step_periods_s"][:8])
             + (" ..." if len(traj.steps) > 8 else "")),
            ("energy ratios", ", ".join(f"{p:.4f}" for p in summary["energy_ratios"][:8])
             + (" ..." if len(traj.steps) > 8 else "")),
            ("trajectory", summary["out"] or "-"),
            ("figure", summary["plot"] or "-"),
        ]))
        if traj.failure is not None:
            con.print(f"[yellow]the walk ended early: {traj.failure}[/yellow]")
    if traj.failure is not None and not traj.steps:
        raise typer.Exit(1)


def _floats(text: str, name: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ParameterError(f"{name} must be comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise ParameterError(f"{name} must be finite numbers, got {text!r}")
    return values


@app.command("stress")
@user_facing
@sim_failures
@wheel_params
def stress_cmd(
    params: Any,
    k_values: Annotated[str, typer.Option("--k-values", help="Stiffnesses to sweep, N/m, comma-separated.")] =
        "300,1000,2700,1e4,1e5,1e6",
    c_values: Annotated[str, typer.Option("--c-values", help="Dampings, N s/m.")] = "0,2,8,100",
    slopes_deg: Annotated[str, typer.Option("--slopes-deg", help="Slopes, deg (each < 22.5).")] = "0.06,1.15,2.86,8.6,22.2",
    mass_ratios: Annotated[str, typer.Option("--mass-ratios", help="Leg-to-hub mass ratios m/m_H.")] = "0.002,0.02,0.2",
    rtol: RtolOpt = 1e-8,
    json_out: JsonOpt = False,
) -> None:
    """Stress the compiled step map over a parameter grid: every point valid or a classified failure."""
    from rich.progress import Progress

    from rimless.sim.model.params import SPOKE_ANGLE_RAD
    from rimless.sim.studies.stress import stress_sweep

    slopes = [math.radians(v) for v in _floats(slopes_deg, "--slopes-deg")]
    if not all(0 <= s < SPOKE_ANGLE_RAD / 2 for s in slopes):
        raise ParameterError("--slopes-deg: every slope must be in [0, 22.5) deg")
    ks, cs, ratios = _floats(k_values, "--k-values"), _floats(c_values, "--c-values"), _floats(mass_ratios, "--mass-ratios")
    if min(ks) <= 0 or min(cs) < 0 or min(ratios) <= 0:
        raise ParameterError("need k > 0, c >= 0 and mass ratios > 0")
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("stress sweep", total=None)
        out = stress_sweep(params, k_values=ks, c_values=cs, slopes_rad=slopes, mass_ratios=ratios, rtol=rtol,
                           progress=lambda i, n: prog.update(task, completed=i, total=n))
    if json_out:
        print_json(out)
    else:
        from rich.table import Table

        reasons = sorted({r for m in out["counts"].values() for r in m})
        table = Table(title=f"stress sweep: {out['points']} steps in {out['seconds']:.1f} s (rtol {rtol:g})")
        table.add_column("outcome")
        for model in out["counts"]:
            table.add_column(model, justify="right")
        for r in reasons:
            table.add_row(r, *[str(out["counts"][m].get(r, 0)) for m in out["counts"]])
        _console().print(table)
        _console().print(f"max integrator steps in one step: {out['max_integrator_steps']}, slowest step "
                         f"{out['slowest_step_s'] * 1e3:.1f} ms, unclassified: {len(out['unclassified'])}")
    if out["unclassified"]:
        raise typer.Exit(1)


@user_facing
def bench_cmd(
    quick: Annotated[bool, typer.Option("--quick", help="Fewer tolerances and repetitions (under a minute).")] = False,
    plot: Annotated[Optional[Path], typer.Option("--plot", help="Write the work-precision figure (.png/.pdf/.svg).")] = None,
    json_out: JsonOpt = False,
) -> None:
    """Work-precision benchmark: the compiled map against solve_ivp RK45/DOP853, side by side in one run."""
    if plot is not None and plot.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise ParameterError(f"{plot}: the figure must end in .png, .pdf or .svg")
    if plot is not None:  # before minutes of work, not after
        from rimless.output import writable_dir

        writable_dir(plot.parent if str(plot.parent) else Path("."), option="--plot")
    from rich.progress import Progress

    from rimless.sim.studies.bench import format_table, plot_work_precision, run_bench

    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("benchmark (the full run takes minutes; --quick under one)", total=None)
        result = run_bench(quick, progress=lambda msg: prog.update(task, description=str(msg)))
    if plot is not None:
        from rimless.output import atomic_file

        with atomic_file(plot, option="--plot") as tmp:
            plot_work_precision(result, str(tmp))
    if json_out:
        print_json(result)
    else:
        typer.echo(format_table(result))
    if plot is not None:
        typer.echo(f"wrote {plot}", err=json_out)


@user_facing
@sim_failures
@wheel_params(exclude=("k",))
def paper_cmd(
    params: Any,
    out: Annotated[Path, typer.Option("--out", metavar="DIR", help="Folder for the figures, CSVs and index.html.")] =
        Path("rimless-paper"),
    k_grid: Annotated[str, typer.Option("--k", metavar="START:STOP:STEP", help="Stiffness grid of the sweep, N/m.")] =
        "1500:3500:250",
    scheduler: Annotated[str, typer.Option("--scheduler", metavar="local|sync|tcp://HOST:8786",
                                           help="Where the sweep's grid points run.")] = "local",
    workers: Annotated[Optional[int], typer.Option("--workers", min=1, max=256, help="Local cluster worker "
                                                   "processes \\[default: one per core].")] = None,
    cache_dir: Annotated[Optional[Path], typer.Option("--cache-dir", help="Sweep result cache "
                                                      "[~/.cache/rimless/sweep].")] = None,
    no_cache: Annotated[bool, typer.Option("--no-cache", help="Recompute every sweep point.")] = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
) -> None:
    """Regenerate the paper's simulation figures (PNG, 150 dpi) with their CSVs, the headline table and an index."""
    from rich.progress import Progress

    from rimless.sim.studies.paper import EIGEN_K, ENERGY_K, run_paper
    from rimless.sim.studies.sweep import default_cache_dir, parse_range

    ks = tuple(parse_range(k_grid, "--k"))
    for k in ks:
        try:
            params.replace(stiffness_n_per_m=k)
        except ParameterError as err:
            raise ParameterError(f"--k {k:g}: {err}") from None
    if not (scheduler in ("local", "sync") or scheduler.startswith(("tcp://", "tls://"))):
        raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {out}: exists and is not a folder")
    out_is_new = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ParameterError(f"--out {out}: cannot create the folder ({err.strerror})") from None
    if not no_cache and cache_dir is not None:
        from rimless.output import writable_dir

        writable_dir(cache_dir, option="--cache-dir")
    eigen_ks = tuple(k for k in EIGEN_K if k in ks) or ks[: min(3, len(ks))]
    energy_ks = tuple(k for k in ENERGY_K if k in ks) or ks[: min(4, len(ks))]
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("paper", total=None)
        try:
            res = run_paper(out, params, ks=ks, backend=backend.value, rtol=rtol, scheduler=scheduler, workers=workers,
                            cache_dir=None if no_cache else (cache_dir or default_cache_dir()), energy_ks=energy_ks,
                            eigen_ks=eigen_ks, progress=lambda msg: prog.update(task, description=msg))
        except ConnectionError as err:
            raise ParameterError(f"--scheduler: {err}") from None
        except BaseException as err:
            from rimless.errors import interrupted_by_user

            if out_is_new and interrupted_by_user(err):  # an interrupted run leaves no half-filled folder behind
                import shutil

                shutil.rmtree(out, ignore_errors=True)
            raise
    summary = {"out": str(out), "files": [str(f) for f in res.files], "table": res.table, "timings_s": res.timings_s,
               "sweep": {"computed": res.sweep.computed, "cached": res.sweep.cached, "workers": res.sweep.workers}}
    if json_out:
        print_json(summary)
        return
    from rich.table import Table

    table = Table(title="the paper's headline numbers beside ours", show_lines=True)
    for col in ("quantity", "paper", "ours"):
        table.add_column(col, overflow="fold")
    for r in res.table:
        table.add_row(r["quantity"], r["paper"], r["ours"])
    con = _console()
    con.print(table)
    for f in res.files:
        con.print(f"wrote {f}", soft_wrap=True)
    con.print(f"load average {res.timings_s['load_average_before']:.1f} before, "
              f"{res.timings_s['load_average_after']:.1f} after (other work on the machine slows every timing)", soft_wrap=True)
    con.print(f"in {res.timings_s['total']:.1f} s (sweep {res.timings_s['sweep']:.1f} s: {res.sweep.computed} grid "
              f"points computed, {res.sweep.cached} cached, {res.sweep.workers} worker(s))", soft_wrap=True)


def register_top_level(root: typer.Typer) -> None:
    """Commands that live at the top level (`rimless bench`, `rimless paper`)."""
    root.command("bench")(bench_cmd)
    root.command("paper")(paper_cmd)


class Scheduler(str, Enum):
    local = "local"
    sync = "sync"


_SWEEP_COLUMNS = (("model", 5), ("k", 6), ("branch", 13), ("stable", 6), ("valid", 5), ("phi_c deg", 9),
                  ("ends by", 17), ("CoT", 6))


@app.command("firmware-sweep")
@user_facing
@sim_failures
@wheel_params
def firmware_sweep_cmd(
    params: Any,
    rates_hz: Annotated[str, typer.Option("--rates-hz", help="Sensor rates, Hz (comma-separated or START:STOP:STEP).")]
    = "300,1000",
    delays_ms: Annotated[str, typer.Option("--delays-ms", help="Clutch engage = release delays, ms.")] = "0,5,10",
    steps: Annotated[int, typer.Option("--steps", min=6, max=200, help="Walk length per point.")] = 8,
    noise_counts: Annotated[float, typer.Option("--noise-counts", min=0.0, max=1000.0, help="Sensor noise, counts.")]
    = 1.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sensor noise and sampling jitter.")] = 0,
    scheduler: Annotated[str, typer.Option("--scheduler", help="sync, local (Dask LocalCluster) or tcp://HOST:PORT.")]
    = "local",
    workers: Annotated[Optional[int], typer.Option("--workers", min=1, max=256, help="Local Dask workers [cores].")]
    = None,
    plot: Annotated[Optional[Path], typer.Option("--plot", help="Write the figure: speed and stored energy against "
                                                 "delay, per rate (.png, .pdf, .svg).")] = None,
    json_out: JsonOpt = False,
) -> None:
    """Firmware in the loop over sensor rate and clutch delay: gait, speed and stored energy against the ideal clutch."""
    from rich.progress import Progress

    from rimless.sim.in_the_loop.sweep import plot_firmware_sweep, run_firmware_sweep
    from rimless.sim.studies.sweep import parse_range

    if plot is not None:
        _check_plot_path(plot)

    rates = parse_range(rates_hz, "--rates-hz")
    delays = parse_range(delays_ms, "--delays-ms")
    if any(not 1.0 <= r <= 1e6 for r in rates):
        raise ParameterError(f"--rates-hz must be rates in [1, 1e6] Hz, got {rates_hz!r}")
    if any(not 0.0 <= d <= 1000.0 for d in delays):
        raise ParameterError(f"--delays-ms must be delays in [0, 1000] ms, got {delays_ms!r}")
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("firmware sweep", total=len(rates) * len(delays))
        out = run_firmware_sweep(params, rates, [d * 1e-3 for d in delays], steps=steps, noise_counts=noise_counts,
                                 seed=seed, scheduler=scheduler, workers=workers,
                                 progress=lambda n, total: prog.update(task, completed=n, total=total))
    out["plot"] = str(plot_firmware_sweep(out, plot)) if plot is not None else None
    if json_out:
        print_json(out)
        return
    if out["plot"]:
        print(f"wrote {out['plot']}")
    print(f"ideal clutch: theta'+ {out['ideal']['theta_dot_plus_rad_s']:.4f} rad/s, period "
          f"{out['ideal']['step_period_s']:.4f} s, stored {out['ideal']['stored_energy_J']:.4f} J")
    print(f"{'rate_hz':>8} {'delay_ms':>8} {'walks':>5} {'period_s':>8} {'speed/ideal':>11} {'stored/ideal':>12} "
          f"{'|eig|':>6}")
    for r in out["rows"]:
        if not r.get("steps_done"):
            print(f"{r['rate_hz']:>8g} {r['delay_ms']:>8g} {'no':>5}  {r.get('failure')}")
            continue
        eig = r["max_abs_eigenvalue_fitted"]
        print(f"{r['rate_hz']:>8g} {r['delay_ms']:>8g} {'yes' if r['walks'] else 'no':>5} {r['step_period_s']:>8.4f} "
              f"{r['speed_ratio']:>11.3f} {r['stored_energy_ratio']:>12.3f} {'-' if eig is None else f'{eig:.3f}':>6}")
    print("speed: step length / period; stored: the stance spring's energy at touchdown; |eig|: fitted to the walk.")


def _check_plot_path(plot: Path) -> None:
    """Refuse a --plot path that cannot be written before any work is done."""
    import os

    from rimless.errors import OutputFileError

    if plot.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise ParameterError(f"{plot}: the file must end in .png, .pdf or .svg")
    parent = plot.parent if str(plot.parent) else Path(".")
    if not (parent.is_dir() and os.access(parent, os.W_OK | os.X_OK)):
        raise OutputFileError(f"--plot {plot}: the folder {parent} does not exist or is not writable")


@app.command("replay")
@user_facing
@sim_failures
@wheel_params
def replay_cmd(
    params: Any,
    log: Annotated[Path, typer.Argument(help="Trial log of `rimless robot run` (JSON Lines).")],
    plot: Annotated[Optional[Path], typer.Option("--plot", help="Write the overlay figure (.png, .pdf, .svg).")] = None,
    rate_hz: Annotated[Optional[float], typer.Option("--rate-hz", help="Firmware in the loop: sampling rate, Hz "
                                                     "[300, or the --robot-config's].")] = None,
    clutch_delay_ms: Annotated[float, typer.Option("--clutch-delay-ms", help="Firmware in the loop: clutch engage "
                                                   "= release delay, ms.")] = 5.0,
    noise_counts: Annotated[float, typer.Option("--noise-counts", help="Firmware in the loop: sensor noise, "
                                                "counts.")] = 1.0,
    robot_config: Annotated[Optional[Path], typer.Option("--robot-config", help="The robot.toml the trial ran with "
                                                         "(detector, sensor and rate settings).")] = None,
    ideal_only: Annotated[bool, typer.Option("--ideal-only", help="Compare with the ideal clutch only (skip the "
                                             "firmware-in-the-loop step).")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Replay a robot trial log against the simulator: recorded steps beside the simulated ER step, under the
    ideal clutch and under the firmware in the loop."""
    from rimless.firmware.service.triallog import TrialLogError
    from rimless.sim.in_the_loop.replay import plot_replay, replay_trial

    if not log.is_file():
        raise ParameterError(f"{log}: no such trial log")
    if plot is not None:
        _check_plot_path(plot)
    fw_config = None
    if not ideal_only:
        from rimless.sim.cli import firmware as firmware_cli

        if robot_config is not None and not robot_config.is_file():
            raise ParameterError(f"--robot-config {robot_config}: no such file")
        fw_config = firmware_cli.build_config(rate_hz=rate_hz, clutch_delay_ms=clutch_delay_ms, release_delay_ms=None,
                                              noise_counts=noise_counts, jitter_ms=0.05, holding_force_n=100.0, seed=0,
                                              robot_config=robot_config)
    try:
        rep = replay_trial(log, params, firmware_config=fw_config)
    except TrialLogError as err:
        raise ParameterError(str(err)) from None
    except ValueError as err:
        raise SimFailure(str(err)) from None
    out = rep.summary()
    out["plot"] = str(plot_replay(rep, plot)) if plot is not None else None
    if json_out:
        print_json(out)
        return

    def f(v: Any, scale: float = 1.0) -> str:
        return "-" if v is None else f"{v * scale:.4g}"

    _console().print(_table(f"replay of {log.name}", [
        ("recorded steps", str(out["steps"])),
        ("step period recorded mean / simulated (s)", f"{f(out['recorded_period_s']['mean'])} / "
                                                      f"{f(out['simulated_period_s'])}"),
        ("lock after touchdown recorded / peak simulated (ms)",
         f"{f(out['recorded_lock_after_touchdown_s']['mean'], 1e3)} / {f(out['simulated_peak_after_impact_s'], 1e3)}"),
        ("max compression recorded / simulated (mm)", f"{f(out['recorded_max_compression_m'], 1e3)} / "
                                                      f"{f(out['simulated_max_compression_m'], 1e3)}"),
        ("faults in the log", ", ".join(out["faults"]) or "none"),
        *_replay_firmware_rows(out["firmware_in_the_loop"], f),
        ("figure", out["plot"] or "-"),
    ]))
    if out["plot"]:
        print(out["plot"])


def _replay_firmware_rows(fw: Optional[dict[str, Any]], f: Any) -> list[tuple[str, str]]:
    if fw is None:
        return []
    if fw["simulated_period_s"] is None:
        return [("firmware in the loop", f"the walk failed: {fw['failure']}")]
    return [
        ("firmware in the loop: rate, delay", f"{fw['rate_hz']:g} Hz, {fw['engage_delay_ms']:g} ms"),
        ("  step period (s)", f(fw["simulated_period_s"])),
        ("  lock command / engaged after impact (ms)",
         f"{f(fw['lock_command_after_impact_s'], 1e3)} / {f(fw['lock_after_impact_s'], 1e3)} ({fw['lock_class']})"),
        ("  max compression (mm)", f(fw["max_compression_m"], 1e3)),
    ]


@app.command("sweep")
@user_facing
@sim_failures
@wheel_params(exclude=("k", "c", "leg_mass_kg", "hub_mass_kg", "mass_model"))
def sweep_cmd(
    params: Any,
    models: Annotated[str, typer.Option("--model", metavar="er,ve", help="Models, comma-separated: er, ve.")] = "er,ve",
    k_grid: Annotated[Optional[str], typer.Option("--k", metavar="START:STOP:STEP|a,b", help="Stiffness grid, N/m: START:STOP:STEP or a,b,c.")] = None,
    c_grid: Annotated[Optional[str], typer.Option("--c", metavar="START:STOP:STEP|a,b", help="Damping grid, N s/m: START:STOP:STEP or a,b,c.")] = None,
    leg_mass_grid: Annotated[Optional[str], typer.Option("--leg-mass-kg", metavar="START:STOP:STEP|a,b", help="Leg mass grid, kg.")] = None,
    hub_mass_grid: Annotated[Optional[str], typer.Option("--hub-mass-kg", metavar="START:STOP:STEP|a,b", help="Hub mass grid, kg.")] = None,
    mass_models: Annotated[Optional[str], typer.Option("--mass-model", metavar="NAME[,NAME]", help="Mass models, comma-separated "
                                                      "(eight-leg, sliding-leg, active-feet).")] = None,
    start_slope_rad: Annotated[float, typer.Option(help="Slope where the gaits are searched, rad.")] = 0.05,
    guesses: Annotated[int, typer.Option(min=2, max=200, help="Number of theta'+ guesses in the gait search.")] = 14,
    out: Annotated[Path, typer.Option("--out", metavar="STEM", help="Output stem: writes STEM.parquet, STEM.csv "
                                      "and STEM-points.parquet/.csv (branch points).")] = Path("rimless-sweep/sweep"),
    scheduler: Annotated[str, typer.Option("--scheduler", metavar="local|sync|tcp://HOST:8786",
                                           help="Where grid points run: a local Dask cluster, this process, or "
                                                "a running Dask scheduler.")] = "local",
    workers: Annotated[Optional[int], typer.Option("--workers", min=1, max=256, help="Local cluster worker "
                                                   "processes \\[default: one per core].")] = None,
    cache_dir: Annotated[Optional[Path], typer.Option("--cache-dir", help="Per-point result cache "
                                                      "[~/.cache/rimless/sweep].")] = None,
    no_cache: Annotated[bool, typer.Option("--no-cache", help="Recompute every point and store nothing.")] = False,
    bench: Annotated[bool, typer.Option("--bench", help="Benchmark instead: the grid (no cache) in-process, on 1 and "
                                        "on 2 workers, and the branch-end location by pseudo-arclength against "
                                        "bisection (takes minutes).")] = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    clutch: Annotated[ClutchKind, typer.Option("--clutch", help="ideal: the branch sweep; firmware: the robot's "
                                               "controller in the loop over --rate-hz x --clutch-delay-ms (ER, "
                                               "at --slope-deg).")] = ClutchKind.ideal,
    fw_rate_hz: Annotated[Optional[str], typer.Option("--rate-hz", metavar="START:STOP:STEP|a,b", help="With "
                                                      "--clutch firmware: sensor rates, Hz [300,1000].")] = None,
    fw_delay_ms: Annotated[Optional[str], typer.Option("--clutch-delay-ms", metavar="START:STOP:STEP|a,b",
                                                       help="With --clutch firmware: clutch engage = release "
                                                            "delays, ms [0:10:2.5].")] = None,
    fw_noise: Annotated[Optional[float], typer.Option("--noise-counts", help="With --clutch firmware: sensor "
                                                      "noise, counts [1].")] = None,
    fw_steps: Annotated[int, typer.Option("--steps", min=6, max=200, help="With --clutch firmware: walk length "
                                          "per point.")] = 8,
    fw_seed: Annotated[int, typer.Option("--seed", help="With --clutch firmware: seed of the sensor noise and "
                                         "sampling jitter.")] = 0,
    fw_critical: Annotated[bool, typer.Option("--critical-slope/--no-critical-slope", help="With --clutch "
                                              "firmware: bisect each point's critical slope (and the ideal ER and VE "
                                              "references) for the CoT and the share of the ER advantage kept "
                                              "(a few walks per point).")] = False,
    fw_low_deg: Annotated[float, typer.Option("--critical-low-deg", help="With --critical-slope: low end of the "
                                              "bisection, deg.")] = 0.5,
    fw_plot: Annotated[Optional[Path], typer.Option("--plot", help="With --clutch firmware: write the figure "
                                                    "(.png, .pdf, .svg): the ER advantage, stored energy and "
                                                    "stability kept against delay, per rate.")] = None,
    json_out: JsonOpt = False,
) -> None:
    """Sweep a parameter grid: every period-1 gait at the start slope, each branch continued down to its end.

    Table columns: stable = orbitally stable at the start slope (max |eig| < 1); valid = unilateral contact (stance force >= 0 in single support, impulses > 0); phi_c = critical slope of the branch (end of its stable, valid part); CoT = tan(phi_c)."""
    from rich.progress import Progress

    from rimless.sim.integrate.backend import resolve
    from rimless.sim.model.params import MASS_MODELS, SPOKE_ANGLE_RAD
    from rimless.sim.studies.sweep import GRID_PARAMETERS, SweepOptions, grid_points, parse_range, run_sweep, write_table

    if fw_plot is not None:
        _check_plot_path(fw_plot)
    if clutch is ClutchKind.firmware:
        _firmware_sweep_dispatch(params, locals())
        return
    for flag, given in (("--rate-hz", fw_rate_hz), ("--clutch-delay-ms", fw_delay_ms), ("--noise-counts", fw_noise),
                        ("--plot", fw_plot), ("--critical-slope", fw_critical or None)):
        if given is not None:
            raise ParameterError(f"{flag} {given}: needs --clutch firmware")
    model_list = [m.strip().lower() for m in models.split(",") if m.strip()]
    if not model_list or any(m not in ("er", "ve") for m in model_list):
        raise ParameterError(f"--model must be er, ve or er,ve, got {models!r}")
    mm = [m.strip() for m in (mass_models or params.mass_model).split(",") if m.strip()]
    if not mm or any(m not in MASS_MODELS for m in mm):
        raise ParameterError(f"--mass-model must be among {', '.join(MASS_MODELS)}, got {mass_models!r}")
    if not 0 < start_slope_rad < SPOKE_ANGLE_RAD / 2:
        raise ParameterError(f"--start-slope-rad must be in (0, {SPOKE_ANGLE_RAD / 2:.4f}) rad, got {start_slope_rad}")
    if not (scheduler in ("local", "sync") or scheduler.startswith(("tcp://", "tls://"))):
        raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
    grid: dict[str, list[float]] = {}
    for name, text, option in (("k", k_grid, "--k"), ("c", c_grid, "--c"), ("leg_mass_kg", leg_mass_grid, "--leg-mass-kg"),
                               ("hub_mass_kg", hub_mass_grid, "--hub-mass-kg")):
        if text is not None:
            grid[name] = parse_range(text, option)
            field_name = GRID_PARAMETERS[name][0]
            for v in grid[name]:
                try:
                    params.replace(**{field_name: v})
                except ParameterError as err:
                    raise ParameterError(f"{option} {v:g}: {err}") from None
    if not grid:
        grid["k"] = [params.k]
    options = SweepOptions(backend=resolve(backend.value), rtol=rtol, start_slope_rad=start_slope_rad,
                           n_guesses=guesses)
    points = grid_points(params, model_list, grid, mm)
    if bench:
        from rimless.sim.studies.sweepbench import branch_end_bench, format_bench, sweep_bench

        with Progress(transient=True, console=_err_console()) as prog:
            prog.add_task("benchmark (minutes): sweep on each scheduler, then branch ends", total=None)
            result = {"sweep": sweep_bench(points, options), "branch_end": branch_end_bench(params)}
        if json_out:
            print_json(result)
        else:
            typer.echo(format_bench(result))
        return
    cache = None if no_cache else (cache_dir or __import__("rimless.sim.studies.sweep", fromlist=["x"]).default_cache_dir())
    if cache is not None:
        from rimless.output import writable_dir

        writable_dir(cache, option="--cache-dir")
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task(f"sweep: {len(points)} grid points", total=len(points))
        try:
            res = run_sweep(points, options, scheduler=scheduler, workers=workers, cache_dir=cache,
                            progress=lambda i, n: prog.update(task, completed=i, total=n))
        except ConnectionError as err:
            raise ParameterError(f"--scheduler: {err}") from None
    meta = {"grid": grid, "models": model_list, "mass_models": mm, "options": options.__dict__,
            "base_params": params.to_dict(), "scheduler": scheduler}
    if not res.rows:
        raise SimFailure("the sweep produced no rows")
    paths = write_table(res.rows, out, meta)
    if res.points:
        paths += write_table(res.points, out.with_name(out.name + "-points"), meta)
    summary = {"rows": res.rows, "files": [str(p) for p in paths], "seconds": res.seconds, "computed": res.computed,
               "cached": res.cached, "scheduler": scheduler, "workers": res.workers, "grid": grid}
    if json_out:
        print_json(summary)
        return
    _print_sweep_table(res.rows)
    con = _console()
    for p in paths:
        con.print(f"wrote {p}", soft_wrap=True)
    con.print(f"{len(points)} grid points ({res.computed} computed, {res.cached} from the cache) in {res.seconds:.1f} s "
              f"on {res.workers} worker(s), scheduler {scheduler}", soft_wrap=True)


def _firmware_sweep_dispatch(params: Any, opts: dict[str, Any]) -> None:
    """`sweep --clutch firmware`: refuse the branch grid's options, then rimless.sim.cli.firmware."""
    from rimless.sim.cli import firmware as firmware_cli
    from rimless.sim.studies.sweep import GRID_PARAMETERS, default_cache_dir, parse_range

    models = [m.strip().lower() for m in opts["models"].split(",") if m.strip()]
    if "er" not in models:
        raise ParameterError(f"--model: --clutch firmware drives the ER wheel's clutches, got {opts['models']!r}")
    changes: dict[str, float] = {}
    for name, key, option in (("k", "k_grid", "--k"), ("c", "c_grid", "--c"), ("leg_mass_kg", "leg_mass_grid",
                              "--leg-mass-kg"), ("hub_mass_kg", "hub_mass_grid", "--hub-mass-kg")):
        if opts[key] is not None:
            values = parse_range(opts[key], option)
            if len(values) != 1:
                raise ParameterError(f"{option}: --clutch firmware sweeps --rate-hz x --clutch-delay-ms at one wheel; "
                                     f"give one value, got {opts[key]!r}")
            changes[GRID_PARAMETERS[name][0]] = values[0]
    if opts["mass_models"] is not None:
        if "," in opts["mass_models"]:
            raise ParameterError(f"--mass-model: --clutch firmware takes one mass model, got {opts['mass_models']!r}")
        changes["mass_model"] = opts["mass_models"].strip()
    try:
        params = params.replace(**changes)
    except ParameterError as err:
        raise ParameterError(f"{err}") from None
    if opts["fw_plot"] is not None:
        _check_plot_path(opts["fw_plot"])
    if opts["bench"]:
        firmware_cli.run_bench(params, json_out=opts["json_out"])
        return
    scheduler = opts["scheduler"]
    if not (scheduler in ("local", "sync") or scheduler.startswith(("tcp://", "tls://"))):
        raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
    cache = None if opts["no_cache"] else (opts["cache_dir"] or default_cache_dir())
    firmware_cli.run_sweep_command(
        params, rate_hz=opts["fw_rate_hz"], clutch_delay_ms=opts["fw_delay_ms"], noise_counts=opts["fw_noise"],
        steps=opts["fw_steps"], seed=opts["fw_seed"], critical_slope=opts["fw_critical"],
        critical_low_deg=opts["fw_low_deg"], out=opts["out"], scheduler=scheduler, workers=opts["workers"],
        cache_dir=cache, plot=opts["fw_plot"], json_out=opts["json_out"])


def _err_console():  # noqa: ANN202
    from rich.console import Console

    return Console(stderr=True)


def _print_sweep_table(rows: list[dict[str, Any]]) -> None:
    """One line per (grid point, branch) in 80 columns; the reasons' details go under the table."""
    from rich.table import Table

    table = Table(show_header=True, header_style="bold", box=None, padding=(0, 1), pad_edge=False)
    for name, width in _SWEEP_COLUMNS:
        table.add_column(name, justify="right" if name not in ("model", "branch", "ends by") else "left",
                         min_width=min(width, len(name)), no_wrap=True)
    notes = []
    for r in rows:
        crit = r.get("critical_slope_deg")
        crit_txt = f"{crit:.4f}" if isinstance(crit, float) and crit == crit else "-"
        cot = r.get("cot")
        table.add_row(r["model"], f"{r['k']:g}", str(r.get("branch", ""))[:13],
                      "yes" if r.get("stable_at_start") else "no", "yes" if r.get("contact_valid_at_start") else "no",
                      crit_txt, str(r.get("reason", ""))[:17], f"{cot:.4f}" if isinstance(cot, float) and cot == cot else "-")
        if r.get("contact_reason"):
            notes.append(f"{r['model']} k={r['k']:g} {r.get('branch')}: not contact-valid: {r['contact_reason']}")
    _console().print(table)
    for n in notes:
        _console().print(n, soft_wrap=True)
