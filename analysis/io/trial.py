"""A wheel trial: one tidy time series plus metadata, stored as one Parquet file (`Trial.to_parquet`,
`read_trial`). `rimless.analysis.kinematics.build` builds it from a Vicon export.

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
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.io.timeseries import Event, TimeSeries
from rimless.errors import InputFileError

__all__ = ["Trial", "TrialMeta", "read_trial", "standard_series", "slope_ci_deg", "ALPHA_RAD"]

PARQUET_META_KEY = b"rimless.trial"
FORMAT_VERSION = 1
#: Inter-leg angle of the eight-legged wheel, rad: the rotation per step (the default of step detection).
ALPHA_RAD = math.pi / 4


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
    #: 95 % interval of ``slope_deg``, rad; ``slope_source`` says where the slope comes from: ``ramp`` (a static
    #: ramp object or markers), ``given`` (by the user) or ``estimated`` (from the motion); ``slope_method`` how.
    slope_ci_rad: tuple[float, float] = (float("nan"), float("nan"))
    slope_method: str = ""
    #: The slope estimated from the motion and its 95 % interval, rad (also when another source is used), or None.
    slope_estimated_deg: float | None = None
    slope_estimated_ci_rad: tuple[float, float] | None = None
    #: The lab's up axis of the file (``z``, ``y``, ``-x``...: world outputs stay in the file's frame) and how it
    #: was found (from the data, or given with ``--up-axis``).
    up_axis: str = "z"
    up_axis_reason: str = ""
    #: Standard error of the fitted hub offset along its worst axis in the wheel plane, m (None when given or not
    #: fitted): an offset error e is a once-a-turn sinusoid of amplitude |e| in the CoM height.
    hub_offset_sd_m: float | None = None
    #: Standard errors of the fitted hub offset along the two axes of its covariance in the wheel plane, m (largest
    #: first: the first is ``hub_offset_sd_m``; the stance feet's sd on both when they placed the hub), or None.
    hub_offset_sd_axes_m: tuple[float, float] | None = None
    #: What the import held, with value, sd and source each (`rimless.analysis.kinematics.build.import_parameters`:
    #: the legs' drift time from the wheel given, or the bound; the leg length when given); None for a trial
    #: imported before they were recorded.
    parameters: tuple[dict[str, Any], ...] | None = None
    #: Each impact's time sd, s, in the order of the impacts (NaN: not estimable; the importer's
    #: `rimless.analysis.kinematics.steps.impact_time_sd` or its kink fit): the impact's own error, apart from a
    #: shift common to all the trial's impacts; () for a trial imported before it was recorded.
    impact_sd_s: tuple[float, ...] = field(default=())

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
        for k in (
            "hub_offset_m",
            "travel_direction",
            "slope_origin_m",
            "window_s",
            "slope_estimated_ci_rad",
            "hub_offset_sd_axes_m",
        ):
            if d.get(k) is not None:
                d[k] = tuple(d[k])
        d["slope_ci_rad"] = tuple(
            float("nan") if v is None else float(v) for v in (d.get("slope_ci_rad") or (None, None))
        )
        if d.get("slope_residual_m") is None:
            d["slope_residual_m"] = float("nan")
        if d.get("parameters") is not None:
            d["parameters"] = tuple(d["parameters"])
        d["impact_sd_s"] = tuple(float("nan") if v is None else float(v) for v in (d.get("impact_sd_s") or ()))
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
    def impact_sd_s(self) -> np.ndarray:
        """Each impact's time sd, s (NaN: not estimable, or not recorded at import): ``meta.impact_sd_s``."""
        sd = self.meta.impact_sd_s
        n = self.impact_time_s.size
        return np.asarray(sd, np.float64) if len(sd) == n else np.full(n, np.nan)

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
        return np.array(
            [t[pos[int(k)]] - t[pos[int(k) - 1]] for k in self.period_step if int(k) in pos and int(k) - 1 in pos],
            dtype=np.float64,
        )

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
            "slope_ci_deg": slope_ci_deg(m.slope_ci_rad),
            "slope_method": m.slope_method,
            "slope_estimated_deg": m.slope_estimated_deg,
            "slope_estimated_ci_deg": slope_ci_deg(m.slope_estimated_ci_rad),
            "slope_residual_m": m.slope_residual_m,
            "com_height_reference": m.com_height_reference,
            "gap_frames": m.n_gap_frames,
            "interpolated_frames": m.n_interpolated_frames,
            "max_gap_s": m.max_gap_s,
            "step_method": m.step_method,
            "step_refused": m.step_refused,
            "steps": int(self.step_period_s.size),
            "impact_time_s": self.impact_time_s.tolist(),
            "impact_sd_ms": [None if not math.isfinite(v) else v * 1e3 for v in self.impact_sd_s.tolist()],
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
            "hub_offset_sd_mm": None if m.hub_offset_sd_m is None else m.hub_offset_sd_m * 1e3,
            "hub_offset_sd_axes_mm": None
            if m.hub_offset_sd_axes_m is None
            else [v * 1e3 for v in m.hub_offset_sd_axes_m],
            "warnings": list(m.warnings),
            "up_axis": m.up_axis,
            "up_axis_reason": m.up_axis_reason,
            "parameters": None if m.parameters is None else [dict(p) for p in m.parameters],
        }

    def to_dict(self) -> dict[str, Any]:
        """`summary()`: the JSON object of the trial, with ``parameters`` (what the import held, as the rows of
        ``trials import --json``)."""
        return self.summary()

    def __repr__(self) -> str:
        m = self.meta
        return (
            f"Trial({Path(m.source_file).name}: {m.n_frames} frames at {m.rate_hz:g} Hz, slope {m.slope_deg:.3f} deg "
            f"({m.slope_source}), {int(self.step_period_s.size)} step period(s), outcome {m.outcome}; "
            ".to_frame(), .summary())"
        )

    def columns(self) -> dict[str, np.ndarray]:
        """The samples as named SI columns: frame, time_s, hub_{x,y,z}_m (lab frame), slope_{x,y,z}_m (hub in the
        slope frame: x down the slope, y the slope normal), com_height_m, wheel_angle_rad (when known), gap,
        interpolated (the columns of the Parquet file)."""
        s = self.series
        cols: dict[str, np.ndarray] = {"frame": s["frame"].astype(np.int64), "time_s": s.time_s}
        for i, ax in enumerate("xyz"):
            cols[f"hub_{ax}_m"] = s["hub"][:, i]
        for i, ax in enumerate("xyz"):
            cols[f"slope_{ax}_m"] = s["hub_slope"][:, i]
        cols["com_height_m"] = s["com_height"]
        if "wheel_angle" in s.data:
            cols["wheel_angle_rad"] = s["wheel_angle"]
        cols["gap"] = s["gap"].astype(bool)
        cols["interpolated"] = s["interpolated"].astype(bool)
        return cols

    def to_frame(self) -> Any:
        """The samples as a pandas DataFrame (`columns()`; NaN in a gap); `attrs["meta"]` holds `summary()`."""
        import pandas as pd

        frame = pd.DataFrame(self.columns())
        frame.attrs["meta"] = self.summary()
        return frame

    # -- storage
    def to_parquet(self, path: str | Path) -> Path:
        """Write the trial as one Parquet file (`columns()`, metadata as JSON); atomic (temp + rename)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table(self.columns())
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
    ts = standard_series(
        ts,
        np.column_stack([c["hub_x_m"], c["hub_y_m"], c["hub_z_m"]]),
        np.column_stack([c["slope_x_m"], c["slope_y_m"], c["slope_z_m"]]),
        c["com_height_m"],
        c.get("wheel_angle_rad"),
        c["gap"].astype(bool),
        c["interpolated"].astype(bool),
    )
    ts = replace(ts, events=tuple(Event(float(t), "impact") for t in extra["impact_time_s"]))
    return Trial(ts, meta)


def standard_series(
    ts: TimeSeries,
    hub: np.ndarray,
    hub_slope: np.ndarray,
    com: np.ndarray,
    angle: np.ndarray | None,
    gap: np.ndarray,
    interp: np.ndarray,
) -> TimeSeries:
    """``ts`` with the trial's data keys of the module doc, with their units and frames."""
    ts = ts.add_data("hub", hub, unit="m", frame="world")
    ts = ts.add_data("hub_slope", hub_slope, unit="m", frame="slope (x down the slope, y normal, z lateral)")
    ts = ts.add_data("com_height", com, unit="m")
    if angle is not None:
        ts = ts.add_data("wheel_angle", angle, unit="rad")
    ts = ts.add_data("gap", gap)
    return ts.add_data("interpolated", interp)


def slope_ci_deg(ci_rad: tuple[float, float] | None) -> list[float] | None:
    """A slope interval in rad as ``[low, high]`` deg for JSON, or None when unknown."""
    if ci_rad is None or not all(math.isfinite(v) for v in ci_rad):
        return None
    return [math.degrees(ci_rad[0]), math.degrees(ci_rad[1])]


def _nan_to_none(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
