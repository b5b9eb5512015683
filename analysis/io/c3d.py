"""Read C3D files (Vicon Nexus' native format; Tracker exports it too) into the same `ViconFile` as the CSV reader.

The binary format is read by ``ezc3d`` (pyomeca's maintained C++ reader with Python bindings, PyPI wheels).
Markers (the ``POINT`` group) become a ``Trajectories`` section (``X Y Z`` per label, lengths converted by
``POINT:UNITS``); a point whose residual is negative (Vicon's mark of an occlusion) or whose coordinates are
all exactly 0 becomes NaN. Rigid bodies (the ``ROTATION`` group Nexus writes for tracked objects, 4x4 poses)
become an ``Objects`` section with helical ``RX RY RZ`` in rad and ``TX TY TZ`` in m, as Tracker's CSV.
Errors are `InputFileError` naming the file and the C3D parameter (``POINT:RATE``...).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.io.vicon_file import LENGTH_UNITS_M, MAX_COORDINATE_M, RATE_RANGE_HZ, Column, Section, ViconFile
from rimless.errors import InputFileError

__all__ = ["read_c3d", "write_c3d"]


def _param(c: Any, group: str, name: str, default: object = None) -> Any:
    """The value of parameter ``group:name`` of the ezc3d object ``c`` (its type is whatever the file holds)."""
    try:
        return c["parameters"][group][name]["value"]
    except (KeyError, TypeError):
        return default


def _rate(path: str, value: object, where: str) -> float:
    try:
        rate = float(np.asarray(value, dtype=float).ravel()[0])
    except (TypeError, ValueError, IndexError):
        raise InputFileError(f"{path}: {where}: no frame rate") from None
    lo, hi = RATE_RANGE_HZ
    if not np.isfinite(rate) or not lo <= rate <= hi:
        raise InputFileError(f"{path}: {where} is {rate!r} Hz: a frame rate must lie in {lo:g}-{hi:g} Hz")
    return rate


def read_c3d(path: str | Path) -> ViconFile:
    """Read a C3D file: markers as a ``Trajectories`` section, rigid bodies as ``Objects`` (SI units)."""
    import ezc3d

    p = str(path)
    if not Path(p).is_file():
        raise InputFileError(f"{p}: no such file")
    try:
        c = ezc3d.c3d(p)
    except (OSError, RuntimeError, ValueError, IndexError) as err:
        raise InputFileError(f"{p}: not a readable C3D file ({str(err).strip() or type(err).__name__})") from None
    sections: list[Section] = []
    first = int(c["header"]["points"].get("first_frame", 0)) + 1  # C3D counts from 0, Vicon frames from 1
    pts = np.asarray(c["data"]["points"], dtype=np.float64)  # (4, n_points, n_frames)
    labels = [str(s).strip() for s in (_param(c, "POINT", "LABELS", []) or [])]
    if pts.ndim == 3 and pts.shape[1] > 0 and pts.shape[2] > 0:
        rate = _rate(p, _param(c, "POINT", "RATE", c["header"]["points"].get("frame_rate")), "POINT:RATE")
        units = [str(u).strip() for u in (_param(c, "POINT", "UNITS", ["mm"]) or ["mm"])]
        unit = units[0] if units else "mm"
        if unit not in LENGTH_UNITS_M:
            raise InputFileError(f"{p}: POINT:UNITS is {unit!r}: not a length unit ({', '.join(LENGTH_UNITS_M)})")
        n_pts, n = pts.shape[1], pts.shape[2]
        labels = (labels + [f"point{i + 1}" for i in range(len(labels), n_pts)])[:n_pts]
        xyz = pts[:3].transpose(2, 1, 0) * LENGTH_UNITS_M[unit]  # (n, k, 3)
        res = c["data"]["meta_points"].get("residuals")
        if res is not None:
            r = np.asarray(res, dtype=np.float64)[0].T  # (n, k)
            xyz[r < 0] = np.nan
        xyz[(xyz == 0).all(axis=2)] = np.nan
        values = xyz.reshape(n, n_pts * 3)
        _check_range(p, values, "POINT")
        cols = tuple(
            Column(lab, comp, "m", unit, 3 + 3 * i + j) for i, lab in enumerate(labels) for j, comp in enumerate("XYZ")
        )
        frames = np.arange(first, first + n, dtype=np.int64)
        sections.append(
            Section("Trajectories", rate, 1, frames, np.zeros(n, np.int64), cols, np.ascontiguousarray(values))
        )
    rot = c["data"].get("rotations")
    if rot is not None and np.size(rot) and np.asarray(rot).ndim == 4 and np.asarray(rot).shape[2] > 0:
        sections.append(_objects(p, c, np.asarray(rot, dtype=np.float64), first))
    if not sections:
        raise InputFileError(f"{p}: the C3D file holds no points and no rigid bodies")
    return ViconFile(path=p, sections=tuple(sections), delimiter="", encoding="c3d")


def _objects(p: str, c: Any, rot: np.ndarray, first: int) -> Section:
    """Rigid bodies from the ROTATION group: (4, 4, n_bodies, n_frames) poses, translation in POINT units."""
    from scipy.spatial.transform import Rotation

    rate = _rate(p, _param(c, "ROTATION", "RATE", _param(c, "POINT", "RATE")), "ROTATION:RATE")
    labels = [str(s).strip() for s in (_param(c, "ROTATION", "LABELS", []) or [])]
    units = [str(u).strip() for u in (_param(c, "POINT", "UNITS", ["mm"]) or ["mm"])]
    scale = LENGTH_UNITS_M.get(units[0] if units else "mm", 1e-3)
    n_b, n = rot.shape[2], rot.shape[3]
    labels = (labels + [f"body{i + 1}" for i in range(len(labels), n_b)])[:n_b]
    values = np.full((n, 6 * n_b), np.nan)
    for b in range(n_b):
        m = rot[:, :, b, :].transpose(2, 0, 1)  # (n, 4, 4)
        ok = np.isfinite(m[:, :3, :]).all(axis=(1, 2)) & (np.abs(np.linalg.det(np.nan_to_num(m[:, :3, :3])) - 1) < 0.1)
        if ok.any():
            values[ok, 6 * b : 6 * b + 3] = Rotation.from_matrix(m[ok, :3, :3]).as_rotvec()
            values[ok, 6 * b + 3 : 6 * b + 6] = m[ok, :3, 3] * scale
    _check_range(p, values, "ROTATION")
    cols = tuple(
        Column(lab, comp, "rad" if comp[0] == "R" else "m", "rad" if comp[0] == "R" else units[0], 3 + 6 * i + j)
        for i, lab in enumerate(labels)
        for j, comp in enumerate(("RX", "RY", "RZ", "TX", "TY", "TZ"))
    )
    frames = np.arange(first, first + n, dtype=np.int64)
    return Section("Objects", rate, 1, frames, np.zeros(n, np.int64), cols, np.ascontiguousarray(values))


def _check_range(p: str, values: np.ndarray, group: str) -> None:
    bad = np.abs(values) > MAX_COORDINATE_M
    if bad.any():
        r, col = np.argwhere(bad)[0]
        raise InputFileError(
            f"{p}: {group} data, frame index {r}, value {col + 1}: beyond "
            f"{MAX_COORDINATE_M:.0e} m: not a position in a capture volume"
        )


def write_c3d(path: str | Path, *, rate_hz: float, markers: Mapping[str, np.ndarray], length_unit: str = "mm") -> Path:
    """Write markers (name -> (n, 3) m; NaN = occluded) as a C3D file (float32, as Nexus writes)."""
    import ezc3d

    names = list(markers)
    arr = np.stack([np.asarray(markers[k], dtype=np.float64) for k in names], axis=1)  # (n, k, 3)
    scale = LENGTH_UNITS_M[length_unit]
    pts = np.ones((4, len(names), arr.shape[0]))
    pts[:3] = arr.transpose(2, 1, 0) / scale
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(rate_hz)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c["parameters"]["POINT"]["UNITS"]["value"] = [length_unit]
    c["data"]["points"] = pts
    out = Path(path)
    tmp = out.with_name(out.name + ".tmp.c3d")
    c.write(str(tmp))
    tmp.replace(out)
    return out
