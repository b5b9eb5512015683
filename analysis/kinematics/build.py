"""Building a `Trial` from a parsed Vicon export: the kinematics of this folder put together.

`build_trial` chooses the wheel's source (`source`), places it on the full frame grid, bridges short gaps
(`fill_short_gaps`), finds the hub and the wheel angle (`hub`), the walking window (`walk`), the slope frame and
CoM height (`slope`), the impacts (`steps`) and the ending, checks that the motion is a wheel's, and returns the
trial of `rimless.analysis.io.trial` (which stores and reads it). `import_trial` reads the file first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.io.manifest import slope_for
from rimless.analysis.io.recording import read_recording
from rimless.analysis.io.timeseries import Event, TimeSeries
from rimless.analysis.io.trial import ALPHA_RAD, Trial, TrialMeta, standard_series
from rimless.analysis.io.vicon_file import Section, ViconFile
from rimless.analysis.kinematics.contacts import HUB_MAX_SE_M, fit_contacts, hub_from_contacts, slope_from_contacts
from rimless.analysis.kinematics.hub import (
    MIN_ROTATION_FOR_OFFSET_RAD,
    RotationStack,
    axis_in_body,
    describe_offset_fit,
    fit_hub_offset,
    hub_from_markers,
    hub_from_pose,
    wheel_angle_from_rotations,
)
from rimless.analysis.kinematics.slope import MAX_PATH_POINTS, fit_slope, travel_direction
from rimless.analysis.kinematics.slope_evidence import (  # noqa: F401  (the constants were defined here)
    GIVEN_SLOPE_HALF_WIDTH_DEG,
    MIN_ESTIMATE_HALF_WIDTH_DEG,
    OFFSET_BOUND_M,
    RAMP_SLOPE_HALF_WIDTH_DEG,
    Z95,
    SlopeEvidence,
    choose_slope,
    leg_compliance,
    slope_evidence,
)
from rimless.analysis.kinematics.source import POSE, XYZ, SourceRefused, choose_source, zeros_to_nan
from rimless.analysis.kinematics.steps import StepResult, detect_steps, find_com_minima, noise_sigma, refine_cusps
from rimless.analysis.kinematics.vertical import (
    UpAxis,
    VerticalUndecided,
    find_up,
    is_z_up,
    rotate_file,
    rotation_to_z_up,
    up_vector,
)
from rimless.analysis.kinematics.walk import classify_ending, find_motion
from rimless.errors import UserError

__all__ = [
    "TrialRefused",
    "build_trial",
    "import_trial",
    "import_parameters",
    "fill_short_gaps",
    "DEFAULT_MAX_GAP_S",
    "TABLE1_LEG_LENGTH_M",
]


class TrialRefused(UserError):
    """A file parsed but holds no usable wheel trajectory; the message says why."""


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
#: The centre of rotation fitted from the height is preferred to the stance feet's centre (when its standard error
#: is smaller) only over at least this much rotation after the first stance, rad (three quarters of a turn: on a
#: short stall of half a turn, 4 steps, the impact line through its hub read 0.91 deg on a 1.3 deg slope, against
#: 1.25 deg through the feet's hub, and the slope's interval missed).
HEIGHT_FIT_TRUSTED_RAD = 1.5 * math.pi
#: Stance-foot pivots that scatter more than this (RMS, m) about the wheel's star of feet are not all stance feet
#: (windows cut by occlusions fit spurious pivots): neither their hub nor their slope line is used.
FEET_MAX_RESIDUAL_M = 0.005


def _full_grid(sec: Section) -> tuple[np.ndarray, np.ndarray]:
    """(all frames from first to last, row index of each in the section or -1)."""
    if sec.n_rows and sec.sub_frame.max() > 0:
        raise TrialRefused(f"section {sec.kind!r} (line {sec.line}) has sub frames: not a trajectory")
    missing = int(sec.frame[-1] - sec.frame[0] + 1 - sec.n_rows) if sec.n_rows else 0
    if missing > max(sec.n_rows, 10_000):
        r = int(np.argmax(np.diff(sec.frame))) + 1
        raise TrialRefused(
            f"{sec.data_line + r}:1: section {sec.kind!r}: the frame number jumps from "
            f"{sec.frame[r - 1]} to {sec.frame[r]}: {missing} frames would be missing (a second take "
            "or a wrong frame number?)"
        )
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
        where = (
            f"{path}:{sec.data_line + int(row[i])}:1" if sec.data_line else f"{path}: frame {int(sec.frame[row[i]])}"
        )
        raise TrialRefused(
            f"{where}: the wheel jumps {d[bad[0]]:.2f} m in {dt[bad[0]] * 1e3:.0f} ms "
            "here: a second take pasted after the first? split the file here"
        )


def _turned(angle: np.ndarray, mask: np.ndarray) -> float:
    """The wheel's total rotation over the frames of ``mask``, rad (0 when none is known)."""
    sel = angle[mask]
    return float(np.nanmax(sel) - np.nanmin(sel)) if np.isfinite(sel).any() else 0.0


def _after_first_step(angle: np.ndarray, mask: np.ndarray, alpha_rad: float) -> np.ndarray:
    """The frames of ``mask`` after the wheel has turned one step (alpha) from its first angle there."""
    sel = angle[mask]
    if not np.isfinite(sel).any():
        return mask
    return mask & (np.nan_to_num(angle, nan=-np.inf) >= float(np.nanmin(sel)) + alpha_rad)


def _xyz(v: np.ndarray) -> tuple[float, float, float]:
    """A (3,) vector as a tuple of floats."""
    x, y, z = (float(c) for c in v)
    return x, y, z


def build_trial(
    vf: ViconFile,
    *,
    object: str | None = None,
    markers: Sequence[str] | None = None,
    slope_deg: float | None = None,
    hub_offset_m: Sequence[float] | None = None,
    orientation: str = "helical",
    leg_length_m: float | None = None,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
    alpha_rad: float = ALPHA_RAD,
    wheel_leg_length_m: float = TABLE1_LEG_LENGTH_M,
    slope_note: str | None = None,
    up_axis: str | None = None,
    wheel: Any = None,
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
    slope_note : where a given slope comes from (e.g. the manifest row), kept in the notes.
    up_axis : the lab's up axis (``x``, ``y``, ``z``, ``-x``, ``-y``, ``-z``; CLI ``--up-axis``); default: found
        from the data (`rimless.analysis.kinematics.vertical.find_up`). World outputs stay in the file's frame.
    wheel : the wheel (a `rimless.sim.Wheel` or wheel input), for its legs' spring only: how far their compression
        may drift as the speed changes (`slope_evidence.leg_compliance`); default: not told, a bound assumed.
        What was held is listed in ``meta.parameters`` (`import_parameters`, ``parameters`` of `Trial.to_dict`).

    Raises
    ------
    TrialRefused
        When the file holds no usable wheel trajectory or is implausible (message says why and where).
    """
    if not (math.isfinite(max_gap_s) and max_gap_s >= 0):
        raise UserError(f"--max-gap-ms must be a finite number >= 0, got {max_gap_s * 1e3!r}")
    try:
        choice = choose_source(vf, object, markers)
    except SourceRefused as err:
        raise TrialRefused(str(err)) from None
    if up_axis is not None:
        up = UpAxis(up_axis.strip().lower().lstrip("+"), f"{up_axis.strip().upper()} up (given with --up-axis)")
        up_vector(up.name)  # a bad name is refused here
    else:
        try:
            up = find_up(vf, choice, orientation)
        except VerticalUndecided as err:
            raise TrialRefused(str(err)) from None
    q_lab: np.ndarray | None = None  # rotates the file's frame to Z up (None: it is Z up)
    if not is_z_up(up.name):
        q_lab = rotation_to_z_up(up_vector(up.name))
        vf = rotate_file(vf, q_lab, orientation)
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
    notes: list[str] = [] if slope_note is None else [slope_note]
    rot: np.ndarray | RotationStack | None = None
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
            raise TrialRefused(
                f"{vf.path}: 2 wheel markers ({', '.join(mk)}) fix neither the hub nor the "
                "rotation: give 3 or more (or the hub marker) with --markers"
            )
        try:
            est0 = hub_from_markers(pts)
        except ValueError as err:
            raise TrialRefused(f"{vf.path}: {err}") from None
        trans = est0.hub_m
        rot = est0.rotation
        if est0.n_relabelled:
            warnings.append(
                f"{est0.n_relabelled} frame(s) with swapped marker labels repaired (the exchange that "
                "fits the rigid marker shape)"
            )
        if est0.n_inconsistent:
            warnings.append(
                f"{est0.n_inconsistent} frame(s) whose markers fit no rigid shape of the wheel "
                "(swapped or ghost markers) treated as gaps"
            )
        del est0, pts
        what = "marker centroid" if len(mk) > 1 else "hub marker"
        units = {f"{m}.{c.component}": c.file_unit for m in mk for c in sec.columns if c.group == m}
    _check_jumps(vf.path, sec, time_s, trans, row)
    del row
    angle: np.ndarray | None = None
    axis: np.ndarray | None = None
    if rot is not None:
        angle, axis = wheel_angle_from_rotations(rot)
        if not np.isfinite(angle).any():
            angle = None
    motion = find_motion(time_s, angle, trans, leg_length_m=wheel_leg_length_m)
    rough = np.zeros(time_s.size, bool)
    rough[motion.release_index : motion.end_index + 1] = True
    contacts = None
    hub_sd_m: float | None = None  # standard error of the fitted hub offset (feet or height), m
    offset_cov: np.ndarray | None = None  # the height fit's covariance (3, 3), m^2, when its offset is used
    sd_axes: tuple[float, float] | None = None  # the offset's sds along its covariance's two axes, m
    if rot is not None and angle is not None and axis is not None:  # the axis comes with the angle
        ok_t = np.flatnonzero(rough & ~np.isnan(trans).any(axis=1))
        # an even subsample of at most MAX_PATH_POINTS frames (no copy of the whole path)
        sub_t = ok_t[:: max(1, -(-ok_t.size // MAX_PATH_POINTS))]
        travel_guess = travel_direction(np.concatenate([trans[sub_t], trans[ok_t[-1:]]])) if ok_t.size >= 2 else None
        del ok_t, sub_t
        contacts = fit_contacts(rot, trans, angle, axis, rough, alpha_rad=alpha_rad, travel=travel_guess)
        # (fit_contacts finds no contact without two frames of the path, i.e. without travel_guess)
        if contacts is not None and travel_guess is not None:
            sc0 = slope_from_contacts(contacts.contacts, travel_guess)
            if sc0 is not None and abs(sc0[0]) >= alpha_rad / 2:
                notes.append(
                    f"the {len(contacts.contacts)} pivots found lie on a line at {math.degrees(sc0[0]):.1f} "
                    "deg, where no wheel stands: not stance feet, not used"
                )
                contacts = None
        hub_c = hub_from_contacts(contacts, alpha_rad) if contacts is not None and hub_offset_m is None else None
        if hub_c is not None and contacts is not None and hub_c[2] > FEET_MAX_RESIDUAL_M:
            notes.append(
                f"the {len(contacts.contacts)} pivots found do not sit on the wheel's star of feet (RMS "
                f"{hub_c[2] * 1e3:.1f} mm, more than {FEET_MAX_RESIDUAL_M * 1e3:.0f} mm): not all are stance feet "
                "(occlusions cut the stances?); neither their hub nor their slope line is used"
            )
            hub_c = contacts = None
        feet = hub_c if hub_c is not None and hub_c[1] <= HUB_MAX_SE_M else None  # the hub the feet determine
        if feet is None and hub_c is not None:
            notes.append(f"the stance feet do not determine the hub (standard error {hub_c[1] * 1e3:.1f} mm)")
        # The centre of rotation from the height (all the frames of the walk, a turn or more) and the centre of
        # the stance feet (half-step windows, a short lever): the one with the smaller standard error is used.
        # The first stance is left out when a half turn remains: a hand release is no step of the gait (the legs
        # settle, a compliant one oscillates), and its height, read as once a turn, biased the offset 0.2-0.3 mm.
        height_fit = None
        settled = _after_first_step(angle, rough, alpha_rad)
        if _turned(angle, settled) < MIN_ROTATION_FOR_OFFSET_RAD:
            settled = rough
        if hub_offset_m is None and _turned(angle, settled) >= MIN_ROTATION_FOR_OFFSET_RAD:
            height_fit = fit_hub_offset(rot, trans, alpha_rad=alpha_rad, mask=settled, angle_axis=(angle, axis))
        # on a short stall the height's line, bumps and once-a-turn term are not told apart well enough for its
        # standard error to be trusted: the feet's centre is used when they place the hub
        short = height_fit is None or height_fit.rotation_rad < HEIGHT_FIT_TRUSTED_RAD
        use_feet = feet is not None and (short or height_fit is None or feet[1] < height_fit.sd_m)
        given: np.ndarray | Sequence[float] | None = hub_offset_m
        if use_feet and feet is not None:
            given = feet[0]
        elif height_fit is not None:
            given = height_fit.offset_m
        est = hub_from_pose(rot, trans, hub_offset_m=given, mask=rough, what=what, angle_axis=(angle, axis))
        hub_raw, offset, residual, hub_sd_m = est.hub_m, est.offset_m, est.offset_residual_m, est.offset_sd_m
        hub_source = est.source
        if use_feet and feet is not None and contacts is not None:  # (contacts: where the feet came from)
            d = np.asarray(feet[0])
            residual, hub_sd_m = feet[2], float(feet[1])
            sd_axes = (hub_sd_m, hub_sd_m)
            hub_source = (
                f"{what} + estimated offset [{d[0] * 1e3:.1f}, {d[1] * 1e3:.1f}, {d[2] * 1e3:.1f}] mm "
                f"(centre of the feet of {len(contacts.contacts)} stances, standard error "
                f"{feet[1] * 1e3:.2f} mm, feet residual {feet[2] * 1e3:.2f} mm)"
            )
        elif height_fit is not None:
            residual, hub_sd_m, offset_cov = height_fit.residual_m, height_fit.sd_m, height_fit.cov_m2
            sd_axes = height_fit.sd_axes_m
            hub_source = f"{what} + estimated offset {describe_offset_fit(height_fit)}"
            if feet is not None:
                hub_source += f"; the stance feet's centre, standard error {feet[1] * 1e3:.2f} mm, not used"
        del est
    else:
        hub_raw, offset, residual = trans, None, None
        hub_source = "single marker taken as the hub" if obj is None else "object origin"
        if hub_offset_m is not None and obj is None:
            warnings.append("--hub-offset-mm ignored: one marker has no orientation to carry an offset")
    if offset is not None and hub_offset_m is None and residual is not None:
        if np.linalg.norm(offset) > HUB_OFFSET_WARN_M:
            warnings.append(
                f"the centre of rotation lies {np.linalg.norm(offset) * 1e3:.0f} mm from the {what} "
                "(markers not centred on the hub, or the object origin is off the hub): corrected"
            )
        if residual > HUB_RESIDUAL_WARN_M:
            warnings.append(
                f"the centre-of-rotation fit leaves {residual * 1e3:.1f} mm RMS: the markers may not be "
                "rigid on the wheel, or the wheel does not roll in one plane"
            )

    # The wheel axis in the body frame, R^T axis (n, 3), for the tilt test at the end. A `RotationStack` costs no
    # memory and makes it then; a matrix array (markers) is replaced by it now. float32: the tilt is compared
    # with 20 deg; the rounding (1e-7 rad) does not matter there.
    u = None
    # the world's up in the body frame, R^T z (n, 3), when the offset's covariance is carried to the impact line's
    # heights (z^T R e: the height of an offset error e)
    up_body = None if offset_cov is None or rot is None else axis_in_body(rot, np.array([0.0, 0.0, 1.0]), np.float32)
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
    contact_slope = None
    if contacts is not None:
        sc = slope_from_contacts(contacts.contacts, travel)
        if sc is not None:
            contact_slope = sc
            frame0 = fit_slope(
                hub_fit, slope_deg=math.degrees(sc[0]) if slope_deg is None else slope_deg, travel=travel
            )
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
    hub_line = None  # the slope of the line through the hub at the impacts (an estimate and a check)
    cusps = cusp_t = None
    if idx.size >= 3:
        cusp_t, cusps = _cusps(time_s, hub_fit, idx)
        hub_line = fit_slope(hub_fit, points_m=cusps, travel=travel)
    hub_unknown = angle is not None and hub_offset_m is None and residual is None and offset is not None
    fm = np.flatnonzero(fit_mask)
    hs = frame0.to_slope(hub[fm[:: max(1, -(-fm.size // MAX_PATH_POINTS))]])[:, 0]
    del fm
    travel_m = float(np.nanmax(hs) - np.nanmin(hs)) if hs.size else 0.0
    evidence = slope_evidence(
        choice.ramp_slope_deg,
        choice.ramp_source,
        slope_deg,
        contact_slope,
        contacts,
        hub_line,
        frame0,
        idx.size,
        hub_unknown=hub_unknown,
        travel_m=travel_m,
        step_m=2 * wheel_leg_length_m * math.sin(alpha_rad / 2),
        impact_along_m=None if cusps is None else (cusps - cusps[0]) @ travel,
        hub_sd_m=hub_sd_m,
        alpha_rad=alpha_rad,
        impact_time_s=cusp_t,
        legs=leg_compliance(wheel),
        hub_height_cov_m2=_height_cov_at(up_body, idx, offset_cov) if cusps is not None else None,
    )
    del up_body
    if hub_unknown and evidence and evidence[0].source == "estimated":
        warnings.append(
            "the slope is not determined by this trial (the hub offset is unknown: fewer than two "
            "stance feet seen and too little rotation): its interval is wide; give --slope-deg or "
            "--slopes"
        )
    evidence, slope_warnings, slope_notes = choose_slope(evidence)
    _check_slope_possible(vf.path, evidence, time_s, angle if contact_slope is not None else None, rough, alpha_rad)
    warnings.extend(slope_warnings)
    notes.extend(slope_notes)
    chosen = evidence[0]
    reference = "the robust line through the hub path"
    if idx.size >= 3:
        frame = fit_slope(
            hub_fit,
            slope_deg=math.degrees(chosen.slope_rad),
            points_m=_hub_at_cusps(time_s, hub_fit, idx),
            travel=travel,
        )
        reference = f"the line through the hub at {idx.size} CoM-height minima (impacts)"
    else:
        frame = fit_slope(hub_fit, slope_deg=math.degrees(chosen.slope_rad), travel=travel)
        if chosen.source == "estimated" and contact_slope is None:
            notes.append(
                f"slope fitted on the whole hub path ({idx.size} CoM minima found, 3 needed for the impact line)"
            )
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
    steps = detect_steps(
        time_s,
        com,
        angle,
        alpha_rad=alpha_rad,
        observed=observed,
        window_s=(t_rel, t_end),
        min_advance_rad=0.1 * alpha_rad if motion.held else 0.0,
        # the hub's velocity turns by alpha at an impact (the wheel's angular velocity may barely change)
        kink_channels=[hub_slope[:, 0], hub_slope[:, 1]],
        leg_length_m=wheel_leg_length_m,
    )

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
        win[motion.release_index : i_last + 1] = True
        win &= ~np.isnan(u).any(axis=1)
        if win.any():
            a_body = u[win].mean(axis=0, dtype=np.float64)
            a_body /= np.linalg.norm(a_body)
            cos_t = np.abs(u @ a_body.astype(np.float32)).astype(np.float64)  # = |axis . (R a_body)|
            tilt = np.arccos(np.clip(cos_t, 0.0, 1.0))
            del cos_t
        del u, win
    progress = angle if angle is not None else hub_slope[:, 0] / wheel_leg_length_m
    sig = noise_sigma(com[rough]) if rough.any() else float("nan")
    ending = classify_ending(
        time_s,
        hub_slope,
        progress,
        (motion.release_index, i_last),
        axis_tilt_rad=tilt,
        noise_m=sig if math.isfinite(sig) else 0.0,
    )

    _plausibility(vf.path, sec, time_s, hub_slope, angle, steps, window_s, alpha_rad, wheel_leg_length_m, warnings)
    n_unseen = _unseen_periods(steps)
    if n_unseen:
        warnings.append(
            f"{n_unseen} step period(s) dropped: an impact fell in a gap longer than "
            f"{max_gap_s * 1e3:g} ms (not guessed)"
        )
    if motion.held:
        notes.append(f"held still for {t_rel:.2f} s before the release")

    ts = TimeSeries(time_s).add_data("frame", frames)
    if q_lab is not None:  # world outputs back in the file's frame (p = Q^T p')
        hub = hub @ q_lab
        travel = travel @ q_lab
        frame = replace(frame, origin_m=frame.origin_m @ q_lab)
        notes.append(f"the lab's vertical: {up.reason}; heights measured along it, world outputs in the file's frame")
    ts = standard_series(ts, hub, hub_slope, com, angle, gap, filled)
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
        hub_offset_m=None if offset is None else _xyz(offset),
        orientation=(orientation if obj is not None else "markers") if angle is not None else None,
        slope_deg=frame.slope_deg,
        slope_source=chosen.source,
        slope_ci_rad=chosen.ci_rad,
        slope_method=chosen.method,
        slope_estimated_deg=next((math.degrees(e.slope_rad) for e in evidence if e.source == "estimated"), None),
        slope_estimated_ci_rad=next((e.ci_rad for e in evidence if e.source == "estimated"), None),
        slope_residual_m=frame.residual_m,
        slope_points=frame.n_points,
        travel_direction=_xyz(travel),
        slope_origin_m=_xyz(frame.origin_m),
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
        hub_offset_sd_m=hub_sd_m,
        hub_offset_sd_axes_m=sd_axes,
        impact_step=tuple(int(k) for k in (steps.impact_step if steps.impact_step is not None else ())),
        period_step=tuple(int(k) for k in (steps.period_step if steps.period_step is not None else ())),
        warnings=tuple(warnings),
        up_axis=up.name,
        up_axis_reason=up.reason,
        parameters=tuple(import_parameters(wheel, leg_length_m)),
        impact_sd_s=tuple(float(v) for v in (steps.impact_sd_s if steps.impact_sd_s is not None else ())),
    )
    return Trial(ts, meta)


def _check_slope_possible(
    path: str,
    evidence: list[SlopeEvidence],
    time_s: np.ndarray,
    angle: np.ndarray | None,
    window: np.ndarray,
    alpha_rad: float,
) -> None:
    """Refuse a slope the observed motion rules out: a rimless wheel cannot stand on |slope| >= alpha/2, and a
    passive wheel that rolls uphill (slope < 0 beyond its interval) only slows down (checked when ``angle`` is
    given: pass it only when the body was seen standing on its feet)."""
    if not evidence:
        return
    e = evidence[0]
    lim = alpha_rad / 2
    if not math.isfinite(e.slope_rad) or abs(e.slope_rad) >= lim:
        raise TrialRefused(
            f"{path}: the {e.source} slope {math.degrees(e.slope_rad):.2f} deg is impossible for a "
            f"wheel that walks: beyond +-{math.degrees(lim):.1f} deg (alpha/2) it cannot stand "
            f"({e.method})"
        )
    if e.ci_rad[1] < 0 and angle is not None:
        a = np.where(window, angle, np.nan)
        ok = np.flatnonzero(np.isfinite(a))
        if ok.size > 4:
            av, tv = a[ok], time_s[ok]
            first = np.flatnonzero(av <= av[0] + alpha_rad)
            last = np.flatnonzero(av >= np.nanmax(av) - alpha_rad)
            if first.size > 1 and last.size > 1 and np.nanmax(av) - av[0] > 2 * alpha_rad:
                v0 = (av[first[-1]] - av[first[0]]) / max(tv[first[-1]] - tv[first[0]], 1e-9)
                v1 = (av[last[-1]] - av[last[0]]) / max(tv[last[-1]] - tv[last[0]], 1e-9)
                if v1 >= v0:
                    raise TrialRefused(
                        f"{path}: the {e.source} slope {math.degrees(e.slope_rad):.2f} deg (uphill) is impossible "
                        f"for the observed motion: the wheel speeds up from {v0:.2f} to {v1:.2f} rad/s over "
                        f"{np.degrees(np.nanmax(av) - av[0]):.0f} deg of rotation, and a passive wheel rolling "
                        f"uphill only slows ({e.method})"
                    )


def _unseen_periods(steps: StepResult) -> int:
    ks = steps.impact_step
    if ks is None or len(ks) < 2:
        return 0
    return int(ks[-1] - ks[0]) - int(len(steps.period_step if steps.period_step is not None else []))


def _plausibility(
    path: str,
    sec: Section,
    time_s: np.ndarray,
    hub_slope: np.ndarray,
    angle: np.ndarray | None,
    steps: StepResult,
    window_s: tuple[float, float],
    alpha_rad: float,
    leg_m: float,
    warnings: list[str],
) -> None:
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
                f"{'m (not mm)' if ratio < 0.1 else 'mm (not m)'}; fix the units row"
            )
        if not 0.5 <= ratio <= 2.0:
            warnings.append(
                f"the wheel moves {per_step:.3f} m per step where {expected:.3f} m is expected "
                f"(legs of {leg_m} m): check the units row (line {sec.units_line}) and the leg length"
            )
    else:
        dur = max(float(np.ptp(time_s[m])), 1e-9)
        speed = travel / dur
        if travel > 0 and (speed < 0.01 or speed > 20):
            raise TrialRefused(
                f"{where}: the units row says {'/'.join(unit) or '(none)'}, but the hub moves at {speed:.4g} m/s "
                "while walking (a wheel walks at about 0.1-2 m/s): check the units row"
            )


def _hub_at_cusps(time_s: np.ndarray, hub: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Hub at each CoM-height cusp: height from the V fit of Z, horizontal position interpolated."""
    return _cusps(time_s, hub, idx)[1]


def _height_cov_at(up_body: np.ndarray | None, idx: np.ndarray, cov_m2: np.ndarray | None) -> np.ndarray | None:
    """(k, k) covariance of the hub's heights at the frames ``idx`` from the offset's covariance ``cov_m2`` (3, 3,
    body frame), m^2: an offset error e puts z^T R e in the height, ``up_body`` (n, 3) the rows z^T R; None when
    either is missing or a row is unknown (then the offset's sd is carried on each axis)."""
    if up_body is None or cov_m2 is None or idx.size == 0:
        return None
    g = np.asarray(up_body[idx], np.float64)
    return None if not np.isfinite(g).all() else g @ cov_m2 @ g.T


def _cusps(time_s: np.ndarray, hub: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(time s, hub m (n, 3)) at each CoM-height cusp (`_hub_at_cusps`)."""
    half = max(3, int(0.25 * np.median(np.diff(idx)))) if idx.size > 1 else 5
    ok = ~np.isnan(hub).any(axis=1)
    tv, hv = time_s[ok], hub[ok]
    out = np.empty((idx.size, 3))
    out[:, 0], out[:, 2] = refine_cusps(time_s, hub[:, 2], idx, half)
    tc = out[:, 0].copy()
    out[:, 0] = np.interp(tc, tv, hv[:, 0])
    out[:, 1] = np.interp(tc, tv, hv[:, 1])
    return tc, out


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


#: The wheel's parameters that set the slope interval's drift allowance sqrt(M / k), M = m_H + 8 m.
LEG_FIELDS = ("hub_mass_kg", "leg_mass_kg", "stiffness_n_per_m")


def import_parameters(wheel: Any = None, leg_length_m: float | None = None) -> list[dict[str, Any]]:
    """What the importer held (``parameters`` of `Trial.to_dict` and of ``trials import --json``), in the entry
    format of the other commands (`rimless.sim.model.uncertain.ParamInput.as_dict`: name, symbol, value, sd, unit,
    source, basis).

    The legs' drift time sqrt(M / k) (M = m_H + 8 m, s) in the slope's interval (`slope_evidence.leg_compliance`,
    its own words in ``basis``): ``derived`` from the ``wheel``'s masses and k (listed with their sources) when it
    gives them (``sd`` None: see theirs), else the importer's bound (``assumed_bound``, ``sd`` None: a bound, not
    a measurement) or 0 for rigid legs (``rigid_legs``); and the leg length when given (``leg_length_m``, held
    exact)."""
    from rimless.analysis.kinematics.slope_evidence import UNKNOWN_LEG_TIME_S
    from rimless.sim.model.uncertain import ParamInput

    legs = leg_compliance(wheel)
    rows: list[dict[str, Any]] = []
    entries = getattr(getattr(wheel, "input", wheel), "entries", None)  # a `Wheel` or a wheel input
    from_wheel = isinstance(entries, dict) and 0 < legs.time_s != UNKNOWN_LEG_TIME_S
    if isinstance(entries, dict) and from_wheel:
        rows += [entries[n].as_dict() for n in LEG_FIELDS]
    source = "derived" if from_wheel else ("rigid_legs" if legs.time_s == 0 else "assumed_bound")
    rows.append(
        {
            "name": "leg_drift_time_s",
            "symbol": "sqrt(M/k)",
            "value": legs.time_s,
            "sd": 0.0 if legs.time_s == 0 else None,
            "unit": "s",
            "source": source,
            "basis": f"the slope interval's allowance for the legs' compression drift: {legs.source}",
        }
    )
    if leg_length_m is not None:
        given = "given (--leg-length-m / leg_length_m=): CoM height from the slope plane, held exact"
        rows.append(ParamInput("leg_length_m", float(leg_length_m), 0.0, "given", given).as_dict())
    return rows


def import_trial(path: str | Path, *, slopes: dict[str, tuple[float, str]] | None = None, **kwargs: Any) -> Trial:
    """`read_recording` (Vicon CSV or C3D) then `build_trial` (keyword arguments as there).

    ``slopes``: a slope manifest (`rimless.analysis.io.manifest.read_slope_manifest`); the row of this file, when
    there is one, gives ``slope_deg`` (a ``slope_deg`` keyword and a manifest together are refused).
    ``wheel`` may also be a wheel file's path (as ``trials import --params``: its values with their sds).
    The trial's ``meta.parameters`` (``parameters`` of `Trial.to_dict`) are what the import held
    (`import_parameters`), the entries of ``trials import --json``.
    """
    wheel = kwargs.get("wheel")
    if isinstance(wheel, (str, Path)):
        from rimless.sim.model.uncertain import read_wheel_input

        if not Path(wheel).is_file():
            raise UserError(f"wheel={wheel}: no such wheel file")
        kwargs["wheel"] = read_wheel_input(Path(wheel))
    if slopes is not None:
        row = slope_for(slopes, path)
        if row is not None:
            if kwargs.get("slope_deg") is not None:
                raise UserError("give either --slope-deg or --slopes, not both")
            kwargs["slope_deg"] = row[0]
            kwargs["slope_note"] = f"slope {row[0]:g} deg given in the manifest {row[1]}"
    return build_trial(read_recording(path), **kwargs)
