"""Wheel parameters: a frozen, validated dataclass whose defaults are the paper's Table 1.

All fields are SI (kg, m, s, rad); the slope is the only angle, in radians. Degrees appear only at the
CLI edge (`--slope-deg`).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from rimless.errors import InputFileError, ParameterError

N_LEGS = 8
SPOKE_ANGLE_RAD = 2.0 * math.pi / N_LEGS  # alpha = pi/4

MASS_MODELS = ("eight-leg", "sliding-leg", "active-feet")


@dataclass(frozen=True)
class WheelParams:
    """Physical parameters of the rimless wheel (paper Table 1 by default).

    Attributes
    ----------
    hub_mass_kg : m_H, mass of the main body.
    leg_mass_kg : m, mass of one leg.
    inertia_kg_m2 : I_c, the hub body's inertia about its centre.
    leg_length_m : L0, free (uncompressed) leg length.
    stiffness_n_per_m : k, leg spring stiffness.
    damping_ns_per_m : c, leg damping coefficient.
    slope_rad : phi, slope angle, 0 <= phi < alpha/2.
    gravity_m_s2 : g.
    mass_model : how the legs' mass enters T and V (model.md section 8).
    guide_friction_n : F_c, Coulomb friction force of each sliding leg's linear guide, N (0: none, the
        paper's model; rimless.sim.model.friction and docs/simulator.md "Guide friction").
    """

    hub_mass_kg: float = 1.892
    leg_mass_kg: float = 0.0378
    inertia_kg_m2: float = 0.036
    leg_length_m: float = 0.237
    stiffness_n_per_m: float = 2700.0
    damping_ns_per_m: float = 8.0
    slope_rad: float = 0.05
    gravity_m_s2: float = 9.81
    mass_model: str = "eight-leg"
    guide_friction_n: float = 0.0

    def __post_init__(self) -> None:
        validate(self)

    @property
    def k(self) -> float:
        return self.stiffness_n_per_m

    @property
    def c(self) -> float:
        return self.damping_ns_per_m

    @property
    def slope_deg(self) -> float:
        return math.degrees(self.slope_rad)

    @property
    def alpha(self) -> float:
        return SPOKE_ANGLE_RAD

    @property
    def total_mass_kg(self) -> float:
        return self.hub_mass_kg + N_LEGS * self.leg_mass_kg

    def replace(self, **changes: Any) -> WheelParams:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def as_vector(self) -> tuple[float, ...]:
        """(m_H, m, I_c, L0, k, c, g, phi): the order the generated code expects."""
        return (
            self.hub_mass_kg,
            self.leg_mass_kg,
            self.inertia_kg_m2,
            self.leg_length_m,
            self.stiffness_n_per_m,
            self.damping_ns_per_m,
            self.gravity_m_s2,
            self.slope_rad,
        )

    def to_dict(self) -> dict[str, Any]:
        """The fields as a dict; guide_friction_n only when it is not 0 (so that every record and cache key
        of the frictionless wheel stays as it was)."""
        d = dataclasses.asdict(self)
        if d["guide_friction_n"] == 0.0:
            del d["guide_friction_n"]
        return d


_FIELDS = tuple(f.name for f in dataclasses.fields(WheelParams))
_POSITIVE = ("hub_mass_kg", "leg_mass_kg", "inertia_kg_m2", "leg_length_m", "stiffness_n_per_m", "gravity_m_s2")


# How each field is called on the command line (and in the paper), for error messages.
OPTION_OF_FIELD = {
    "hub_mass_kg": "--hub-mass-kg (m_H)",
    "leg_mass_kg": "--leg-mass-kg (m)",
    "inertia_kg_m2": "--inertia-kg-m2 (I_c)",
    "leg_length_m": "--leg-length-m (L0)",
    "stiffness_n_per_m": "--k",
    "damping_ns_per_m": "--c",
    "slope_rad": "--slope-rad/--slope-deg (phi)",
    "gravity_m_s2": "--g",
    "mass_model": "--mass-model",
    "guide_friction_n": "--guide-friction-n (F_c)",
}


def validate(p: Any, spelled: dict[str, str] | None = None) -> None:
    """Raise ParameterError naming the first invalid parameter of `p` (a `WheelParams`, or any object with its
    fields): by its field and command-line option, or with ``spelled`` (a parameter file's keys as written,
    field -> key) by the file's key, since no option was given."""

    def _name(field: str) -> str:
        if spelled is not None:
            return spelled.get(field, field)
        return f"{field} [{OPTION_OF_FIELD[field]}]"

    for name in _FIELDS:
        if name == "mass_model":
            continue
        value = getattr(p, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"parameter {_name(name)} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ParameterError(f"parameter {_name(name)} must be finite, got {value}")
    for name in _POSITIVE:
        if getattr(p, name) <= 0.0:
            raise ParameterError(f"parameter {_name(name)} must be > 0, got {getattr(p, name)}")
    if p.damping_ns_per_m < 0.0:
        raise ParameterError(f"parameter {_name('damping_ns_per_m')} must be >= 0, got {p.damping_ns_per_m}")
    if p.guide_friction_n < 0.0:
        raise ParameterError(f"parameter {_name('guide_friction_n')} must be >= 0, got {p.guide_friction_n}")
    if not 0.0 <= p.slope_rad < SPOKE_ANGLE_RAD / 2.0:
        if spelled is not None and spelled.get("slope_rad") == "slope_deg":  # a file's slope_deg, in its unit
            raise ParameterError(
                f"parameter slope_deg must satisfy 0 <= slope < alpha/2 = {math.degrees(SPOKE_ANGLE_RAD / 2):.1f} "
                f"deg, got {math.degrees(p.slope_rad):.10g} deg"
            )
        raise ParameterError(
            f"parameter {_name('slope_rad')} must satisfy 0 <= slope < alpha/2 = {SPOKE_ANGLE_RAD / 2:.6f} rad "
            f"({math.degrees(SPOKE_ANGLE_RAD / 2):.1f} deg), got {p.slope_rad} rad"
        )
    if p.mass_model not in MASS_MODELS:
        raise ParameterError(
            f"parameter {_name('mass_model')} must be one of {', '.join(MASS_MODELS)}, got {p.mass_model!r}"
        )


# Names accepted in a TOML parameter file, mapped to fields. Paper symbols are accepted as aliases.
_ALIASES = {
    "m_H": "hub_mass_kg",
    "hub_mass_kg": "hub_mass_kg",
    "m": "leg_mass_kg",
    "leg_mass_kg": "leg_mass_kg",
    "I_c": "inertia_kg_m2",
    "inertia_kg_m2": "inertia_kg_m2",
    "L0": "leg_length_m",
    "leg_length_m": "leg_length_m",
    "k": "stiffness_n_per_m",
    "stiffness_n_per_m": "stiffness_n_per_m",
    "c": "damping_ns_per_m",
    "damping_ns_per_m": "damping_ns_per_m",
    "phi": "slope_rad",
    "slope_rad": "slope_rad",
    "g": "gravity_m_s2",
    "gravity_m_s2": "gravity_m_s2",
    "mass_model": "mass_model",
    "F_c": "guide_friction_n",
    "guide_friction_n": "guide_friction_n",
}


#: The names a parameter file may use (field names and the paper's symbols) -> fields.
PARAM_ALIASES = _ALIASES


def in_source(source: str) -> str:
    """Where a bad value was read, as every parameter error names it (a wheel file for `rimless sim --params` and
    the trials commands alike): `` in <file>``, empty without a source."""
    return f" in {source}" if source else ""


def params_from_mapping(
    values: dict[str, Any], *, base: WheelParams | None = None, source: str = "", name_keys: bool = False
) -> WheelParams:
    """Build parameters from a mapping of field names or paper symbols (`slope_deg` accepted). An invalid value
    is named by its field and `rimless sim` option, or with ``name_keys`` (a parameter file) by its key as the
    mapping spells it."""
    where = in_source(source)
    changes: dict[str, Any] = {}
    spelled: dict[str, str] = {}  # field -> the key as the mapping spells it (error messages name it)
    for key, value in values.items():
        if key == "slope_deg":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParameterError(f"parameter slope_deg{where} must be a number, got {value!r}")
            changes["slope_rad"] = math.radians(value)
            spelled["slope_rad"] = key
        elif key in _ALIASES:
            changes[_ALIASES[key]] = value
            spelled[_ALIASES[key]] = key
        else:
            known = ", ".join(sorted(set(_ALIASES) | {"slope_deg"}))
            raise ParameterError(f"unknown parameter {key!r}{where}; known: {known}")
    if "slope_deg" in values and ("slope_rad" in values or "phi" in values):
        raise ParameterError(f"give the slope once{where}: slope_deg or slope_rad, not both")
    base = base or WheelParams()
    try:  # a file's values checked first with its keys as names (no `rimless sim` option was given)
        if name_keys:
            validate(SimpleNamespace(**{**{f: getattr(base, f) for f in _FIELDS}, **changes}), spelled)
        return dataclasses.replace(base, **changes)
    except ParameterError as err:
        raise ParameterError(f"{err}{where}") from None


def load_params(path: str | Path, *, base: WheelParams | None = None) -> WheelParams:
    """Read a TOML parameter file; its keys may sit at top level or under a [wheel] table (uncertainties, if
    any, are ignored here: `rimless.sim.model.uncertain.read_wheel_input` reads them)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise InputFileError(f"cannot read parameter file {path}: {err.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise InputFileError(f"{path}: not valid TOML: {err}") from None
    if "wheel" in data and isinstance(data["wheel"], dict):
        data = data["wheel"]
    # a wheel file with uncertainties (`rimless.sim.model.uncertain`): {value, sd} tables give their value, a
    # parameter marked "fit" (or given only an sd) keeps the base's value
    data = {
        k: (v["value"] if isinstance(v, dict) else v)
        for k, v in data.items()
        if not (v == "fit" or (isinstance(v, dict) and "value" not in v))
    }
    return params_from_mapping(data, base=base, source=str(path), name_keys=True)
