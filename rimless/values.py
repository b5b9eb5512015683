"""Lists typed on the command line: `c,k`, `er,ve`, `0,5,10`, `1500:3500:250`, `X,Y,Z`.

The one parser every command uses. Errors are `ParameterError`s whose one line names the option, so the
CLI rules turn them into `error: ...` and exit 2. Numbers stay in the unit the option names (`--k` in N/m,
`--clutch-delay-ms` in ms); the caller converts to SI.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, TypeVar, overload

from rimless.errors import ParameterError

T = TypeVar("T")

MAX_VALUES = 10000


@overload
def parse_list(
    text: str,
    option: str,
    *,
    choices: Sequence[str] | None = None,
    count: int | None = None,
    unique: bool = False,
    lower: bool = False,
) -> list[str]: ...


@overload
def parse_list(
    text: str,
    option: str,
    item: Callable[[str], T],
    *,
    choices: Sequence[str] | None = None,
    count: int | None = None,
    unique: bool = False,
    lower: bool = False,
) -> list[T]: ...


def parse_list(
    text: str,
    option: str,
    item: Callable[[str], Any] = str,
    *,
    choices: Sequence[str] | None = None,
    count: int | None = None,
    unique: bool = False,
    lower: bool = False,
) -> list[Any]:
    """`a,b,c` -> [item(a), item(b), item(c)]; every error names `option`.

    `choices` restricts the (stripped, optionally lower-cased) names; `count` requires exactly that many
    items; `unique` refuses a name given twice. Empty items (`a,,b`) are an error.
    """
    raw = [t.strip() for t in str(text).split(",")]
    if lower:
        raw = [t.lower() for t in raw]
    if not raw or any(not t for t in raw):
        raise ParameterError(f"{option} must be values separated by commas, got {text!r}")
    if count is not None and len(raw) != count:
        raise ParameterError(f"{option} needs {count} values separated by commas, got {text!r}")
    if choices is not None:
        bad = [t for t in raw if t not in choices]
        if bad:
            raise ParameterError(f"{option}: unknown value {bad[0]!r}; known: {', '.join(choices)}")
    if unique and len(set(raw)) != len(raw):
        raise ParameterError(f"{option}: a value is named twice in {text!r}")
    out: list[Any] = []
    for t in raw:
        try:
            out.append(item(t))
        except (TypeError, ValueError):
            where = "" if t == str(text).strip() else f" in {text!r}"
            raise ParameterError(f"{option} must be {_expected(item)} separated by commas, got {t!r}{where}") from None
    return out


def _expected(item: Callable[[str], Any]) -> str:
    """What `item` reads, in the plural: `numbers` for float, `whole numbers` for int, else its name."""
    names: dict[Any, str] = {float: "numbers", int: "whole numbers"}
    return names.get(item, f"{getattr(item, '__name__', 'value')} values")


def parse_numbers(text: str, option: str, *, count: int | None = None) -> list[float]:
    """Comma-separated finite numbers; every error names `option`."""
    values = parse_list(text, option, float, count=count)
    if not all(math.isfinite(v) for v in values):
        raise ParameterError(f"{option} must be finite numbers, got {text!r}")
    return values


def parse_range(text: str, option: str) -> list[float]:
    """`START:STOP:STEP` (STOP included when on the grid) or comma-separated numbers; errors name `option`."""
    text = str(text).strip()
    if ":" not in text:
        return parse_numbers(text, option)
    try:
        parts = [float(v) for v in text.split(":")]
    except ValueError:
        parts = []
    if len(parts) != 3:
        raise ParameterError(f"{option} must be START:STOP:STEP or comma-separated numbers, got {text!r}")
    start, stop, step = parts
    if not all(math.isfinite(v) for v in parts) or step <= 0 or stop < start:
        raise ParameterError(f"{option} {text!r}: need START:STOP:STEP with STEP > 0 and STOP >= START")
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    if n > MAX_VALUES:
        raise ParameterError(f"{option} {text!r}: {n} values is too many (at most {MAX_VALUES})")
    return [round(start + i * step, 12) for i in range(n)]
