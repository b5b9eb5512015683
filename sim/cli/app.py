"""The `rimless sim` typer app and what its commands share: the wheel-parameter options (`wheel_params`),
the option types, the choices, and the checks of output paths and schedulers made before any work."""

import functools
import inspect
import math
import os
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.errors import OutputFileError, ParameterError

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
    ("k", float | None, "Leg spring stiffness k, N/m [Table 1: 2700]."),
    ("c", float | None, "Leg damping c, N s/m [Table 1: 8]."),
    ("slope_deg", float | None, "Slope, degrees [Table 1: 0.05 rad = 2.865 deg]."),
    ("slope_rad", float | None, "Slope, rad [Table 1: 0.05]."),
    ("hub_mass_kg", float | None, "Hub (main body) mass m_H, kg [1.892]."),
    ("leg_mass_kg", float | None, "Mass of one leg m, kg [0.0378]."),
    ("inertia_kg_m2", float | None, "Hub inertia I_c, kg m^2 [0.036]."),
    ("leg_length_m", float | None, "Free leg length L0, m [0.237]."),
    ("g", float | None, "Gravity, m/s^2 [9.81]."),
    ("mass_model", MassModel | None, "How the legs' mass enters the model (model.md section 8) [eight-leg]."),
    (
        "guide_friction_n",
        float | None,
        "Coulomb friction F_c of each sliding leg's linear guide, N, with stick "
        "phases (beyond the paper; docs/simulator.md) [0: none].",
    ),
    (
        "params_file",
        Path | None,
        "TOML file of parameters (keys: k, c, slope_deg or slope_rad, m_H, m, I_c, L0, g, "
        "mass_model, guide_friction_n); command-line options win.",
    ),
]
# commands whose work does not model guide friction (the firmware in the loop, the paper's fixed study) leave
# the option out: wheel_params(exclude=NO_FRICTION + ...)
NO_FRICTION = ("guide_friction_n",)
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
    for key in (
        "k",
        "c",
        "slope_deg",
        "slope_rad",
        "hub_mass_kg",
        "leg_mass_kg",
        "inertia_kg_m2",
        "leg_length_m",
        "g",
        "guide_friction_n",
    ):
        if values.get(key) is not None:
            mapping[key] = values[key]
    if values.get("mass_model") is not None:
        mapping["mass_model"] = values["mass_model"].value
    try:
        return params_from_mapping(mapping, base=base, source="the command-line options")
    except ParameterError as err:
        if values.get("slope_deg") is not None and "slope" in str(err):
            from rimless.sim.model.params import SPOKE_ANGLE_RAD

            raise ParameterError(
                f"--slope-deg must be a finite slope in [0, {math.degrees(SPOKE_ANGLE_RAD / 2):g}) deg, "
                f"got {values['slope_deg']:g} deg"
            ) from None
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
        extra.append(
            inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=None, annotation=Annotated[annotation, opt])
        )

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        values = {name: kwargs.pop(name, None) for name, _, _ in options}
        kwargs["params"] = build_params(values)
        if "guide_friction_n" in exclude and kwargs["params"].guide_friction_n > 0.0:
            raise ParameterError(
                "guide_friction_n (from --params) is not modelled by this command; "
                "guide friction is on sim fixed-point, gait, gaits and critical-slope"
            )
        return func(*args, **kwargs)

    params = own + extra
    wrapper.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in params}
    del wrapper.__wrapped__  # typer must read the new signature, not the wrapped one
    return wrapper


ModelOpt = Annotated[
    Model, typer.Option("--model", help="er: energy-recycling (spring-clutch legs); ve: viscoelastic.")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object instead of a table.")]
BackendOpt = Annotated[Backend, typer.Option("--backend", help="fast (compiled), reference (scipy solve_ivp) or auto.")]
RtolOpt = Annotated[float, typer.Option("--rtol", min=1e-13, max=1e-3, help="Integrator relative tolerance.")]
GuessOpt = Annotated[
    float | None, typer.Option("--theta-dot-guess", help="Initial guess of theta'+ (rad/s): picks the branch.")
]
ThetaGuessOpt = Annotated[
    float | None,
    typer.Option(
        "--theta-plus-guess", help="Initial guess of theta+ (rad), the post-impact stance angle [-alpha/2 - 0.07]."
    ),
]
GaitOpt = Annotated[
    int | None,
    typer.Option(
        "--gait",
        min=1,
        max=200,
        metavar="N",
        help="Start from gait N of `rimless sim gaits` (same parameters, numbered by step period) instead of a guess.",
    ),
]
StrictOpt = Annotated[
    bool,
    typer.Option(
        "--strict-contact",
        help="Reject gaits whose leading foot pulls on the ground in "
        "double support or whose lifted foot dips below the slope.",
    ),
]
HoldPowerOpt = Annotated[
    float,
    typer.Option(
        "--clutch-hold-power-w",
        rich_help_panel="Electrical power",
        help="Power the ER clutch draws while it holds (powered = locked), W.",
    ),
]
SwitchEnergyOpt = Annotated[
    float,
    typer.Option(
        "--clutch-switch-energy-j",
        rich_help_panel="Electrical power",
        help="Energy per clutch engage or release (two per step), J.",
    ),
]
ElectronicsPowerOpt = Annotated[
    float,
    typer.Option(
        "--electronics-power-w",
        rich_help_panel="Electrical power",
        help="Sensing and computing power over the whole step, W (ER; VE only with --ve-electronics).",
    ),
]
VeElectronicsOpt = Annotated[
    bool,
    typer.Option(
        "--ve-electronics/--no-ve-electronics",
        rich_help_panel="Electrical power",
        help="The VE wheel carries the same electronics (default: a passive VE wheel draws nothing).",
    ),
]


def clutch_power(hold_power_w: float, switch_energy_j: float, electronics_power_w: float, ve_electronics: bool) -> Any:
    """ClutchPower from the electrical options (validated; errors name the option)."""
    from rimless.sim.model.electrical import ClutchPower

    return ClutchPower(hold_power_w, switch_energy_j, electronics_power_w, ve_electronics)


def check_plot_path(plot: Path) -> None:
    """Refuse a --plot path that cannot be written before any work is done."""
    if plot.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise ParameterError(f"{plot}: the file must end in .png, .pdf or .svg")
    parent = plot.parent if str(plot.parent) else Path(".")
    if not (parent.is_dir() and os.access(parent, os.W_OK | os.X_OK)):
        raise OutputFileError(f"--plot {plot}: the folder {parent} does not exist or is not writable")


def option_given(name: str) -> bool:
    """True if the running command's parameter `name` (python name, e.g. "slope_deg") was given by the user."""
    from rimless.cli_rules import click

    ParameterSource = click.core.ParameterSource
    get_current_context = click.globals.get_current_context

    ctx = get_current_context(silent=True)
    if ctx is None:
        return False
    return ctx.get_parameter_source(name) in (ParameterSource.COMMANDLINE, ParameterSource.ENVIRONMENT)


def start_slope(params: Any, start_slope_rad: float | None) -> float:
    """The slope (rad) a search or continuation starts from: --start-slope-rad, else the wheel's slope
    (--slope-deg/--slope-rad/--params, Table 1 by default); both given is refused."""
    from rimless.sim.model.params import SPOKE_ANGLE_RAD

    slope_given = [f for f, n in (("--slope-deg", "slope_deg"), ("--slope-rad", "slope_rad")) if option_given(n)]
    if start_slope_rad is not None:
        if slope_given:
            raise ParameterError(f"give the start slope once: {slope_given[0]} or --start-slope-rad, not both")
        return start_slope_rad
    if not 0 < params.slope_rad < SPOKE_ANGLE_RAD / 2:
        flag = slope_given[0] if slope_given else "--slope-deg"
        raise ParameterError(
            f"{flag}: the search starts on a slope in (0, {math.degrees(SPOKE_ANGLE_RAD / 2):g}) "
            f"deg, got {params.slope_deg:g} deg"
        )
    return float(params.slope_rad)


def check_scheduler(scheduler: str) -> None:
    """--scheduler: local, sync or the address of a running Dask scheduler; --workers only with a local
    cluster; --cache-dir not with --no-cache (each checked where the command has the option)."""
    if not (scheduler in ("local", "sync") or scheduler.startswith(("tcp://", "tls://"))):
        raise ParameterError(f"--scheduler must be local, sync or tcp://HOST:PORT, got {scheduler!r}")
    if scheduler != "local" and option_given("workers"):
        raise ParameterError(
            f"--workers sets the size of a local cluster: it needs --scheduler local, got {scheduler!r}"
        )
    if option_given("cache_dir") and option_given("no_cache"):
        raise ParameterError("--cache-dir and --no-cache: give one or the other")


def refuse_unused(options: tuple[str, ...], why: str) -> None:
    """ParameterError naming the first of `options` (python names) the user gave: it would be ignored."""
    from rimless.cli_rules import click

    get_current_context = click.globals.get_current_context

    ctx = get_current_context(silent=True)
    for name in options:
        if option_given(name):
            param = next((p for p in (ctx.command.params if ctx else []) if p.name == name), None)
            longs = [o for o in getattr(param, "opts", []) if o.startswith("--")]
            raise ParameterError(f"{longs[0] if longs else '--' + name.replace('_', '-')} {why}")
