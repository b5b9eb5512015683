"""The parsed form of a Vicon export, whatever its format: a `ViconFile` of `Section`s of `Column`s, SI inside.

The CSV reader (`rimless.analysis.io.vicon_csv`) and the C3D reader (`rimless.analysis.io.c3d`) both return it;
the kinematics read it. Lengths are in m and angles in rad where the file's unit is one of the tables below.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Column", "Section", "ViconFile", "LENGTH_UNITS_M", "ANGLE_UNITS_RAD", "RATE_RANGE_HZ", "MAX_COORDINATE_M"]

#: Length units we convert, and their size in metres.
LENGTH_UNITS_M: Mapping[str, float] = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
#: Angle units we convert, and their size in radians.
ANGLE_UNITS_RAD: Mapping[str, float] = {"rad": 1.0, "deg": math.pi / 180.0, "°": math.pi / 180.0}
#: Plausible frame rates, Hz; a rate row (or C3D rate) outside is an error.
RATE_RANGE_HZ = (1.0, 10000.0)
#: Largest coordinate accepted, m (beyond it the number is not a position in a capture volume).
MAX_COORDINATE_M = 1e7


@dataclass(frozen=True)
class Column:
    """One data column of a section.

    ``group`` is the object/marker/device name (prefix and repeated ``Obj:Obj`` removed), ``component``
    the header cell (``TX``, ``X``, ``Fz``...), ``unit`` the unit of `Section.values` (SI when converted),
    ``file_unit`` what the file said, ``column`` the 1-based column in the file.
    """

    group: str
    component: str
    unit: str
    file_unit: str
    column: int


@dataclass(frozen=True, eq=False)
class Section:
    """One section of a Vicon CSV file, values in SI where the unit is a length or an angle.

    Attributes
    ----------
    kind : the title row (``"Objects"``, ``"Trajectories"``, ``"Devices"``...).
    rate_hz : the rate row, Hz.
    line : 1-based line of the title row.
    frame, sub_frame : int64 arrays, shape (n,).
    columns : one `Column` per column of ``values``.
    values : float64 array, shape (n, len(columns)); NaN where the file had no value.
    name_prefix : ``"Global Angle"``/``"Local Angle"`` when Tracker wrote one, else ``""``.
    """

    kind: str
    rate_hz: float
    line: int
    frame: np.ndarray
    sub_frame: np.ndarray
    columns: tuple[Column, ...]
    values: np.ndarray
    name_prefix: str = ""
    #: 1-based line of the first data row; data row r is on line ``data_line + r``.
    data_line: int = 0
    #: 1-based line of the units row.
    units_line: int = 0

    @property
    def n_rows(self) -> int:
        """Number of data rows."""
        return int(self.values.shape[0])

    @property
    def time_s(self) -> np.ndarray:
        """Time of each row from the first row, s (frames, and sub-frames when there are several)."""
        n_sub = int(self.sub_frame.max()) + 1 if self.n_rows else 1
        if self.n_rows == 0:
            return np.zeros(0)
        tick = (self.frame - self.frame[0]) * n_sub + self.sub_frame - self.sub_frame[0]
        return tick / self.rate_hz

    def groups(self) -> list[str]:
        """Group names (objects, markers, devices) in file order, without repeats."""
        return list(dict.fromkeys(c.group for c in self.columns))

    def get(self, group: str, components: tuple[str, ...] | None = None) -> np.ndarray:
        """Values of one group, shape (n, k), in the order of ``components`` (default: file order); a read-only
        view when the columns are adjacent in that order, else a copy.

        Raises KeyError naming what is missing.
        """
        cols = {c.component: i for i, c in enumerate(self.columns) if c.group == group}
        if not cols:
            raise KeyError(f"no group {group!r} in section {self.kind!r} (line {self.line})")
        if components is None:
            idx = list(cols.values())
        else:
            missing = [c for c in components if c not in cols]
            if missing:
                raise KeyError(f"group {group!r} of section {self.kind!r} has no column(s) {missing}")
            idx = [cols[c] for c in components]
        if idx and idx == list(range(idx[0], idx[0] + len(idx))):
            view = self.values[:, idx[0] : idx[0] + len(idx)]  # no copy; read-only so the section stays intact
            view.flags.writeable = False
            return view
        return self.values[:, idx]

    def components(self, group: str) -> tuple[str, ...]:
        """Component names of one group in file order."""
        return tuple(c.component for c in self.columns if c.group == group)


@dataclass(frozen=True, eq=False)
class ViconFile:
    """A parsed Vicon CSV file: its sections and how it was written."""

    path: str
    sections: tuple[Section, ...]
    delimiter: str = ","
    decimal: str = "."
    encoding: str = "utf-8"
    line_ending: str = "\n"
    notes: tuple[str, ...] = field(default=())

    def section(self, kind: str) -> Section | None:
        """The first section titled ``kind``, or None."""
        return next((s for s in self.sections if s.kind == kind), None)

    def kinds(self) -> list[str]:
        """Section titles in file order."""
        return [s.kind for s in self.sections]
