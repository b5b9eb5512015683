"""A wheel trial: one tidy time series plus metadata, built from a Vicon export and stored as Parquet.

Data (all on the full frame grid from the first to the last frame; missing rows are gaps):

========================  ======  ==========================================================
key                       shape   meaning
========================  ======  ==========================================================
``frame``                 (n,)    Vicon frame number
``hub``                   (n, 3)  world hub position, m
``hub_slope``             (n, 3)  hub in the slope frame (x down the slope, y normal, z lateral), m
``com_height``            (n,)    CoM height = hub height normal to the slope, m
``wheel_angle``           (n,)    unwrapped wheel angle, rad (only when orientation is known)
``gap``                   (n,)    True where the hub is unknown (NaN)
``interpolated``          (n,)    True where a short gap was filled by the bounded rule
========================  ======  ==========================================================

Events: ``("impact", time_s)``. ``Trial.meta`` holds source file, section, object or markers, rate, file
units, hub and slope provenance, the gap rule and the step detection.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from rimless.errors import InputFileError, UserError

from .hub import HubEstimate, hub_from_markers, hub_from_object
from .slope import SlopeFrame, fit_slope
from .steps import ALPHA_RAD, StepResult, detect_steps, find_com_minima, refine_cusp
from .timeseries import Event, TimeSeries
from .vicon_csv import Section, ViconFile, read_vicon_csv

__all__ = ["Trial", "TrialMeta", "TrialRefused", "build_trial", "import_trial", "read_trial", "fill_short_gaps"]

PARQUET_META_KEY = b"rimless.trial"
FORMAT_VERSION = 1
_POSE = ("RX", "RY", "RZ", "TX", "TY", "TZ")
_XYZ = ("X", "Y", "Z")


class TrialRefused(UserError):
    """A file parsed but holds no usable wheel trajectory; the message says why."""


@dataclass(frozen=True)
class TrialMeta:
    """Everything about a trial that is not a time series (JSON-serialisable; SI with unit suffixes)."""

    source_file: str
    section: str
    section_line: int
    object: str | None
    markers: tuple[str, ...]
    rate_hz: float
    first_frame: int
    n_frames: int
    file_units: dict[str, str]
    hub_source: str
    hub_offset_m: tuple[float, float, float] | None
    orientation: str | None
    slope_deg: float
    slope_source: str
    slope_residual_m: float
    slope_points: int
    travel_direction: tuple[float, float, float]
    slope_origin_m: tuple[float, float, float]
    com_height_reference: str
    max_gap_s: float
    n_gap_frames: int
    n_interpolated_frames: int
    step_method: str
    step_refused: str | None
    step_phase_rad: float | None
    alpha_rad: float = ALPHA_RAD
    notes: tuple[str, ...] = field(default=())
    format_version: int = FORMAT_VERSION

    def to_json(self) -> str:
        """JSON text of the metadata (NaN as null)."""
        d = asdict(self)
        return json.dumps(_nan_to_none(d))

    @classmethod
    def from_json(cls, text: str) -> TrialMeta:
        """Inverse of `to_json`."""
        d = json.loads(text)
        for k in ("markers", "notes"):
            d[k] = tuple(d[k])
        for k in ("hub_offset_m", "travel_direction", "slope_origin_m"):
            if d.get(k) is not None:
                d[k] = tuple(d[k])
        if d.get("slope_residual_m") is None:
            d["slope_residual_m"] = float("nan")
        return cls(**d)


@dataclass(frozen=True, eq=False)
class Trial:
    """A wheel trial: ``series`` (see the module doc for keys) and ``meta``."""

    series: TimeSeries
    meta: TrialMeta

    # -- convenient views
    @property
    def time_s(self) -> np.ndarray:
        """(n,) s from the first frame."""
        return self.series.time_s

    @property
    def impact_time_s(self) -> np.ndarray:
        """Impact times, s."""
        return self.series.get_event_times("impact")

    @property
    def step_period_s(self) -> np.ndarray:
        """Time between consecutive impacts, s; entry k-1 is step k."""
        return np.diff(self.impact_time_s)

    @property
    def steps(self) -> StepResult:
        """The step detection as a `StepResult`."""
        t = self.impact_time_s
        return StepResult(t, np.diff(t), self.meta.step_method, self.meta.step_refused, self.meta.step_phase_rad)

    def summary(self) -> dict[str, Any]:
        """A JSON-ready summary: metadata, slope estimate, steps and periods."""
        m = self.meta
        return {
            "file": m.source_file,
            "section": m.section,
            "object": m.object,
            "markers": list(m.markers),
            "frames": m.n_frames,
            "first_frame": m.first_frame,
            "rate_hz": m.rate_hz,
            "duration_s": float(self.time_s[-1]) if len(self.time_s) else 0.0,
            "file_units": m.file_units,
            "hub_source": m.hub_source,
            "hub_offset_m": m.hub_offset_m,
            "orientation": m.orientation,
            "slope_deg": m.slope_deg,
            "slope_source": m.slope_source,
            "slope_residual_m": m.slope_residual_m,
            "com_height_reference": m.com_height_reference,
            "gap_frames": m.n_gap_frames,
            "interpolated_frames": m.n_interpolated_frames,
            "max_gap_s": m.max_gap_s,
            "step_method": m.step_method,
            "step_refused": m.step_refused,
            "steps": int(self.step_period_s.size),
            "impact_time_s": self.impact_time_s.tolist(),
            "step_period_s": self.step_period_s.tolist(),
            "notes": list(m.notes),
        }

    # -- storage
    def to_parquet(self, path: str | Path) -> Path:
        """Write the trial as one Parquet file (columns below, metadata as JSON); atomic (temp + rename)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        s = self.series
        cols: dict[str, Any] = {"frame": s["frame"].astype(np.int64), "time_s": s.time_s}
        for i, ax in enumerate("xyz"):
            cols[f"hub_{ax}_m"] = s["hub"][:, i]
        for i, ax in enumerate("xyz"):
            cols[f"slope_{ax}_m"] = s["hub_slope"][:, i]
        cols["com_height_m"] = s["com_height"]
        if "wheel_angle" in s.data:
            cols["wheel_angle_rad"] = s["wheel_angle"]
        cols["gap"] = s["gap"].astype(bool)
        cols["interpolated"] = s["interpolated"].astype(bool)
        table = pa.table(cols)
        extra = {"meta": json.loads(self.meta.to_json()), "impact_time_s": self.impact_time_s.tolist()}
        table = table.replace_schema_metadata({PARQUET_META_KEY: json.dumps(extra).encode()})
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.name + f".tmp{os.getpid()}")
        try:
            pq.write_table(table, tmp)
            os.replace(tmp, out)
        finally:
            if tmp.exists():
                tmp.unlink()
        return out


def read_trial(path: str | Path) -> Trial:
    """Read a trial written by `Trial.to_parquet`. Raises `InputFileError` if it is not one."""
    import pyarrow.parquet as pq

    p = Path(path)
    if not p.is_file():
        raise InputFileError(f"{p}: no such trial file")
    try:
        table = pq.read_table(p)
    except (OSError, ValueError) as err:
        raise InputFileError(f"{p}: not a readable Parquet trial ({err})") from None
    md = table.schema.metadata or {}
    if PARQUET_META_KEY not in md:
        raise InputFileError(f"{p}: Parquet file without rimless trial metadata (not written by `trials import`)")
    extra = json.loads(md[PARQUET_META_KEY])
    meta = TrialMeta.from_json(json.dumps(extra["meta"]))
    c = {name: table.column(name).to_numpy() for name in table.column_names}
    ts = TimeSeries(
        c["time_s"],
        {},
        tuple(Event(t, "impact") for t in extra["impact_time_s"]),
    )
    ts = ts.add_data("frame", c["frame"].astype(np.int64))
    ts = _add_standard(ts, np.column_stack([c["hub_x_m"], c["hub_y_m"], c["hub_z_m"]]),
                       np.column_stack([c["slope_x_m"], c["slope_y_m"], c["slope_z_m"]]), c["com_height_m"],
                       c.get("wheel_angle_rad"), c["gap"].astype(bool), c["interpolated"].astype(bool))
    return Trial(ts, meta)


def _add_standard(ts: TimeSeries, hub: np.ndarray, hub_slope: np.ndarray, com: np.ndarray,
                  angle: np.ndarray | None, gap: np.ndarray, interp: np.ndarray) -> TimeSeries:
    ts = ts.add_data("hub", hub, unit="m", frame="world")
    ts = ts.add_data("hub_slope", hub_slope, unit="m", frame="slope (x down the slope, y normal, z lateral)")
    ts = ts.add_data("com_height", com, unit="m")
    if angle is not None:
        ts = ts.add_data("wheel_angle", angle, unit="rad")
    ts = ts.add_data("gap", gap)
    return ts.add_data("interpolated", interp)


def fill_short_gaps(values: np.ndarray, max_gap_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Linearly interpolate runs of at most ``max_gap_frames`` NaN rows that have valid rows on both sides.

    Returns (filled copy, bool mask of filled rows). Longer runs and runs at the ends stay NaN.
    """
    v = np.array(values, dtype=np.float64, copy=True)
    bad = np.isnan(v.reshape(v.shape[0], -1)).any(axis=1)
    filled = np.zeros(v.shape[0], bool)
    if max_gap_frames <= 0 or not bad.any() or bad.all():
        return v, filled
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    for a, b in zip(starts, stops):
        if a == 0 or b == v.shape[0] or b - a > max_gap_frames:
            continue
        w = (np.arange(a, b) - (a - 1)) / (b - (a - 1))
        v[a:b] = v[a - 1] + np.multiply.outer(w, v[b] - v[a - 1]) if v.ndim > 1 else v[a - 1] + w * (v[b] - v[a - 1])
        filled[a:b] = True
    return v, filled


# --------------------------------------------------------------------------------------------- building


def _pick_source(vf: ViconFile, obj: str | None, markers: Sequence[str] | None) -> tuple[Section, str | None, list[str]]:
    kinds = vf.kinds()
    if markers:
        sec = vf.section("Trajectories")
        if sec is None:
            raise TrialRefused(f"{vf.path}: markers were asked for but the file has no Trajectories section "
                               f"(sections: {', '.join(kinds)})")
        missing = [m for m in markers if m not in sec.groups()]
        if missing:
            raise TrialRefused(f"{vf.path}: marker(s) {missing} not in the Trajectories section (line {sec.line})")
        return sec, None, list(markers)
    sec = vf.section("Objects")
    if sec is not None:
        objs = [g for g in sec.groups() if set(_POSE) <= set(sec.components(g))]
        if obj is not None:
            if obj not in objs:
                raise TrialRefused(f"{vf.path}: object {obj!r} not in the Objects section (line {sec.line}); "
                                   f"objects: {', '.join(objs) or 'none'}")
            return sec, obj, []
        if len(objs) == 1:
            return sec, objs[0], []
        if len(objs) > 1:
            raise TrialRefused(f"{vf.path}: the Objects section (line {sec.line}) holds {len(objs)} objects "
                               f"({', '.join(objs)}): choose one with object=")
    sec = vf.section("Trajectories")
    if sec is not None:
        groups = [g for g in sec.groups() if set(_XYZ) <= set(sec.components(g))]
        if obj is not None:
            groups = [g for g in groups if g.split(":")[0] == obj]
        if len(groups) in (1, 4):
            return sec, None, groups
        subjects: dict[str, int] = {}
        for g in groups:
            subjects[g.split(":")[0] if ":" in g else "(unlabelled)"] = subjects.get(
                g.split(":")[0] if ":" in g else "(unlabelled)", 0) + 1
        four = [s for s, n in subjects.items() if n == 4]
        if obj is None and len(four) == 1:
            return sec, None, [g for g in groups if g.split(":")[0] == four[0]]
        detail = ", ".join(f"{s}: {n}" for s, n in subjects.items())
        raise TrialRefused(
            f"{vf.path}: no Objects section, and the Trajectories section (line {sec.line}) has {len(groups)} "
            f"markers ({detail}); a wheel trial needs the 4 wheel markers (or 1 hub marker): choose them "
            "with markers= (CLI: --markers A,B,C,D)")
    others = ", ".join(f"{s.kind} (line {s.line}, {len(s.groups())} channels)" for s in vf.sections)
    raise TrialRefused(f"{vf.path}: no usable trajectory: no Objects or Trajectories section, only {others}")


def _full_grid(sec: Section) -> tuple[np.ndarray, np.ndarray]:
    """(all frames from first to last, row index of each in the section or -1)."""
    if sec.n_rows and sec.sub_frame.max() > 0:
        raise TrialRefused(f"section {sec.kind!r} (line {sec.line}) has sub frames: not a trajectory")
    frames = np.arange(sec.frame[0], sec.frame[-1] + 1)
    row = np.full(frames.size, -1, np.int64)
    row[sec.frame - sec.frame[0]] = np.arange(sec.n_rows)
    return frames, row


def _on_grid(arr: np.ndarray, row: np.ndarray) -> np.ndarray:
    out = np.full((row.size,) + arr.shape[1:], np.nan)
    ok = row >= 0
    out[ok] = arr[row[ok]]
    return out


def build_trial(
    vf: ViconFile,
    *,
    object: str | None = None,  # noqa: A002 - the Vicon word
    markers: Sequence[str] | None = None,
    slope_deg: float | None = None,
    hub_offset_m: Sequence[float] | None = None,
    orientation: str = "helical",
    leg_length_m: float | None = None,
    max_gap_s: float = 0.0,
    alpha_rad: float = ALPHA_RAD,
) -> Trial:
    """Build a `Trial` from a parsed Vicon file.

    Parameters
    ----------
    vf : from `read_vicon_csv`.
    object : tracked object (Objects section) or subject prefix of the markers; default: the only one.
    markers : names of the wheel markers (4 in one plane, or 1 at the hub) in the Trajectories section.
    slope_deg : known slope, deg; default: estimated from the hub path (see `TrialMeta.slope_source`).
    hub_offset_m : hub in the object frame, m; default: estimated when the object turns enough
        (see `hub_from_object`).
    orientation : convention of RX, RY, RZ (``"helical"`` or a scipy Euler sequence such as ``"xyz"``).
    leg_length_m : leg length; when given, CoM height is measured from the slope plane
        (impact line - leg_length * cos(alpha / 2)); otherwise from the line through the impacts.
    max_gap_s : gaps up to this long are linearly interpolated (flagged ``interpolated``); longer stay NaN.
    alpha_rad : rotation per step, rad.

    Raises
    ------
    TrialRefused
        When the file holds no usable wheel trajectory (message says why).
    """
    sec, obj, mk = _pick_source(vf, object, markers)
    if sec.n_rows < 10:
        raise TrialRefused(f"{vf.path}: section {sec.kind!r} (line {sec.line}) has {sec.n_rows} rows: too short")
    frames, row = _full_grid(sec)
    notes: list[str] = []
    if obj is not None:
        pose = _on_grid(sec.get(obj, _POSE), row)
        if np.isnan(pose).all():
            raise TrialRefused(f"{vf.path}: object {obj!r} has no values (never tracked)")
        est = hub_from_object(pose[:, :3], pose[:, 3:], hub_offset_m=hub_offset_m, convention=orientation)
        units = {c.component: c.file_unit for c in sec.columns if c.group == obj}
    else:
        pts = np.stack([_on_grid(sec.get(m, _XYZ), row) for m in mk], axis=1)
        counts = (~np.isnan(pts).any(axis=2)).sum(axis=0)
        if (counts == 0).any():
            dead = [m for m, c in zip(mk, counts) if c == 0]
            raise TrialRefused(f"{vf.path}: marker(s) {dead} have no values in any frame")
        try:
            est = hub_from_markers(pts)
        except ValueError as err:
            raise TrialRefused(f"{vf.path}: {err}") from None
        units = {f"{m}.{c.component}": c.file_unit for m in mk for c in sec.columns if c.group == m}
    hub_raw = est.hub_m
    angle = est.wheel_angle_rad
    rate = sec.rate_hz
    max_gap_frames = int(math.floor(max_gap_s * rate + 1e-9))
    hub, filled = fill_short_gaps(hub_raw, max_gap_frames)
    if angle is not None:
        angle, _ = fill_short_gaps(angle, max_gap_frames)
    gap = np.isnan(hub).any(axis=1)
    if gap.all() or (~gap).sum() < 10:
        raise TrialRefused(f"{vf.path}: fewer than 10 frames with a known hub")
    time_s = (frames - frames[0]) / rate

    frame0 = fit_slope(hub, slope_deg=slope_deg)
    travel = frame0.travel
    y = frame0.to_slope(hub)[:, 1]
    period_guess = None
    if angle is not None and np.isfinite(angle).any():
        total = float(np.nanmax(angle) - np.nanmin(angle))
        if total > 0:
            period_guess = alpha_rad / (total / (time_s[~gap][-1] - time_s[~gap][0]))
    idx, _, _ = find_com_minima(time_s, y, min_period_s=period_guess)
    reference = "the robust line through the hub path"
    frame = frame0
    if idx.size >= 3:
        frame = fit_slope(hub, slope_deg=slope_deg, points_m=_hub_at_cusps(time_s, hub, idx), travel=travel)
        reference = f"the line through the hub at {idx.size} CoM-height minima (impacts)"
    elif slope_deg is None:
        notes.append(f"slope fitted on the whole hub path ({idx.size} CoM minima found, 3 needed for the "
                     "impact line)")
    hub_slope = frame.to_slope(hub)
    com = hub_slope[:, 1].copy()
    if leg_length_m is not None:
        com = com + leg_length_m * math.cos(alpha_rad / 2)
        reference = f"slope plane = {reference} minus leg_length_m*cos(alpha/2) ({leg_length_m} m)"
    else:
        reference = f"height above {reference}"
    steps = detect_steps(time_s, com, angle, alpha_rad=alpha_rad)

    ts = TimeSeries(time_s, {}, tuple(Event(t, "impact") for t in steps.impact_time_s))
    ts = ts.add_data("frame", frames)
    ts = _add_standard(ts, hub, hub_slope, com, angle, gap, filled)
    meta = TrialMeta(
        source_file=str(vf.path),
        section=sec.kind,
        section_line=sec.line,
        object=obj,
        markers=tuple(mk),
        rate_hz=float(rate),
        first_frame=int(frames[0]),
        n_frames=int(frames.size),
        file_units=units,
        hub_source=est.source,
        hub_offset_m=None if est.offset_m is None else tuple(float(v) for v in est.offset_m),
        orientation=(orientation if obj is not None else "markers") if angle is not None else None,
        slope_deg=frame.slope_deg,
        slope_source=frame.source,
        slope_residual_m=frame.residual_m,
        slope_points=frame.n_points,
        travel_direction=tuple(float(v) for v in travel),
        slope_origin_m=tuple(float(v) for v in frame.origin_m),
        com_height_reference=reference,
        max_gap_s=float(max_gap_s),
        n_gap_frames=int(gap.sum()),
        n_interpolated_frames=int(filled.sum()),
        step_method=steps.method,
        step_refused=steps.refused,
        step_phase_rad=steps.phase_rad,
        alpha_rad=float(alpha_rad),
        notes=tuple(notes),
    )
    return Trial(ts, meta)


def _hub_at_cusps(time_s: np.ndarray, hub: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Hub at each CoM-height cusp: height from the V fit of Z, horizontal position interpolated."""
    half = max(3, int(0.25 * np.median(np.diff(idx)))) if idx.size > 1 else 5
    ok = ~np.isnan(hub).any(axis=1)
    tv, hv = time_s[ok], hub[ok]
    out = np.empty((idx.size, 3))
    for k, i in enumerate(idx):
        out[k, 0], out[k, 2] = refine_cusp(time_s, hub[:, 2], int(i), half)
    tc = out[:, 0].copy()
    out[:, 0] = np.interp(tc, tv, hv[:, 0])
    out[:, 1] = np.interp(tc, tv, hv[:, 1])
    return out


def import_trial(path: str | Path, **kwargs: Any) -> Trial:
    """`read_vicon_csv` then `build_trial` (keyword arguments as there)."""
    return build_trial(read_vicon_csv(path), **kwargs)


def _nan_to_none(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


# Keep names used only in annotations importable for users of this module.
_ = (HubEstimate, SlopeFrame, replace)
