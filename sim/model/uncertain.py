"""The wheel as an uncertain input: every model parameter with a value, a 1-sigma uncertainty and its source.

A wheel file is the TOML of `rimless.sim.model.params.load_params` (keys at top level or under ``[wheel]``;
field names or the paper's symbols), where each parameter may be

- a plain number: that value, **exact** (sd 0), as before;
- a table with ``value`` and ``sd`` (1 sigma, same unit), e.g. ``k = {value = 2700, sd = 300}`` or
  ``[wheel.inertia_kg_m2]`` / ``value = 0.036`` / ``sd = 0.004``; ``sd`` alone keeps Table 1's value,
  ``value`` alone takes the default uncertainty (`DEFAULT_SD`) at that value;
- the string ``"fit"``: to be fitted on the trials (``trials calibrate``; its start is Table 1's value).

A parameter the file does not name keeps Table 1's value with the default uncertainty of `DEFAULT_SD`. Those
defaults are ASSUMED, NOT MEASURED: tolerances typical of such a prototype, stated so that every inference says
what it holds and how well it is known (docs/trials.md "The wheel is an input"). The slope is not a wheel
parameter here (each trial has its own) and the mass model is a choice, not a number: neither carries an sd.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.errors import InputFileError, ParameterError
from rimless.sim.model.params import PARAM_ALIASES, WheelParams, params_from_mapping

__all__ = [
    "DEFAULT_SD",
    "UNITS",
    "SYMBOLS",
    "UNCERTAIN_FIELDS",
    "ParamInput",
    "WheelInput",
    "default_wheel_input",
    "wheel_input_from",
    "read_wheel_input",
]

#: The model parameters that carry an uncertainty, in the order they are listed.
UNCERTAIN_FIELDS = (
    "hub_mass_kg",
    "leg_mass_kg",
    "inertia_kg_m2",
    "leg_length_m",
    "stiffness_n_per_m",
    "damping_ns_per_m",
    "guide_friction_n",
    "gravity_m_s2",
)
UNITS = {
    "hub_mass_kg": "kg",
    "leg_mass_kg": "kg",
    "inertia_kg_m2": "kg m^2",
    "leg_length_m": "m",
    "stiffness_n_per_m": "N/m",
    "damping_ns_per_m": "N s/m",
    "guide_friction_n": "N",
    "gravity_m_s2": "m/s^2",
}
SYMBOLS = {
    "hub_mass_kg": "m_H",
    "leg_mass_kg": "m",
    "inertia_kg_m2": "I_c",
    "leg_length_m": "L0",
    "stiffness_n_per_m": "k",
    "damping_ns_per_m": "c",
    "guide_friction_n": "F_c",
    "gravity_m_s2": "g",
}

#: Default 1-sigma uncertainty of each parameter when nothing better is given: (kind, size, basis). "rel" is a
#: fraction of the value, "abs" an amount in the parameter's unit. ASSUMED, NOT MEASURED.
DEFAULT_SD: dict[str, tuple[str, float, str]] = {
    "hub_mass_kg": ("rel", 0.02, "assumed, not measured: +-2 % for a weighed assembly (cables, fasteners)"),
    "leg_mass_kg": ("rel", 0.02, "assumed, not measured: +-2 % for a weighed part"),
    "inertia_kg_m2": ("rel", 0.10, "assumed, not measured: +-10 % for an inertia from CAD, not a swing test"),
    "leg_length_m": ("abs", 0.001, "assumed, not measured: +-1 mm machining and assembly tolerance"),
    "stiffness_n_per_m": ("rel", 0.10, "assumed, not measured: +-10 %, a stock spring's rate tolerance"),
    "damping_ns_per_m": ("rel", 0.50, "assumed, not measured: +-50 %, c is not measured on the prototype"),
    "guide_friction_n": ("abs", 0.2, "assumed, not measured: 0 +- 0.2 N (the paper's model has none)"),
    "gravity_m_s2": ("abs", 0.0, "exact: standard gravity (local variation below 0.1 %, neglected)"),
}

#: every parameter's physical lower bound (masses, lengths, k, g > 0; c, F_c >= 0): a held one's stated normal is
#: carried truncated there, named when that moves its mean by `TRUNCATION_NAMED` sd or more (the analysis's
#: `rimless.analysis.inference.held.LOWER_BOUND` and `TRUNCATION_NAMED`, which must agree)
LOWER_BOUND = 0.0
TRUNCATION_NAMED = 1e-3

#: What a parameter's value and sd came from (the ``source`` of each row of ``parameters``).
SOURCES = ("table1", "wheel_file", "wheel", "leg_test_prior", "fitted")


def default_sd(name: str, value: float) -> float:
    kind, size, _ = DEFAULT_SD[name]
    return abs(value) * size if kind == "rel" else size


@dataclass(frozen=True)
class ParamInput:
    """One parameter: value, 1-sigma uncertainty (0: exact), unit, where they came from and why that sd."""

    name: str
    value: float
    sd: float
    source: str
    basis: str

    @property
    def unit(self) -> str:
        return UNITS[self.name]

    @property
    def symbol(self) -> str:
        return SYMBOLS[self.name]

    @property
    def carried_as(self) -> str:
        """How an inference carries this parameter: "exact" (sd 0), "fitted" (its standard error), "normal",
        or "normal truncated at 0" where the bound moves the mean by 1e-3 sd or more (value within about 3.1 sd
        of 0: F_c = 0 +- 0.2 N, c +- 50 %), as `rimless.analysis.inference.held.carry_bounded` carries it."""
        if self.source == "fitted":
            return "fitted"
        if self.sd == 0:
            return "exact"
        a = -self.value / self.sd  # the bound in sd from the value; the truncated normal's mean offset phi/(1-Phi)
        offset = math.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi) / (0.5 * math.erfc(a / math.sqrt(2.0)))
        return f"normal truncated at {LOWER_BOUND:g}" if offset >= TRUNCATION_NAMED else "normal"

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "symbol": self.symbol,
            "value": self.value,
            "sd": self.sd,
            "unit": self.unit,
            "source": self.source,
            "basis": self.basis,
            "carried_as": self.carried_as,
        }


@dataclass
class WheelInput:
    """The wheel's parameters (`params`) and, per parameter, its value, sd and source (`entries`); `fit`: the
    fields the file marks ``"fit"``; `path`: the wheel file (None: defaults)."""

    params: WheelParams
    entries: dict[str, ParamInput]
    fit: tuple[str, ...] = ()
    path: Path | None = None
    held_note: str = field(default="")

    def held(self, exclude: tuple[str, ...] = ()) -> list[ParamInput]:
        """The parameters held (not fitted) with a nonzero uncertainty, in `UNCERTAIN_FIELDS` order."""
        return [e for n, e in self.entries.items() if e.sd > 0 and n not in exclude and e.source != "fitted"]

    def with_entry(self, name: str, value: float, sd: float, source: str, basis: str) -> WheelInput:
        entries = dict(self.entries)
        entries[name] = ParamInput(name, float(value), float(sd), source, basis)
        return WheelInput(self.params.replace(**{name: value}), entries, self.fit, self.path, self.held_note)

    def parameters(self) -> list[dict[str, Any]]:
        """The JSON list ``parameters``: one {name, symbol, value, sd, unit, source, basis, carried_as} per parameter."""
        return [self.entries[n].as_dict() for n in UNCERTAIN_FIELDS]

    def lines(self) -> list[str]:
        """The parameters as printed lines."""
        out = []
        for n in UNCERTAIN_FIELDS:
            e = self.entries[n]
            sd = "exact" if e.sd == 0 else f"+- {e.sd:.3g}"
            out.append(f"  {e.symbol} = {e.value:.4g} {sd} {e.unit}  [{e.source}: {e.basis}]")
        return out


def default_wheel_input(params: WheelParams | None = None, *, source: str = "table1") -> WheelInput:
    """Every parameter at ``params`` (default Table 1) with the default uncertainty of `DEFAULT_SD`."""
    p = params or WheelParams()
    table1 = WheelParams()
    entries = {}
    for n in UNCERTAIN_FIELDS:
        v = float(getattr(p, n))
        src = "table1" if v == getattr(table1, n) else source
        entries[n] = ParamInput(n, v, default_sd(n, v), src, DEFAULT_SD[n][2])
    return WheelInput(p, entries)


def _number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | float) and math.isfinite(value)


def wheel_input_from(
    params: WheelParams | None = None, sd: Mapping[str, float] | None = None, *, source: str = "wheel"
) -> WheelInput:
    """``params`` (default Table 1) with the uncertainties ``sd`` (field names or the paper's symbols -> 1
    sigma, 0 = exact) over the defaults; a `ParameterError` names a bad key or sd. A parameter given an sd is the
    caller's statement: its source is ``source`` even at Table 1's value (as a wheel file's ``{sd = ...}``);
    "table1" stays for the defaults."""
    win = default_wheel_input(params, source=source)
    for key, s in (sd or {}).items():
        name = PARAM_ALIASES.get(key)
        if name not in UNCERTAIN_FIELDS:
            raise ParameterError(f"uncertainty of {key!r}: not a wheel parameter ({', '.join(UNCERTAIN_FIELDS)})")
        if not (_number(s) and s >= 0):
            raise ParameterError(f"uncertainty of {key!r} must be a number >= 0, got {s!r}")
        e = win.entries[name]
        win.entries[name] = ParamInput(name, e.value, float(s), source, "given" if s > 0 else "exact: given")
    return win


def read_wheel_input(path: str | Path) -> WheelInput:
    """Read a wheel file (see the module doc). Every error names the file and the key (`InputFileError` for an
    unreadable file or bad TOML, `ParameterError` for a bad entry)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise InputFileError(f"cannot read wheel file {path}: {err.strerror}") from None
    except tomllib.TOMLDecodeError as err:
        raise InputFileError(f"{path}: not valid TOML: {err}") from None
    except UnicodeDecodeError:
        raise InputFileError(f"{path}: not a text (UTF-8) file") from None
    if "wheel" in data and isinstance(data["wheel"], dict):
        data = data["wheel"]
    plain: dict[str, Any] = {}
    sds: dict[str, tuple[float | None, str]] = {}  # field -> (sd or None for "fit", key as written)
    fit: list[str] = []
    for key, raw in data.items():
        name = PARAM_ALIASES.get(key)
        where = f"{path}: key {key!r}"
        if isinstance(raw, dict):
            unknown = set(raw) - {"value", "sd"}
            if unknown:
                raise ParameterError(f"{where}: unknown field(s) {', '.join(sorted(unknown))} (give value and sd)")
            if not raw:
                raise ParameterError(f"{where}: an empty table (give value and/or sd)")
            if name not in UNCERTAIN_FIELDS:
                raise ParameterError(
                    f"{where}: not a wheel parameter with an uncertainty ({', '.join(SYMBOLS.values())})"
                )
            if "value" in raw:
                if not _number(raw["value"]):
                    raise ParameterError(f"{where}: value must be a finite number, got {raw['value']!r}")
                plain[key] = raw["value"]
            s = raw.get("sd")
            if s is not None and not (_number(s) and s >= 0):
                raise ParameterError(f"{where}: sd must be a number >= 0, got {s!r}")
            sds[name] = (float(s) if s is not None else -1.0, key)  # -1: the default sd at the value
        elif raw == "fit":
            if name not in UNCERTAIN_FIELDS or name == "gravity_m_s2":
                raise ParameterError(f"{where}: only m_H, m, I_c, L0, k, c, F_c can be fitted")
            fit.append(name)
            sds[name] = (None, key)
        else:
            if isinstance(raw, str) and key != "mass_model":
                raise ParameterError(f'{where}: expected a number, {{value = ..., sd = ...}} or "fit", got {raw!r}')
            plain[key] = raw
    params = params_from_mapping(plain, source=str(path), name_keys=True)  # its errors name the file (in_source)
    win = default_wheel_input(params, source="wheel_file")
    given = {PARAM_ALIASES[k] for k in plain if k in PARAM_ALIASES}
    for name in UNCERTAIN_FIELDS:
        v = float(getattr(params, name))
        if name in sds:
            s, key = sds[name]
            if s is None:
                win.entries[name] = ParamInput(name, v, default_sd(name, v), "table1", f'to be fitted ({key} = "fit")')
            elif s < 0:
                basis = f"{path} ({key}), default sd: {DEFAULT_SD[name][2]}"
                win.entries[name] = ParamInput(name, v, default_sd(name, v), "wheel_file", basis)
            else:
                win.entries[name] = ParamInput(name, v, s, "wheel_file", f"{path} ({key})")
        elif name in given:
            win.entries[name] = ParamInput(name, v, 0.0, "wheel_file", f"exact: plain number in {path}")
    win.fit = tuple(fit)
    win.path = path
    return win


def wheel_input_for(
    params: WheelParams,
    base: WheelInput | None = None,
    sd: Mapping[str, float] | None = None,
    *,
    stated: Collection[str] = (),
) -> WheelInput:
    """The uncertain input of a wheel at ``params``: ``base``'s entries (a wheel file's) where its value is the
    one used, else the default uncertainty (source ``wheel`` when the value differs from Table 1, or when its
    field is in ``stated``: a value the caller gave, e.g. ``Wheel(guide_friction_n=0.0)``); then the
    uncertainties ``sd`` (field names or symbols -> 1 sigma; source ``wheel``) over those."""
    win = wheel_input_from(params, sd=None, source="wheel")
    if base is not None:
        for n, e in base.entries.items():
            if getattr(params, n) == e.value:
                win.entries[n] = e
        win.fit, win.path = base.fit, base.path
    for n in stated:
        own = win.entries.get(n)
        if own is not None and own.source == "table1":
            win.entries[n] = ParamInput(n, own.value, own.sd, "wheel", own.basis)
    if sd:
        over = wheel_input_from(params, sd, source="wheel")
        for key in sd:
            n = PARAM_ALIASES[key]
            win.entries[n] = over.entries[n]
    return win
