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

from rimless.analysis.kinematics.hub import HubEstimate
from rimless.analysis.kinematics.slope import SlopeFrame, fit_slope
from rimless.analysis.kinematics.steps import ALPHA_RAD, StepResult, detect_steps, find_com_minima, refine_cusps
from rimless.analysis.io.timeseries import Event, TimeSeries
from rimless.analysis.io.vicon_csv import Section, ViconFile, read_vicon_csv

__all__ = ["Trial", "TrialMeta", "TrialRefused", "build_trial", "import_trial", "read_trial", "fill_short_gaps",
           "DEFAULT_MAX_GAP_S"]

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
    source_reason: str = ""
    ramp_slope_deg: float | None = None
    ramp_source: str | None = None
    outcome: str = "unknown"
    outcome_reason: str = ""
    window_s: tuple[float, float] | None = None
    hub_offset_residual_m: float | None = None
    impact_step: tuple[int, ...] = field(default=())
    period_step: tuple[int, ...] = field(default=())
    warnings: tuple[str, ...] = field(default=())

    def to_json(self) -> str:
        """JSON text of the metadata (NaN as null)."""
        d = asdict(self)
        return json.dumps(_nan_to_none(d))

    @classmethod
    def from_json(cls, text: str) -> TrialMeta:
        """Inverse of `to_json`."""
        d = json.loads(text)
        for k in ("markers", "notes", "impact_step", "period_step", "warnings"):
            d[k] = tuple(d.get(k) or ())
        for k in ("hub_offset_m", "travel_direction", "slope_origin_m", "window_s"):
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
    def impact_step(self) -> np.ndarray:
        """Step count of each impact from the first observed one (impacts lost in gaps skip numbers)."""
        ks = self.meta.impact_step
        return np.asarray(ks, np.int64) if len(ks) == self.impact_time_s.size else np.arange(self.impact_time_s.size)

    @property
    def period_step(self) -> np.ndarray:
        """`impact_step` of the impact that ends each period in `step_period_s`."""
        if self.meta.impact_step or self.meta.period_step:
            return np.asarray(self.meta.period_step, np.int64)
        return np.arange(1, max(self.impact_time_s.size, 1))

    @property
    def step_period_s(self) -> np.ndarray:
        """Step periods whose two impacts were both observed with no gap between them, s (see `period_step`)."""
        t, ks = self.impact_time_s, self.impact_step
        if t.size < 2:
            return np.zeros(0)
        pos = {int(k): i for i, k in enumerate(ks)}
        return np.array([t[pos[int(k)]] - t[pos[int(k) - 1]] for k in self.period_step
                         if int(k) in pos and int(k) - 1 in pos], dtype=np.float64)

    @property
    def consecutive_periods_s(self) -> np.ndarray:
        """The longest run of consecutive valid periods (for comparisons that need consecutive steps), s."""
        p, ks = self.step_period_s, self.period_step
        if p.size == 0:
            return p
        breaks = np.flatnonzero(np.diff(ks) != 1) + 1
        runs = np.split(np.arange(p.size), breaks)
        best = max(runs, key=len)
        return p[best]

    @property
    def steps(self) -> StepResult:
        """The step detection as a `StepResult`."""
        t = self.impact_time_s
        return StepResult(t, self.step_period_s, self.meta.step_method, self.meta.step_refused,
                          self.meta.step_phase_rad, self.impact_step, self.period_step)

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
            "period_step": self.period_step.tolist(),
            "impact_step": self.impact_step.tolist(),
            "notes": list(m.notes),
            "source": m.source_reason,
            "ramp_slope_deg": m.ramp_slope_deg,
            "ramp_source": m.ramp_source,
            "outcome": m.outcome,
            "outcome_reason": m.outcome_reason,
            "window_s": list(m.window_s) if m.window_s else None,
            "hub_offset_mm": None if m.hub_offset_m is None else [v * 1e3 for v in m.hub_offset_m],
            "hub_offset_residual_mm": None if m.hub_offset_residual_m is None else m.hub_offset_residual_m * 1e3,
            "warnings": list(m.warnings),
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
    ts = TimeSeries(c["time_s"]).add_data("frame", c["frame"].astype(np.int64))
    ts = _add_standard(ts, np.column_stack([c["hub_x_m"], c["hub_y_m"], c["hub_z_m"]]),
                       np.column_stack([c["slope_x_m"], c["slope_y_m"], c["slope_z_m"]]), c["com_height_m"],
                       c.get("wheel_angle_rad"), c["gap"].astype(bool), c["interpolated"].astype(bool))
    ts = replace(ts, events=tuple(Event(float(t), "impact") for t in extra["impact_time_s"]))
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
    n = v.shape[0]
    bad = np.isnan(v.reshape(n, -1)).any(axis=1)
    filled = np.zeros(n, bool)
    if max_gap_frames <= 0 or not bad.any() or bad.all():
        return v, filled
    edges = np.diff(bad.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    del edges
    short = (starts > 0) & (stops < n) & (stops - starts <= max_gap_frames)
    if not short.any():
        return v, filled
    # every row of every short run, with the valid rows on each side (only those rows are touched)
    left, right = starts[short] - 1, stops[short]
    lens = right - left - 1
    rows = np.arange(int(lens.sum())) + np.repeat(left + 1 - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens)
    left, right = np.repeat(left, lens), np.repeat(right, lens)
    flat = v.reshape(n, -1)
    for c in range(flat.shape[1]):  # np.interp's formula between the two valid rows: slope * (x - x0) + f0
        f0, f1 = flat[left, c], flat[right, c]
        flat[rows, c] = (f1 - f0) / (right - left) * (rows - left) + f0
    filled[rows] = True
    return v, filled


# --------------------------------------------------------------------------------------------- building

#: The one gap rule of `trials import` and `trials report`: gaps up to this long (s) with data on both sides are
#: bridged by linear interpolation (flagged ``interpolated``, never used as observations); longer gaps split
#: the trial into observed segments and no step period spans them.
DEFAULT_MAX_GAP_S = 0.05
#: Table 1 leg length, m: the plausibility checks compare the recording with a wheel of this size.
TABLE1_LEG_LENGTH_M = 0.237
#: A hub jump larger than this (m) plus 5 m/s times the time between two valid frames is a seam.
JUMP_M = 0.1
#: Warn when the fitted centre of rotation lies this far (m) from the tracked point, or fits this badly (m).
HUB_OFFSET_WARN_M = 0.01
HUB_RESIDUAL_WARN_M = 0.002


def _full_grid(sec: Section) -> tuple[np.ndarray, np.ndarray]:
    """(all frames from first to last, row index of each in the section or -1)."""
    if sec.n_rows and sec.sub_frame.max() > 0:
        raise TrialRefused(f"section {sec.kind!r} (line {sec.line}) has sub frames: not a trajectory")
    missing = int(sec.frame[-1] - sec.frame[0] + 1 - sec.n_rows) if sec.n_rows else 0
    if missing > max(sec.n_rows, 10_000):
        r = int(np.argmax(np.diff(sec.frame))) + 1
        raise TrialRefused(f"{sec.data_line + r}:1: section {sec.kind!r}: the frame number jumps from "
                           f"{sec.frame[r - 1]} to {sec.frame[r]}: {missing} frames would be missing (a second take "
                           "or a wrong frame number?)")
    frames = np.arange(sec.frame[0], sec.frame[-1] + 1)
    row = np.full(frames.size, -1, np.int64)
    row[sec.frame - sec.frame[0]] = np.arange(sec.n_rows)
    return frames, row


def _on_grid(arr: np.ndarray, row: np.ndarray) -> np.ndarray:
    """``arr`` rows on the full frame grid (NaN at missing frames); ``arr`` itself when no frame is missing."""
    if row.size == arr.shape[0] and (row.size == 0 or (row[0] == 0 and row[-1] == row.size - 1)):
        return arr  # rows are 0..n-1 in order (frames strictly increase), nothing to place
    out = np.full((row.size,) + arr.shape[1:], np.nan)
    ok = row >= 0
    out[ok] = arr[row[ok]]
    return out


def _check_jumps(path: Path | str, sec: Section, time_s: np.ndarray, p: np.ndarray, row: np.ndarray) -> None:
    """Refuse at the seam line when the tracked point jumps (a second take pasted after the first)."""
    ok = np.flatnonzero(~np.isnan(p).any(axis=1))
    if ok.size < 2:
        return
    d = np.linalg.norm(np.diff(p[ok], axis=0), axis=1)
    dt = np.diff(time_s[ok])
    bad = np.flatnonzero(d > JUMP_M + 5.0 * dt)
    if bad.size:
        i = ok[bad[0] + 1]
        where = (f"{path}:{sec.data_line + int(row[i])}:1" if sec.data_line
                 else f"{path}: frame {int(sec.frame[row[i]])}")
        raise TrialRefused(f"{where}: the wheel jumps {d[bad[0]]:.2f} m in {dt[bad[0]] * 1e3:.0f} ms "
                           "here: a second take pasted after the first? split the file here")


def build_trial(
    vf: ViconFile,
    *,
    object: str | None = None,  # noqa: A002 - the Vicon word
    markers: Sequence[str] | None = None,
    slope_deg: float | None = None,
    hub_offset_m: Sequence[float] | None = None,
    orientation: str = "helical",
    leg_length_m: float | None = None,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
    alpha_rad: float = ALPHA_RAD,
    wheel_leg_length_m: float = TABLE1_LEG_LENGTH_M,
) -> Trial:
    """Build a `Trial` from a parsed Vicon file.

    Parameters
    ----------
    vf : from `read_vicon_csv` (or `rimless.analysis.io.c3d.read_c3d`).
    object : tracked object (Objects section) or subject prefix of the markers (CLI ``--object``);
        default: the candidate that moves like the wheel (`rimless.analysis.kinematics.source.choose_source`).
    markers : names of the wheel markers (3 or more on the wheel, or 1 at the hub) (CLI ``--markers``).
    slope_deg : known slope, deg; default: estimated from the hub path in the walking window.
    hub_offset_m : hub in the object (or marker reference) frame, m (CLI ``--hub-offset-mm``); default: the
        centre of rotation fitted on the walking window when the wheel turns more than 180 deg there.
    orientation : convention of RX, RY, RZ (``"helical"`` or a scipy Euler sequence such as ``"xyz"``).
    leg_length_m : leg length; when given, CoM height is measured from the slope plane
        (impact line - leg_length * cos(alpha / 2)); otherwise from the line through the impacts.
    max_gap_s : gaps up to this long are linearly interpolated (flagged ``interpolated``); longer stay NaN.
    alpha_rad : rotation per step, rad.
    wheel_leg_length_m : the wheel's leg length for the plausibility checks (Table 1), m.

    Raises
    ------
    TrialRefused
        When the file holds no usable wheel trajectory or is implausible (message says why and where).
    """
    from rimless.analysis.kinematics.hub import RotationStack, axis_in_body, hub_from_markers, hub_from_pose, wheel_angle_from_rotations
    from rimless.analysis.kinematics.source import POSE, XYZ, SourceRefused, choose_source, zeros_to_nan
    from rimless.analysis.kinematics.walk import classify_ending, find_motion

    if not (math.isfinite(max_gap_s) and max_gap_s >= 0):
        raise UserError(f"--max-gap-ms must be a finite number >= 0, got {max_gap_s * 1e3!r}")
    try:
        choice = choose_source(vf, object, markers)
    except SourceRefused as err:
        raise TrialRefused(str(err)) from None
    sec, obj, mk = choice.section, choice.object, list(choice.markers)
    warnings: list[str] = list(choice.warnings)
    if sec.n_rows < 10:
        raise TrialRefused(f"{vf.path}: section {sec.kind!r} (line {sec.line}) has {sec.n_rows} rows: too short")
    try:
        frames, row = _full_grid(sec)
    except TrialRefused as err:
        raise TrialRefused(f"{vf.path}:{err}" if str(err)[:1].isdigit() else f"{vf.path}: {err}") from None
    rate = sec.rate_hz
    time_s = (frames - frames[0]) / rate
    notes: list[str] = []
    rot = None
    if obj is not None:
        pose = _on_grid(sec.get(obj, POSE), row)  # a view of the section when no frame is missing
        zero = ~(pose != 0).any(axis=1)  # six exact zeros: an occlusion (as `zeros_to_nan`, without a copy)
        if (zero | np.isnan(pose).all(axis=1)).all():
            raise TrialRefused(f"{vf.path}: object {obj!r} has no values (never tracked)")
        # matrices made slice by slice from the angles when used (n x 3 x 3 floats are never held at once)
        rot = RotationStack(pose[:, :3], orientation, invalid=zero)
        trans = pose[:, 3:].copy()
        trans[zero] = np.nan
        del pose, zero
        what = "object origin"
        units = {c.component: c.file_unit for c in sec.columns if c.group == obj}
    else:
        pts = np.stack([zeros_to_nan(_on_grid(sec.get(m, XYZ), row), 3) for m in mk], axis=1)
        counts = (~np.isnan(pts).any(axis=2)).sum(axis=0)
        if (counts == 0).any():
            dead = [m for m, c in zip(mk, counts) if c == 0]
            raise TrialRefused(f"{vf.path}: marker(s) {dead} have no values in any frame")
        if len(mk) == 2:
            raise TrialRefused(f"{vf.path}: 2 wheel markers ({', '.join(mk)}) fix neither the hub nor the "
                               "rotation: give 3 or more (or the hub marker) with --markers")
        try:
            est0 = hub_from_markers(pts)
        except ValueError as err:
            raise TrialRefused(f"{vf.path}: {err}") from None
        trans = est0.hub_m
        rot = est0.rotation
        del est0, pts
        what = "marker centroid" if len(mk) > 1 else "hub marker"
        units = {f"{m}.{c.component}": c.file_unit for m in mk for c in sec.columns if c.group == m}
    _check_jumps(vf.path, sec, time_s, trans, row)
    del row
    angle = None
    axis = None
    if rot is not None:
        angle, axis = wheel_angle_from_rotations(rot)
        if not np.isfinite(angle).any():
            angle = None
    motion = find_motion(time_s, angle, trans, leg_length_m=wheel_leg_length_m)
    rough = np.zeros(time_s.size, bool)
    rough[motion.release_index:motion.end_index + 1] = True
    if rot is not None and angle is not None:
        est = hub_from_pose(rot, trans, hub_offset_m=hub_offset_m, mask=rough, what=what, angle_axis=(angle, axis))
        hub_raw, offset, residual = est.hub_m, est.offset_m, est.offset_residual_m
        hub_source = est.source
        del est
    else:
        hub_raw, offset, residual = trans, None, None
        hub_source = "single marker taken as the hub" if obj is None else "object origin"
        if hub_offset_m is not None and obj is None:
            warnings.append("--hub-offset-mm ignored: one marker has no orientation to carry an offset")
    if offset is not None and hub_offset_m is None and residual is not None:
        if np.linalg.norm(offset) > HUB_OFFSET_WARN_M:
            warnings.append(f"the centre of rotation lies {np.linalg.norm(offset) * 1e3:.0f} mm from the {what} "
                            "(markers not centred on the hub, or the object origin is off the hub): corrected")
        if residual > HUB_RESIDUAL_WARN_M:
            warnings.append(f"the centre-of-rotation fit leaves {residual * 1e3:.1f} mm RMS: the markers may not be "
                            "rigid on the wheel, or the wheel does not roll in one plane")

    # The wheel axis in the body frame, R^T axis (n, 3), for the tilt test at the end. A `RotationStack` costs no
    # memory and makes it then; a matrix array (markers) is replaced by it now. float32: the tilt is compared
    # with 20 deg; the rounding (1e-7 rad) does not matter there.
    u = None
    if rot is not None and axis is not None and not isinstance(rot, RotationStack):
        u = axis_in_body(rot, axis, np.float32)
        rot = None
    max_gap_frames = int(math.floor(min(max_gap_s, 1e6) * rate + 1e-9))
    hub, filled = fill_short_gaps(hub_raw, max_gap_frames)
    del hub_raw, trans
    if angle is not None:
        angle, _ = fill_short_gaps(angle, max_gap_frames)
    gap = np.isnan(hub).any(axis=1)
    if gap.all() or (~gap).sum() < 10:
        raise TrialRefused(f"{vf.path}: fewer than 10 frames with a known hub")

    fit_mask = rough & ~gap
    if fit_mask.sum() < 10:
        fit_mask = ~gap
    hub_fit = np.where(fit_mask[:, None], hub, np.nan)
    frame0 = fit_slope(hub_fit, slope_deg=slope_deg)
    travel = frame0.travel
    y = np.where(fit_mask, frame0.to_slope(hub)[:, 1], np.nan)
    period_guess = None
    if angle is not None and np.isfinite(angle[fit_mask]).sum() > 2:
        aw = angle[fit_mask]
        total = float(np.nanmax(aw) - np.nanmin(aw))
        tw = time_s[fit_mask]
        if total > 0:
            period_guess = alpha_rad / (total / max(tw[-1] - tw[0], 1e-9))
        del aw, tw
    idx, _, _ = find_com_minima(time_s, y, min_period_s=period_guess)
    reference = "the robust line through the hub path"
    frame = frame0
    if idx.size >= 3:
        frame = fit_slope(hub_fit, slope_deg=slope_deg, points_m=_hub_at_cusps(time_s, hub_fit, idx), travel=travel)
        reference = f"the line through the hub at {idx.size} CoM-height minima (impacts)"
    elif slope_deg is None:
        notes.append(f"slope fitted on the whole hub path ({idx.size} CoM minima found, 3 needed for the "
                     "impact line)")
    del hub_fit, y, idx
    hub_slope = frame.to_slope(hub)
    com = hub_slope[:, 1].copy()
    if leg_length_m is not None:
        com = com + leg_length_m * math.cos(alpha_rad / 2)
        reference = f"slope plane = {reference} minus leg_length_m*cos(alpha/2) ({leg_length_m} m)"
    else:
        reference = f"height above {reference}"
    observed = ~gap & ~filled
    t_rel, t_end = float(time_s[motion.release_index]), float(time_s[motion.end_index])
    steps = detect_steps(time_s, com, angle, alpha_rad=alpha_rad, observed=observed, window_s=(t_rel, t_end),
                         min_advance_rad=0.1 * alpha_rad if motion.held else 0.0)

    # walking window and ending
    if steps.impact_time_s.size:
        i_last = int(np.searchsorted(time_s, steps.impact_time_s[-1]))
        i_last = min(i_last, time_s.size - 1)
    else:
        i_last = motion.end_index
    window_s = (t_rel, float(steps.impact_time_s[-1]) if steps.impact_time_s.size else t_end)
    tilt = None
    if rot is not None and axis is not None:
        u = axis_in_body(rot, axis, np.float32)
    del rot
    if u is not None:
        win = np.zeros(time_s.size, bool)
        win[motion.release_index:i_last + 1] = True
        win &= ~np.isnan(u).any(axis=1)
        if win.any():
            a_body = u[win].mean(axis=0, dtype=np.float64)
            a_body /= np.linalg.norm(a_body)
            cos_t = np.abs(u @ a_body.astype(np.float32)).astype(np.float64)  # = |axis . (R a_body)|
            tilt = np.arccos(np.clip(cos_t, 0.0, 1.0))
            del cos_t
        del u, win
    progress = angle if angle is not None else hub_slope[:, 0] / wheel_leg_length_m
    from rimless.analysis.kinematics.steps import noise_sigma

    sig = noise_sigma(com[rough]) if rough.any() else float("nan")
    ending = classify_ending(time_s, hub_slope, progress, (motion.release_index, i_last), axis_tilt_rad=tilt,
                             noise_m=sig if math.isfinite(sig) else 0.0)

    _plausibility(vf.path, sec, time_s, hub_slope, angle, steps, window_s, alpha_rad, wheel_leg_length_m, warnings)
    n_unseen = _unseen_periods(steps)
    if n_unseen:
        warnings.append(f"{n_unseen} step period(s) dropped: an impact fell in a gap longer than "
                        f"{max_gap_s * 1e3:g} ms (not guessed)")
    if motion.held:
        notes.append(f"held still for {t_rel:.2f} s before the release")

    ts = TimeSeries(time_s).add_data("frame", frames)
    ts = _add_standard(ts, hub, hub_slope, com, angle, gap, filled)
    ts = replace(ts, events=tuple(Event(t, "impact") for t in steps.impact_time_s.tolist()))  # sorted once
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
        hub_source=hub_source,
        hub_offset_m=None if offset is None else tuple(float(v) for v in offset),
        orientation=(orientation if obj is not None else "markers") if angle is not None else None,
        slope_deg=frame.slope_deg,
        slope_source=frame.source + (" (walking window)" if frame.source != "given" else ""),
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
        source_reason=choice.reason,
        ramp_slope_deg=choice.ramp_slope_deg,
        ramp_source=choice.ramp_source,
        outcome=ending.outcome,
        outcome_reason=ending.reason,
        window_s=window_s,
        hub_offset_residual_m=residual,
        impact_step=tuple(int(k) for k in (steps.impact_step if steps.impact_step is not None else ())),
        period_step=tuple(int(k) for k in (steps.period_step if steps.period_step is not None else ())),
        warnings=tuple(warnings),
    )
    return Trial(ts, meta)


def _unseen_periods(steps: StepResult) -> int:
    ks = steps.impact_step
    if ks is None or len(ks) < 2:
        return 0
    return int(ks[-1] - ks[0]) - int(len(steps.period_step if steps.period_step is not None else []))


def _plausibility(path: str, sec: Section, time_s: np.ndarray, hub_slope: np.ndarray, angle: np.ndarray | None,
                  steps: StepResult, window_s: tuple[float, float], alpha_rad: float, leg_m: float,
                  warnings: list[str]) -> None:
    """Compare the size and speed of the recorded motion with the wheel's (catches a mm/m mislabel)."""
    expected = 2 * leg_m * math.sin(alpha_rad / 2)  # hub travel per step, m
    m = (time_s >= window_s[0]) & (time_s <= window_s[1]) & ~np.isnan(hub_slope).any(axis=1)
    if m.sum() < 3:
        return
    x = hub_slope[m, 0]
    travel = float(np.max(x) - np.min(x))
    unit = sorted({c.file_unit for c in sec.columns if c.component in ("X", "Y", "Z", "TX", "TY", "TZ")})
    where = f"{path}:{sec.units_line}:1" if sec.units_line else path
    if angle is not None and np.isfinite(angle[m]).sum() > 2:
        turned = float(np.nanmax(angle[m]) - np.nanmin(angle[m]))
        if turned < alpha_rad:
            return
        per_step = travel / (turned / alpha_rad)
        ratio = per_step / expected
        if ratio < 0.1 or ratio > 10:
            raise TrialRefused(
                f"{where}: the units row says {'/'.join(unit) or '(none)'}, but the wheel moves {per_step:.4g} m per "
                f"{math.degrees(alpha_rad):.0f} deg of rotation where a wheel with {leg_m} m legs moves "
                f"{expected:.3f} m: the numbers are likely in "
                f"{'m (not mm)' if ratio < 0.1 else 'mm (not m)'}; fix the units row")
        if not 0.5 <= ratio <= 2.0:
            warnings.append(f"the wheel moves {per_step:.3f} m per step where {expected:.3f} m is expected "
                            f"(legs of {leg_m} m): check the units row (line {sec.units_line}) and the leg length")
    else:
        dur = max(float(np.ptp(time_s[m])), 1e-9)
        speed = travel / dur
        if travel > 0 and (speed < 0.01 or speed > 20):
            raise TrialRefused(
                f"{where}: the units row says {'/'.join(unit) or '(none)'}, but the hub moves at {speed:.4g} m/s "
                "while walking (a wheel walks at about 0.1-2 m/s): check the units row")


def _hub_at_cusps(time_s: np.ndarray, hub: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Hub at each CoM-height cusp: height from the V fit of Z, horizontal position interpolated."""
    half = max(3, int(0.25 * np.median(np.diff(idx)))) if idx.size > 1 else 5
    ok = ~np.isnan(hub).any(axis=1)
    tv, hv = time_s[ok], hub[ok]
    out = np.empty((idx.size, 3))
    out[:, 0], out[:, 2] = refine_cusps(time_s, hub[:, 2], idx, half)
    tc = out[:, 0].copy()
    out[:, 0] = np.interp(tc, tv, hv[:, 0])
    out[:, 1] = np.interp(tc, tv, hv[:, 1])
    return out


def read_recording(path: str | Path) -> ViconFile:
    """A Vicon export: ``.c3d`` by `rimless.analysis.io.c3d.read_c3d`, anything else as Vicon CSV."""
    if str(path).lower().endswith(".c3d"):
        from rimless.analysis.io.c3d import read_c3d

        return read_c3d(path)
    return read_vicon_csv(path)


def import_trial(path: str | Path, **kwargs: Any) -> Trial:
    """`read_recording` (Vicon CSV or C3D) then `build_trial` (keyword arguments as there)."""
    return build_trial(read_recording(path), **kwargs)


def _nan_to_none(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


# Keep names used only in annotations importable for users of this module.
_ = (HubEstimate, SlopeFrame)
