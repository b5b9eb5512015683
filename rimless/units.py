"""Echo a value in the unit the user typed: the unit is the option's suffix (`--slope-deg`, `--max-gap-ms`).

Inside, every quantity is SI (rad, s, m, kg, N); a message about an option converts back before printing:
`typed("--slope-deg", 0.5236)` gives `--slope-deg 30`.
"""

from __future__ import annotations

import math

# suffix of the option name -> (factor from SI to the typed unit, unit label)
_FROM_SI: dict[str, tuple[float, str]] = {
    "deg": (180.0 / math.pi, "deg"),
    "rad": (1.0, "rad"),
    "ms": (1e3, "ms"),
    "s": (1.0, "s"),
    "mm": (1e3, "mm"),
    "m": (1.0, "m"),
    "kg": (1.0, "kg"),
    "hz": (1.0, "Hz"),
}


def unit_of(option: str) -> tuple[float, str]:
    """(factor from SI, unit label) for an option name such as `--slope-deg`; (1, '') if it names no unit."""
    suffix = option.rsplit("-", 1)[-1].rsplit("_", 1)[-1].lower()
    return _FROM_SI.get(suffix, (1.0, ""))


def in_typed_unit(option: str, value_si: float) -> float:
    """The SI value converted to the unit of `option`."""
    return value_si * unit_of(option)[0]


def typed(option: str, value_si: float, digits: int = 6) -> str:
    """`option value` with the value in the option's unit, e.g. `--slope-deg 30`."""
    return f"{option} {in_typed_unit(option, value_si):.{digits}g}"
