"""The lab's vertical: which axis of the Vicon frame points up, from the data or given (``--up-axis``).

A Vicon export does not say where gravity points: labs calibrate Z up (Vicon's default) or Y up. Every
kinematic rule of this folder measures heights along world Z, so a file whose vertical is another axis is
turned first (`rotate_file`: positions and object orientations, a proper rotation that takes the up axis to
+Z) and the trial's world outputs are turned back.

From the data (`find_up`): a rolling wheel turns about a horizontal axis ``w`` (signed so that the wheel angle
increases) while its hub travels along ``t`` (down the ramp, signed by the net motion); rolling without slip
on feet below the hub makes ``w`` parallel to ``up x t``, so ``t x w`` is the ramp's outward normal, within the
slope (less than alpha/2 = 22.5 deg for any wheel that stands) of the vertical. The lab's vertical is the
signed axis nearest that normal; when the normal lies 22.5 deg or more from every axis, or the data hold no
rotation and the path does not rule out Z, the data cannot decide: the file is refused naming ``--up-axis``
(or Z is kept when nothing contradicts it). Positions in m, angles in rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from rimless.analysis.io.vicon_file import ViconFile
from rimless.analysis.kinematics.source import POSE, XYZ, SourceChoice, zeros_to_nan
from rimless.errors import UserError

__all__ = [
    "UP_AXES",
    "UpAxis",
    "VerticalUndecided",
    "up_vector",
    "rotation_to_z_up",
    "rotate_file",
    "find_up",
    "is_z_up",
]

#: The names ``--up-axis`` takes.
UP_AXES = ("x", "y", "z", "-x", "-y", "-z")
#: Frames used to find the vertical (an even subsample beyond).
MAX_FRAMES = 20_000
#: The normal must lie within this angle of an axis, rad (alpha/2: no wheel stands on a steeper ramp).
MAX_TILT_RAD = math.pi / 8
#: Least travel, m, and rotation, rad, for the data to say anything about the vertical.
MIN_TRAVEL_M = 0.1
MIN_TURN_RAD = math.pi / 4


class VerticalUndecided(UserError):
    """The data do not decide which lab axis is vertical; the message names ``--up-axis``."""


@dataclass(frozen=True)
class UpAxis:
    """The lab's up axis (one of `UP_AXES`) and how it was found."""

    name: str
    reason: str

    @property
    def vector(self) -> np.ndarray:
        return up_vector(self.name)


def up_vector(name: str) -> np.ndarray:
    """Unit vector of an ``--up-axis`` name (``x``, ``-y``, ...); a bad name is a `UserError`."""
    key = name.strip().lower().lstrip("+")
    if key not in UP_AXES:
        raise UserError(f"--up-axis must be one of {', '.join(UP_AXES)}, got {name!r}")
    v = np.zeros(3)
    v["xyz".index(key[-1])] = -1.0 if key.startswith("-") else 1.0
    return v


def rotation_to_z_up(up: np.ndarray) -> np.ndarray:
    """A proper rotation Q (3, 3) with ``Q @ up = +Z``, permuting the lab axes (identity for +Z)."""
    i = int(np.argmax(np.abs(up)))
    e0 = np.zeros(3)
    e0[(i + 1) % 3] = 1.0
    z = np.sign(up[i]) * np.eye(3)[i]
    return np.vstack([e0, np.cross(z, e0), z])


def rotate_file(vf: ViconFile, q: np.ndarray, orientation: str = "helical") -> ViconFile:
    """``vf`` with every position (X, Y, Z and TX, TY, TZ) turned by ``q`` and every object orientation
    (RX, RY, RZ in ``orientation``: helical or a scipy Euler sequence) made ``q R``; occlusions (all-zero rows)
    and gaps stay so."""
    from scipy.spatial.transform import Rotation

    sections = []
    for sec in vf.sections:
        cols: dict[str, dict[str, int]] = {}
        for k, c in enumerate(sec.columns):
            cols.setdefault(c.group, {})[c.component] = k
        v = None
        for comps in cols.values():
            for trio in (XYZ, POSE[3:]):
                if all(c in comps for c in trio):
                    if v is None:
                        v = np.array(sec.values, dtype=np.float64, copy=True)
                    idx = [comps[c] for c in trio]
                    p = v[:, idx]
                    zero = ~(p != 0).any(axis=1)
                    if all(c in comps for c in POSE):
                        zero &= ~(v[:, [comps[c] for c in POSE[:3]]] != 0).any(axis=1)
                    out = p @ q.T
                    out[zero] = 0.0
                    v[:, idx] = out
            if all(c in comps for c in POSE[:3]):
                if v is None:
                    v = np.array(sec.values, dtype=np.float64, copy=True)
                idx = [comps[c] for c in POSE[:3]]
                a = v[:, idx]
                ok = ~np.isnan(a).any(axis=1)
                zero = ~(a != 0).any(axis=1)
                if all(c in comps for c in POSE):
                    zero &= ~(v[:, [comps[c] for c in POSE[3:]]] != 0).any(axis=1)
                use = ok & ~zero
                if use.any():
                    r0 = (
                        Rotation.from_rotvec(a[use])
                        if orientation == "helical"
                        else Rotation.from_euler(orientation, a[use])
                    )
                    r1 = Rotation.from_matrix(q) * r0
                    a[use] = r1.as_rotvec() if orientation == "helical" else r1.as_euler(orientation)
                    v[:, idx] = a
        sections.append(sec if v is None else replace(sec, values=v))
    return replace(vf, sections=tuple(sections))


def _even(idx: np.ndarray) -> np.ndarray:
    return idx[:: max(1, -(-idx.size // MAX_FRAMES))]


def _spin_axis_object(angles: np.ndarray, orientation: str) -> tuple[np.ndarray | None, float]:
    """(signed world rotation axis, turn rad) of an object's orientation, from increments between consecutive
    frames of an even subsample."""
    from scipy.spatial.transform import Rotation

    ok = ~np.isnan(angles).any(axis=1) & (angles != 0).any(axis=1)
    i0 = np.flatnonzero(ok[:-1] & ok[1:])
    if i0.size < 4:
        return None, 0.0
    stride = max(1, -(-i0.size // MAX_FRAMES))
    i0 = i0[::stride]

    def rot(a: np.ndarray):
        return Rotation.from_rotvec(a) if orientation == "helical" else Rotation.from_euler(orientation, a)

    inc = (rot(angles[i0 + 1]) * rot(angles[i0]).inv()).as_rotvec()
    return _dominant(inc, stride)


def _dominant(inc: np.ndarray, stride: int) -> tuple[np.ndarray | None, float]:
    norm = np.linalg.norm(inc, axis=1)
    use = norm > 0
    axis = None
    for _ in range(3):
        sel = inc[use] if use.any() else inc
        _, vec = np.linalg.eigh(sel.T @ sel)
        axis = vec[:, -1]
        use = np.abs(inc @ axis) >= math.cos(math.radians(30.0)) * norm
    if axis is None:
        return None, 0.0
    turn = float(np.sum(inc @ axis)) * stride
    if turn < 0:
        axis, turn = -axis, -turn
    return axis, turn


def _spin_axis_markers(pts: np.ndarray) -> tuple[np.ndarray | None, float]:
    """(signed world rotation axis, turn rad) of markers on a wheel (n, k, 3): the sum of ``r x dr`` about
    their centroid between consecutive frames where all are seen."""
    ok = ~np.isnan(pts).any(axis=(1, 2))
    i0 = np.flatnonzero(ok[:-1] & ok[1:])
    if i0.size < 4:
        return None, 0.0
    stride = max(1, -(-i0.size // MAX_FRAMES))
    i0 = i0[::stride]
    a, b = pts[i0], pts[i0 + 1]
    ra = a - a.mean(axis=1, keepdims=True)
    rb = b - b.mean(axis=1, keepdims=True)
    r2 = np.einsum("nki,nki->n", ra, ra)
    # the rotation vector of each increment, about the markers' centroid: sum_k r x dr / sum_k |r|^2 (for markers
    # in the wheel plane; an axial offset only adds a part along r that averages out over a turn)
    inc = np.cross(ra, rb - ra).sum(axis=1) / np.maximum(r2, 1e-12)[:, None]
    return _dominant(inc, stride)


def _travel(p: np.ndarray) -> tuple[np.ndarray | None, float]:
    """(unit 3-D direction of the path's main axis signed by the net motion, its extent m)."""
    ok = _even(np.flatnonzero(~np.isnan(p).any(axis=1)))
    if ok.size < 3:
        return None, 0.0
    x = p[ok]
    c = x - x.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    u = vt[0]
    if (x[-1] - x[0]) @ u < 0:
        u = -u
    s = c @ u
    return u, float(np.ptp(s))


def find_up(vf: ViconFile, choice: SourceChoice, orientation: str = "helical") -> UpAxis:
    """The lab's up axis from the motion of the chosen wheel (see the module doc); +Z when the data do not
    contradict it and cannot decide; `VerticalUndecided` (naming ``--up-axis``) when they contradict Z and
    cannot decide."""
    sec = choice.section
    axis: np.ndarray | None = None
    turn = 0.0
    if choice.object is not None:
        pose = zeros_to_nan(sec.get(choice.object, POSE), 6)
        path = pose[:, 3:]
        axis, turn = _spin_axis_object(pose[:, :3], orientation)
    else:
        pts = np.stack([zeros_to_nan(sec.get(m, XYZ), 3) for m in choice.markers], axis=1)
        if pts.shape[1] > 1:  # the markers' centroid per frame (NaN where none is seen: a gap, as elsewhere)
            seen = np.isfinite(pts).all(axis=2)
            n = seen.sum(axis=1)
            total = np.where(seen[:, :, None], pts, 0.0).sum(axis=1)
            path = np.where(n[:, None] > 0, total / np.maximum(n, 1)[:, None], np.nan)
        else:
            path = pts[:, 0]
        if pts.shape[1] >= 3:
            axis, turn = _spin_axis_markers(pts)
    travel, extent = _travel(path)
    z = np.array([0.0, 0.0, 1.0])
    where = f"{vf.path}: "
    if travel is None or extent < MIN_TRAVEL_M:
        return UpAxis("z", "Z up (Vicon's default): the wheel travels too little to tell")
    if axis is not None and turn < MIN_TURN_RAD:
        # a rigid body that does not roll: nothing to find the vertical from, and not a walk to measure
        return UpAxis("z", "Z up (Vicon's default): the tracked body does not roll, nothing to tell the vertical by")
    if axis is None:
        # one marker, no rotation: a nearly level path rules axes out but does not pick one
        if abs(travel @ z) < math.sin(MAX_TILT_RAD):
            return UpAxis("z", "Z up (Vicon's default): one marker shows no rotation; its path is level enough")
        raise VerticalUndecided(
            f"{where}the wheel's path rises {math.degrees(math.asin(min(abs(travel @ z), 1.0))):.0f} deg along "
            "world Z, so Z is not the lab's vertical, and without a rotation (one marker) the data cannot say "
            "which axis is: give --up-axis (x, y, z, -x, -y or -z)"
        )
    normal = np.cross(travel, axis)
    nn = float(np.linalg.norm(normal))
    if nn < 0.5:  # the travel runs along the rotation axis: not rolling
        if abs(travel @ z) < math.sin(MAX_TILT_RAD):
            return UpAxis("z", "Z up (Vicon's default): the motion is not a rolling one")
        raise VerticalUndecided(
            f"{where}the wheel does not roll across its axis, so the data cannot say which lab axis is "
            "vertical: give --up-axis (x, y, z, -x, -y or -z)"
        )
    normal /= nn
    k = int(np.argmax(np.abs(normal)))
    tilt = math.acos(min(abs(float(normal[k])), 1.0))
    name = ("-" if normal[k] < 0 else "") + "xyz"[k]
    if tilt >= MAX_TILT_RAD:
        raise VerticalUndecided(
            f"{where}the ramp's normal found from the rolling wheel ({normal[0]:+.2f}, {normal[1]:+.2f}, "
            f"{normal[2]:+.2f}) lies {math.degrees(tilt):.0f} deg from the nearest lab axis ({name}), too far "
            "for a ramp a wheel walks on: the data cannot decide the vertical: give --up-axis "
            "(x, y, z, -x, -y or -z)"
        )
    how = (
        f"the ramp's normal from the rolling wheel (travel x rotation axis) lies {math.degrees(tilt):.1f} deg "
        f"from {name.upper()}"
    )
    return UpAxis(name, f"{name.upper()} up: {how}")


def is_z_up(name: str) -> bool:
    return name.strip().lower().lstrip("+") == "z"
