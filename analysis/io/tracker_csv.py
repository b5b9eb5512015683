"""Write trajectories as a Vicon Tracker CSV export (the layout `rimless.analysis.io.vicon_csv` reads):
the bundled example trials and the tests' recordings are made with it."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from rimless.analysis.io.vicon_file import ANGLE_UNITS_RAD, LENGTH_UNITS_M

__all__ = ["write_tracker_csv"]


def write_tracker_csv(
    path: str | Path,
    *,
    rate_hz: float,
    objects: Mapping[str, np.ndarray] | None = None,
    markers: Mapping[str, np.ndarray] | None = None,
    first_frame: int = 1,
    length_unit: str = "mm",
    angle_unit: str = "rad",
    delimiter: str = ",",
    newline: str = "\n",
) -> Path:
    """Write trajectories in Vicon Tracker CSV layout (an ``Objects`` and/or a ``Trajectories`` section).

    Parameters
    ----------
    path : output file.
    rate_hz : frame rate, Hz.
    objects : name -> array (n, 6): RX, RY, RZ in rad (helical vector, as Tracker's ``Global Angle``),
        TX, TY, TZ in m. Written with the ``Global Angle Name:Name`` header Tracker uses.
    markers : name -> array (n, 3): X, Y, Z in m.
    first_frame : number of the first frame.
    length_unit, angle_unit : units to write (``mm``/``cm``/``m``, ``rad``/``deg``); values are converted.
    delimiter, newline : ``","`` or ``";"``, ``"\\n"`` or ``"\\r\\n"``.

    NaN is written as an empty cell (an occlusion). Numbers use the shortest repr that reads back exactly.
    """
    if length_unit not in LENGTH_UNITS_M or angle_unit not in ANGLE_UNITS_RAD:
        raise ValueError(f"unknown unit {length_unit!r}/{angle_unit!r}")
    if not objects and not markers:
        raise ValueError("nothing to write: give objects and/or markers")
    lscale, ascale = LENGTH_UNITS_M[length_unit], ANGLE_UNITS_RAD[angle_unit]
    blocks: list[str] = []
    for kind, groups, comps in (
        ("Objects", objects, ("RX", "RY", "RZ", "TX", "TY", "TZ")),
        ("Trajectories", markers, ("X", "Y", "Z")),
    ):
        if not groups:
            continue
        arrays = []
        names_row = ["", ""]
        comp_row = ["Frame", "Sub Frame"]
        unit_row = ["", ""]
        n = None
        for name, arr in groups.items():
            a = np.asarray(arr, dtype=np.float64)
            if a.ndim != 2 or a.shape[1] != len(comps):
                raise ValueError(f"{kind} {name!r}: expected shape (n, {len(comps)}), got {a.shape}")
            n = a.shape[0] if n is None else n
            if a.shape[0] != n:
                raise ValueError(f"{kind} {name!r}: {a.shape[0]} rows, others have {n}")
            if kind == "Objects":
                a = np.concatenate([a[:, :3] / ascale, a[:, 3:] / lscale], axis=1)
                names_row += [f"Global Angle {name}:{name}"] + [""] * 5
                unit_row += [angle_unit] * 3 + [length_unit] * 3
            else:
                a = a / lscale
                names_row += [name, "", ""]
                unit_row += [length_unit] * 3
            comp_row += list(comps)
            arrays.append(a)
        assert n is not None
        data = np.concatenate(arrays, axis=1)
        lines = [
            kind,
            _fmt_number(float(rate_hz)),
            delimiter.join(names_row),
            delimiter.join(comp_row),
            delimiter.join(unit_row),
        ]
        text_cells = (
            np.where(np.isnan(data), "", np.vectorize(_fmt_number, otypes=[object])(data))
            if data.size
            else np.zeros((n, 0), dtype=object)
        )
        frames = np.arange(first_frame, first_frame + n)
        for i in range(n):
            lines.append(delimiter.join([str(frames[i]), "0", *text_cells[i]]))
        blocks.append(newline.join(lines) + newline)
    out = Path(path)
    out.write_text(
        newline.join(blocks) if len(blocks) == 1 else blocks[0] + newline + blocks[1], encoding="utf-8", newline=""
    )
    return out


def _fmt_number(v: float) -> str:
    if math.isnan(v):
        return ""
    if v == int(v) and abs(v) < 1e15:
        return str(int(v))
    return repr(v)
