"""The slope manifest of a series of trials: a CSV ``file,slope_deg`` (the inclinometer reading of each run).

A header row ``file,slope_deg`` is required; ``#`` starts a comment line; blank lines are skipped. ``file`` is
the export's name (``run1.csv``) or its path as given on the command line; the slope is in degrees,
positive down the walking direction.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

from rimless.errors import InputFileError

__all__ = ["read_slope_manifest", "slope_for"]

#: Largest slope a manifest may give, deg (the CLI's --slope-deg range).
MAX_SLOPE_DEG = 45.0


def read_slope_manifest(path: str | Path) -> dict[str, tuple[float, str]]:
    """``{file: (slope_deg, "manifest.csv:line")}`` from a manifest CSV.

    Raises `InputFileError` naming ``file:line`` and the field for a missing file, a missing header, a bad or
    duplicate row.
    """
    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{p}: no such slope manifest (--slopes)")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise InputFileError(f"{p}: cannot read the slope manifest (--slopes): {err}") from None
    out: dict[str, tuple[float, str]] = {}
    header_seen = False
    for line_no, row in enumerate(csv.reader(text.splitlines()), start=1):
        cells = [c.strip() for c in row]
        if not cells or not any(cells) or cells[0].startswith("#"):
            continue
        if not header_seen:
            if [c.lower() for c in cells[:2]] != ["file", "slope_deg"]:
                raise InputFileError(
                    f"{p}:{line_no}:1: the slope manifest must start with the header "
                    f"'file,slope_deg', found {','.join(cells)!r}"
                )
            header_seen = True
            continue
        if len(cells) < 2 or not cells[0]:
            raise InputFileError(f"{p}:{line_no}:1: a row needs 'file,slope_deg', found {','.join(cells)!r}")
        try:
            v = float(cells[1])
        except ValueError:
            raise InputFileError(f"{p}:{line_no}:2: slope_deg {cells[1]!r} is not a number") from None
        if not math.isfinite(v) or abs(v) > MAX_SLOPE_DEG:
            raise InputFileError(
                f"{p}:{line_no}:2: slope_deg {cells[1]} is outside -{MAX_SLOPE_DEG:g}..{MAX_SLOPE_DEG:g}"
            )
        if cells[0] in out:
            raise InputFileError(f"{p}:{line_no}:1: {cells[0]!r} is listed twice (first at {out[cells[0]][1]})")
        out[cells[0]] = (v, f"{p}:{line_no}")
    if not header_seen:
        raise InputFileError(f"{p}: the slope manifest is empty (expected the header 'file,slope_deg' and rows)")
    return out


def slope_for(manifest: dict[str, tuple[float, str]], path: str | Path) -> tuple[float, str] | None:
    """The manifest row of an export: by its path as given, its resolved path, or its name; None if absent."""
    p = Path(path)
    for key in (str(path), str(p), p.name):
        if key in manifest:
            return manifest[key]
    try:
        res = p.resolve()
    except OSError:
        return None
    for k, v in manifest.items():
        try:
            if Path(k).resolve() == res:
                return v
        except OSError:
            continue
    return None
