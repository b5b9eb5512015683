"""Which object or marker set of a Vicon file is the wheel, and what a static ramp says about the slope.

A file may hold several tracked objects (``Objects``) and marker sets (``Trajectories``, grouped by the
subject prefix ``Subject:Marker``), a static ``Ramp`` object or ramp markers, and unlabelled markers (names
such as ``*12`` or ``2 1937``). The wheel is the candidate that turns (more than two steps) while it
translates; a static candidate is never taken as the wheel. A static ramp (an object whose name holds
"ramp", or three or more static markers) gives an independent slope: the tilt of the object's axis nearest
to world Z, or of the plane through the markers. Positions in m, angles in rad inside; degrees in words.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rimless.analysis.io.vicon_file import Section, ViconFile
from rimless.errors import UserError

__all__ = ["SourceChoice", "choose_source", "UNLABELLED", "zeros_to_nan"]

POSE = ("RX", "RY", "RZ", "TX", "TY", "TZ")
XYZ = ("X", "Y", "Z")
#: Names Vicon gives markers it could not label.
UNLABELLED = re.compile(r"^(\*\d+|\d+(\s+\d+)*|unlabell?ed.*|unlabeled.*)$", re.IGNORECASE)
#: A candidate whose positions stay within this extent, m, is static.
STATIC_EXTENT_M = 0.02
#: A marker set with more markers than this is not a wheel (a wheel carries a few markers on its face).
MAX_WHEEL_MARKERS = 8
#: Least rotation, rad, for a candidate to walk (two steps of the eight-legged wheel).
MIN_TURN_RAD = np.pi / 2


class SourceRefused(UserError):
    """No candidate in the file moves like the wheel; the message lists what was found."""


@dataclass(frozen=True)
class SourceChoice:
    """The wheel's data source and why; the ramp measurement when there is one."""

    section: Section
    object: str | None
    markers: tuple[str, ...]
    reason: str
    ramp_slope_deg: float | None = None
    ramp_source: str | None = None
    warnings: tuple[str, ...] = field(default=())

    @property
    def label(self) -> str:
        """``object NAME`` or ``markers A,B,C,D``."""
        return f"object {self.object}" if self.object else f"markers {','.join(self.markers)}"


def zeros_to_nan(values: np.ndarray, width: int) -> np.ndarray:
    """Rows of each ``width``-wide group whose values are all exactly 0 become NaN (occlusions written as 0)."""
    v = np.array(values, float, copy=True)
    for g in range(v.shape[1] // width):
        block = v[:, g * width : (g + 1) * width]
        block[(block == 0).all(axis=1)] = np.nan
    return v


def _subsample(p: np.ndarray) -> np.ndarray:
    """The even subsample of at most 100,000 rows that `_extent` measures (a view)."""
    return p[:: int(np.ceil(p.shape[0] / 100_000))] if p.shape[0] > 100_000 else p


def _extent(p: np.ndarray) -> float:
    """Largest coordinate range of a path (n, 3), m (an even subsample of at most 100,000 frames)."""
    p = _subsample(p)
    ok = ~np.isnan(p).any(axis=1)
    if ok.sum() < 2:
        return 0.0
    q = p[ok]
    return float(np.max(np.ptp(q, axis=0)))


def _object_turn(rotvec: np.ndarray) -> float:
    from rimless.analysis.kinematics.hub import rotations_from_angles, wheel_angle_from_rotations

    rot = rotations_from_angles(rotvec)
    a, _ = wheel_angle_from_rotations(rot)
    return float(np.nanmax(a) - np.nanmin(a)) if np.isfinite(a).any() else 0.0


def _markers_turn(pts: np.ndarray) -> float:
    from rimless.analysis.kinematics.hub import hub_from_markers

    try:
        est = hub_from_markers(pts)
    except ValueError:
        return 0.0
    a = est.wheel_angle_rad
    return float(np.nanmax(a) - np.nanmin(a)) if a is not None and np.isfinite(a).any() else 0.0


def _ramp_from_object(rotvec: np.ndarray) -> float | None:
    from scipy.spatial.transform import Rotation

    ok = ~np.isnan(rotvec).any(axis=1)
    if not ok.any():
        return None
    mats = Rotation.from_rotvec(rotvec[ok]).as_matrix()
    # The object's axis nearest world Z is taken as the ramp normal (median over the frames).
    cz = np.median(np.abs(mats[:, 2, :]), axis=0)
    return float(np.degrees(np.arccos(np.clip(cz.max(), -1.0, 1.0))))


def _ramp_from_markers(pts: np.ndarray) -> float | None:
    """Tilt of the plane through static markers, deg (None when they are collinear)."""
    mean = np.nanmedian(pts, axis=0)  # (k, 3)
    mean = mean[~np.isnan(mean).any(axis=1)]
    if mean.shape[0] < 3:
        return None
    c = mean - mean.mean(axis=0)
    _, sv, vt = np.linalg.svd(c)
    if sv[1] < 0.05 * sv[0] or sv[1] < 0.05:
        return None
    n = vt[2]
    return float(np.degrees(np.arccos(min(abs(n[2]), 1.0))))


#: Markers of one set closer together than this, m, mean the numbers are not in the unit the file says.
MIN_SPAN_M = 0.005


def _check_span(vf: ViconFile, sec: Section, subj: str, names: list[str]) -> None:
    """Refuse, naming the units row, when a marker set is far too small to be on a wheel or a ramp."""
    if len(names) < 3:
        return
    pts = np.stack([zeros_to_nan(sec.get(m, XYZ), 3) for m in names], axis=1)
    seen = pts[: min(pts.shape[0], 2000)]
    med = np.full(pts.shape[1:], np.nan)
    have = ~np.isnan(seen).all(axis=0).any(axis=1)
    if have.sum() < 3:
        return
    med[have] = np.nanmedian(seen[:, have], axis=0)
    med = med[have]
    if med.shape[0] < 3:
        return
    span = float(np.max(np.ptp(med, axis=0)))
    if 0 < span < MIN_SPAN_M:
        unit = sorted({c.file_unit for c in sec.columns if c.group in names})
        raise SourceRefused(
            f"{vf.path}:{sec.units_line}:1: the units row says {'/'.join(unit)}, but the markers of "
            f"{subj or 'the file'} lie within {span * 1e3:.2g} mm of each other (a wheel is about 0.2-0.5 m across):"
            " the numbers are likely in m; fix the units row"
        )


def choose_source(
    vf: ViconFile, obj: str | None, markers: Sequence[str] | None, *, label: str = "--object"
) -> SourceChoice:
    """Pick the wheel among the file's objects and marker sets (see the module doc).

    ``obj``/``markers`` force a choice (CLI ``--object``/``--markers``); anything missing is refused naming
    the option and what exists.
    """
    warns: list[str] = []
    objects_sec = [s for s in vf.sections if s.kind == "Objects"]
    traj_sec = [s for s in vf.sections if s.kind == "Trajectories"]
    cands: list[tuple[str, Section, str | None, tuple[str, ...]]] = []  # (kind, section, object, markers)
    static_objects: list[tuple[Section, str]] = []
    static_markers: list[tuple[Section, str]] = []
    unlabelled: list[str] = []
    too_many: list[str] = []
    for sec in objects_sec:
        for g in sec.groups():
            if set(POSE) <= set(sec.components(g)):
                cands.append(("object", sec, g, ()))
    for sec in traj_sec:
        by_subject: dict[str, list[str]] = {}
        for g in sec.groups():
            if not set(XYZ) <= set(sec.components(g)):
                continue
            if UNLABELLED.match(g.strip()):
                unlabelled.append(g)
                continue
            by_subject.setdefault(g.split(":")[0] if ":" in g else "", []).append(g)
        for subj, names in by_subject.items():
            moving = []
            for m in names:
                p = zeros_to_nan(sec.get(m, XYZ), 3)
                if np.isnan(p).all():
                    continue
                if _extent(p) < STATIC_EXTENT_M:
                    static_markers.append((sec, m))
                else:
                    moving.append(m)
            _check_span(vf, sec, subj, names)
            if len(moving) > MAX_WHEEL_MARKERS:
                too_many.append(f"{subj or '(no subject)'}: {len(names)}")
            elif moving:
                cands.append(("markers", sec, subj or None, tuple(moving)))
    if unlabelled:
        warns.append(
            f"{len(unlabelled)} unlabelled marker(s) ignored ({', '.join(unlabelled[:4])}"
            f"{', ...' if len(unlabelled) > 4 else ''})"
        )

    # forced choices
    if markers:
        msec = next((s for s in traj_sec if all(m in s.groups() for m in markers)), None)
        if msec is None:
            have = traj_sec[0].groups() if traj_sec else []
            missing = [m for m in markers if m not in have]
            raise SourceRefused(
                f"{vf.path}: --markers {','.join(markers)}: "
                + (
                    f"marker(s) {missing} not in the Trajectories section (line {traj_sec[0].line})"
                    if traj_sec
                    else "the file has no Trajectories section"
                )
            )
        chosen = SourceChoice(msec, None, tuple(markers), "markers given with --markers")
        return _with_ramp(vf, chosen, objects_sec, static_markers, warns, exclude_object=None)
    if obj is not None:
        for kind, sec, o, mk in cands:  # noqa: B007
            if kind == "object" and o == obj:
                return _with_ramp(
                    vf,
                    SourceChoice(sec, obj, (), f"object {obj} given with --object"),
                    objects_sec,
                    static_markers,
                    warns,
                    exclude_object=obj,
                )
        for kind, sec, o, mk in cands:
            if kind == "markers" and o == obj:
                return _with_ramp(
                    vf,
                    SourceChoice(sec, None, mk, f"markers of subject {obj} given with --object"),
                    objects_sec,
                    static_markers,
                    warns,
                    exclude_object=None,
                )
        names = [o for k, _, o, _ in cands if o]
        raise SourceRefused(
            f"{vf.path}: --object {obj}: no object or marker subject of that name; found {', '.join(names) or 'none'}"
        )

    scored = []
    if len(cands) == 1 and not too_many:
        # One candidate: take it unless it is static (its rotation is checked by the step detection).
        kind, sec, o, mk = cands[0]
        # zeros_to_nan is row by row: applied to the rows `_extent` measures only
        if kind == "object":
            assert o is not None  # an object candidate is named by its group
            ext = _extent(zeros_to_nan(_subsample(sec.get(o, POSE)), 6)[:, 3:])
        else:
            ext = max(_extent(zeros_to_nan(_subsample(sec.get(m, XYZ)), 3)) for m in mk)
        if ext >= STATIC_EXTENT_M:
            what = f"object {o}" if kind == "object" else f"markers {','.join(mk)}"
            chosen = SourceChoice(
                sec,
                o if kind == "object" else None,
                mk if kind == "markers" else (),
                f"{what} ({sec.kind}, line {sec.line}): the only moving candidate (moves {ext:.2f} m)",
            )
            return _with_ramp(
                vf, chosen, objects_sec, static_markers, warns, exclude_object=o if kind == "object" else None
            )
    for kind, sec, o, mk in cands:
        if kind == "object":
            assert o is not None  # an object candidate is named by its group
            data = zeros_to_nan(sec.get(o, POSE), 6)
            ext = _extent(data[:, 3:])
            turn = _object_turn(data[:, :3]) if ext >= STATIC_EXTENT_M else 0.0
            if ext < STATIC_EXTENT_M:
                static_objects.append((sec, o))
        else:
            pts = np.stack([zeros_to_nan(sec.get(m, XYZ), 3) for m in mk], axis=1)
            ext = max(_extent(pts[:, i]) for i in range(len(mk)))
            turn = _markers_turn(pts) if len(mk) >= 3 else np.nan
        scored.append((kind, sec, o, mk, ext, turn))
    walkers = [c for c in scored if c[4] >= 0.1 and (np.isnan(c[5]) or c[5] >= MIN_TURN_RAD)]
    if not walkers:
        found = [
            f"{'object ' + str(o) if k == 'object' else (o or '(no subject)') + ': ' + str(len(mk))} "
            f"(moves {e * 1e3:.0f} mm, turns {np.degrees(tn):.0f} deg)"
            for k, _, o, mk, e, tn in scored
        ]
        found += [f"{t} markers (too many for a wheel)" for t in too_many]
        if unlabelled:
            moving_u = (
                [
                    g
                    for g in unlabelled
                    if _extent(zeros_to_nan(_subsample(traj_sec[0].get(g, XYZ)), 3)) >= STATIC_EXTENT_M
                ]
                if len(traj_sec) == 1
                else []
            )
            pick = (moving_u or unlabelled)[:MAX_WHEEL_MARKERS]
            raise SourceRefused(
                f"{vf.path}: nothing labelled moves like the wheel"
                + (f" (found {'; '.join(found)})" if found else "")
                + f"; {len(unlabelled)} unlabelled marker(s) ({', '.join(unlabelled[:6])}"
                + (", ..." if len(unlabelled) > 6 else "")
                + f"{'; ' + str(len(moving_u)) + ' of them move' if moving_u else ''}) are never taken "
                f"as the wheel without a name: name the wheel's markers with --markers {','.join(pick)}"
            )
        if not found and static_markers:
            shown = ", ".join(m for _, m in static_markers[:6]) + (", ..." if len(static_markers) > 6 else "")
            raise SourceRefused(
                f"{vf.path}: nothing moves like the wheel: only static markers ({shown}: each moves "
                f"less than {STATIC_EXTENT_M * 1e3:.0f} mm); choose with --markers A,B,C,D"
            )
        if not found:
            kinds = ", ".join(f"{s.kind} (line {s.line}, {len(s.groups())} channels)" for s in vf.sections)
            raise SourceRefused(
                f"{vf.path}: no usable trajectory: no Objects or Trajectories section with a "
                f"moving object or marker set, only {kinds}"
            )
        raise SourceRefused(
            f"{vf.path}: nothing moves like the wheel (turning more than "
            f"{np.degrees(MIN_TURN_RAD):.0f} deg while it travels); found {'; '.join(found)}; "
            "choose with --object NAME or --markers A,B,C,D"
        )
    # Prefer a rigid body that turns (objects, then marker sets of 3 or more), the largest rotation first.
    walkers.sort(key=lambda c: (np.isnan(c[5]), -(c[5] if not np.isnan(c[5]) else 0), c[0] != "object"))
    kind, sec, o, mk, ext, turn = walkers[0]
    others = [c for c in scored if c is not walkers[0]]
    what = f"object {o}" if kind == "object" else f"markers {','.join(mk)}"
    motion = (
        f"turns {np.degrees(turn):.0f} deg while it moves {ext:.2f} m"
        if not np.isnan(turn)
        else f"moves {ext:.2f} m (one marker: no rotation)"
    )
    reason = f"{what} ({sec.kind}, line {sec.line}) {motion}"
    if others:
        reason += "; also found: " + ", ".join(
            (f"object {c[2]}" if c[0] == "object" else f"markers {','.join(c[3])}")
            + (
                " (static)"
                if c[4] < STATIC_EXTENT_M
                else f" (turns {np.degrees(c[5]):.0f} deg)"
                if not np.isnan(c[5])
                else " (moves)"
            )
            for c in others
        )
    if len(walkers) > 1:
        warns.append(f"{len(walkers)} candidates move like a wheel; took {what} (choose with --object/--markers)")
    chosen = SourceChoice(sec, o if kind == "object" else None, mk if kind == "markers" else (), reason)
    return _with_ramp(
        vf,
        chosen,
        objects_sec,
        static_markers,
        warns,
        exclude_object=o if kind == "object" else None,
        static_objects=static_objects,
    )


def _with_ramp(
    vf: ViconFile,
    chosen: SourceChoice,
    objects_sec: list[Section],
    static_markers: list[tuple[Section, str]],
    warns: list[str],
    *,
    exclude_object: str | None,
    static_objects: list[tuple[Section, str]] | None = None,
) -> SourceChoice:
    if static_objects is None:
        static_objects = []
        for sec in objects_sec:
            for g in sec.groups():
                if g != exclude_object and set(POSE) <= set(sec.components(g)):
                    d = zeros_to_nan(sec.get(g, POSE), 6)
                    if _extent(d[:, 3:]) < STATIC_EXTENT_M:
                        static_objects.append((sec, g))
    slope = src = None
    ramps = [(s, g) for s, g in static_objects if "ramp" in g.lower()]
    if ramps:
        sec, g = ramps[0]
        slope = _ramp_from_object(zeros_to_nan(sec.get(g, POSE), 6)[:, :3])
        src = f"static object {g} ({sec.kind}, line {sec.line}): tilt of its axis nearest to vertical"
    mk = [(s, m) for s, m in static_markers if m not in chosen.markers]
    if slope is None and len(mk) >= 3:
        pts = np.stack([zeros_to_nan(s.get(m, XYZ), 3) for s, m in mk], axis=1)
        slope = _ramp_from_markers(pts)
        if slope is not None:
            src = f"plane through {len(mk)} static markers ({', '.join(m for _, m in mk[:6])})"
    for s, g in static_objects:
        if (s, g) not in ramps[:1]:
            warns.append(f"static object {g} ignored")
    return SourceChoice(chosen.section, chosen.object, chosen.markers, chosen.reason, slope, src, tuple(warns))
