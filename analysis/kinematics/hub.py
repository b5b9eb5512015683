"""The wheel hub and the wheel angle, from four markers or from a tracked object's pose.

All positions in m, angles in rad, arrays with time on the first axis; NaN marks a missing frame.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# The offset's height fit lives in `hub_offset` (one concept); its names stay importable from here.
from rimless.analysis.kinematics.hub_offset import (  # noqa: F401  (re-exported)
    BUMP_HARMONICS,
    HUB_PRIOR_SD_M,
    MAX_FIT_FRAMES,
    MAX_OFFSET_PASSES,
    MAX_TRIMS,
    MISFIT_FALSE_ALARM,
    MISFIT_NOISE_MULTIPLE,
    OFFSET_TOL_M,
    OUTLIER_SIGMAS,
    PRIOR_NOISE_M,
    SIDEBANDS_PER_TURN,
    SPEED_TERMS,
    HubOffsetFit,
    describe_offset_fit,
    fit_offset,
)

__all__ = [
    "HubEstimate",
    "RotationStack",
    "apply_rotations",
    "axis_in_body",
    "hub_from_markers",
    "hub_from_object",
    "rotations_from_angles",
    "wheel_angle_from_rotations",
    "HubOffsetFit",
    "describe_offset_fit",
    "estimate_hub_offset",
    "fit_hub_offset",
    "hub_from_pose",
]

#: A marker frame fits the reference shape to this RMS, m (or 8x the median residual when larger).
RIGID_TOL_M = 0.005
#: Largest rotation of a marker set between consecutive frames, rad (a wheel turning 20 rad/s at 100 Hz).
MAX_TURN_PER_FRAME_RAD = 0.2
#: A marker set whose centroid moves more than this (m) plus this per frame is a seam, not a relabelling.
SEAM_M, SEAM_M_PER_FRAME = 0.1, 0.05
#: Least total rotation (rad) for a hub offset in the object frame to be observable.
MIN_ROTATION_FOR_OFFSET_RAD = np.pi


@dataclass(frozen=True, eq=False)
class HubEstimate:
    """Hub path and wheel rotation.

    Attributes
    ----------
    hub_m : (n, 3) world hub position, m; NaN where unknown.
    wheel_angle_rad : (n,) unwrapped wheel angle, increasing over the trial, or None when orientation
        is unknown.
    axis : (3,) world wheel axis (unit) or None.
    source : how the hub was obtained, in words.
    offset_m : (3,) hub offset in the object / marker frame, m, or None.
    offset_residual_m : RMS of the smoothness residual of the offset fit, m, or None.
    """

    hub_m: np.ndarray
    wheel_angle_rad: np.ndarray | None
    axis: np.ndarray | None
    source: str
    offset_m: np.ndarray | None = None
    offset_residual_m: float | None = None
    # (n, 3, 3) world-from-body (marker sets: from the reference frame); a RotationStack from hub_from_pose
    rotation: np.ndarray | RotationStack | None = None
    n_relabelled: int = 0  # frames whose marker labels were swapped and are repaired (marker sets)
    n_inconsistent: int = 0  # frames whose markers fit no rigid shape, made gaps (marker sets)
    offset_sd_m: float | None = None  # standard error of a fitted offset, m (`HubOffsetFit.sd_m`), or None


def rotations_from_angles(angles_rad: np.ndarray, convention: str = "helical") -> np.ndarray:
    """Rotation matrices (n, 3, 3) from Vicon RX, RY, RZ (n, 3), rad; NaN rows give NaN matrices.

    ``convention``: ``"helical"`` (rotation vector, Tracker's default) or an Euler sequence understood by
    scipy such as ``"xyz"`` (extrinsic) / ``"XYZ"`` (intrinsic).
    """
    from scipy.spatial.transform import Rotation

    a = np.asarray(angles_rad, dtype=np.float64)
    if a.shape[0] == 0:
        return np.zeros((0, 3, 3))
    ok = ~np.any(np.isnan(a), axis=1)
    # NaN rows are computed as zero rotations and set to NaN after: no masked copies of the matrices
    filled = np.where(ok[:, None], a, 0.0)  # also a writable copy of a read-only view (scipy needs one)
    rot = Rotation.from_rotvec(filled) if convention == "helical" else Rotation.from_euler(convention, filled)
    out = rot.as_matrix()
    out[~ok] = np.nan
    return out


class RotationStack:
    """World-from-body rotations of n frames (a stand-in for an (n, 3, 3) array), computed from the Vicon angles
    slice by slice when indexed: n x 3 angles are kept instead of n x 3 x 3 matrices.

    ``angles_rad`` (n, 3) as for `rotations_from_angles`; rows where ``invalid`` is True (e.g. six-zero
    occlusions) and NaN rows give NaN matrices. Indexing (a slice, integer or boolean rows) returns an array.
    """

    #: Frames per slice in whole-stack products.
    SLICE = 1 << 18

    def __init__(self, angles_rad: np.ndarray, convention: str = "helical", invalid: np.ndarray | None = None):
        self.angles, self.convention, self.invalid = angles_rad, convention, invalid
        self.shape = (angles_rad.shape[0], 3, 3)
        self[0:1]  # an unknown convention fails here, as `rotations_from_angles` would

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key) -> np.ndarray:
        a = self.angles[key]
        m = rotations_from_angles(a.reshape(-1, 3), self.convention)
        if self.invalid is not None:
            m[np.asarray(self.invalid[key]).reshape(-1)] = np.nan
        return m[0] if a.ndim == 1 else m

    def valid(self) -> np.ndarray:
        """(n,) True where the rotation is known."""
        ok = ~np.isnan(self.angles).any(axis=1)
        return ok if self.invalid is None else ok & ~self.invalid

    def masked(self, keep: np.ndarray) -> RotationStack:
        """The same stack with the rows where ``keep`` is False invalid."""
        bad = ~keep if self.invalid is None else self.invalid | ~keep
        return RotationStack(self.angles, self.convention, bad)

    def slices(self):
        for a in range(0, self.shape[0], self.SLICE):
            yield a, self[a : a + self.SLICE]


def _valid_rows(rot: np.ndarray | RotationStack) -> np.ndarray:
    if isinstance(rot, RotationStack):
        return rot.valid()
    return ~np.isnan(rot.reshape(rot.shape[0], 9)).any(axis=1)


def apply_rotations(rot: np.ndarray | RotationStack, d: np.ndarray) -> np.ndarray:
    """``rot @ d`` for every frame, (n, 3)."""
    if not isinstance(rot, RotationStack):
        return np.einsum("nij,j->ni", rot, d)
    out = np.empty((rot.shape[0], 3))
    for a, m in rot.slices():
        out[a : a + m.shape[0]] = np.einsum("nij,j->ni", m, d)
    return out


def axis_in_body(rot: np.ndarray | RotationStack, axis: np.ndarray, dtype: type = np.float64) -> np.ndarray:
    """``rot.T @ axis`` for every frame (a world axis in the body frame), (n, 3)."""
    if not isinstance(rot, RotationStack):
        return (axis @ rot).astype(dtype, copy=False)
    out: np.ndarray = np.empty((rot.shape[0], 3), dtype)
    for a, m in rot.slices():
        out[a : a + m.shape[0]] = axis @ m
    return out


def _rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation vectors of rotation matrices (k, 3, 3) turning less than 180 deg (the log map), rad.

    sin(angle) * axis is the skew part and cos(angle) comes from the trace; atan2 keeps it accurate for
    small and large angles alike (a vectorised form of scipy's ``as_rotvec`` for this range, ~10x faster).
    """
    v = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
    s = np.linalg.norm(v, axis=1)
    c = 0.5 * (m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2] - 1.0)
    ang = np.arctan2(s, c)
    scale = np.where(s > 1e-12, ang / np.where(s > 1e-12, s, 1.0), 1.0)
    return v * scale[:, None]


def _increment_rotvec(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation vectors of ``a @ b.T`` for stacks of rotations (k, 3, 3), from the trace and skew part only."""

    def dot(i: int, j: int) -> np.ndarray:  # (a @ b.T)[i, j] = row i of a . row j of b
        return np.einsum("nk,nk->n", a[:, i, :], b[:, j, :])

    v = np.empty((a.shape[0], 3))
    for col, (i, j) in enumerate(((2, 1), (0, 2), (1, 0))):
        v[:, col] = dot(i, j)
        v[:, col] -= dot(j, i)
    v *= 0.5
    c = dot(0, 0)
    c += dot(1, 1)
    c += dot(2, 2)
    c -= 1.0
    c *= 0.5
    s = np.sqrt(np.einsum("ni,ni->n", v, v))
    ang = np.arctan2(s, c)
    scale = np.where(s > 1e-12, ang / np.where(s > 1e-12, s, 1.0), 1.0)
    v *= scale[:, None]
    return v


def wheel_angle_from_rotations(rot: np.ndarray | RotationStack) -> tuple[np.ndarray, np.ndarray]:
    """Unwrapped rotation angle about the dominant world axis.

    Parameters
    ----------
    rot : (n, 3, 3) world-from-body rotations (or a `RotationStack`); NaN rows are gaps.

    Returns
    -------
    angle_rad : (n,), 0 at the first valid frame, increasing over the trial (axis sign chosen so);
        NaN at gaps. Increments between consecutive valid frames are assumed below 180 deg.
    axis : (3,) unit world axis.
    """
    n = rot.shape[0]
    ok = np.flatnonzero(_valid_rows(rot))
    angle = np.full(n, np.nan)
    if ok.size < 2:
        return angle, np.array([0.0, 0.0, 1.0])
    # Increments between consecutive valid frames (world frame): adjacent frames in one pass over ``rot``
    # (no copy of it), the few pairs across a gap separately.
    inc = np.empty((ok.size - 1, 3))
    step = 1 << 18  # pairs per slice: bounds the temporaries
    for a in range(0, ok.size - 1, step):
        b = min(a + step, ok.size - 1)
        i0, i1 = ok[a:b], ok[a + 1 : b + 1]
        adjacent = i1 - i0 == 1
        lo, hi = int(i0[0]), int(i0[-1])
        m = rot[lo : hi + 2]
        part = _increment_rotvec(m[1:], m[:-1])
        del m
        inc[a : a + i0.size][adjacent] = part[i0[adjacent] - lo]
        jump = np.flatnonzero(~adjacent)
        if jump.size:
            inc[a + jump] = _increment_rotvec(rot[i1[jump]], rot[i0[jump]])
    use = np.ones(inc.shape[0], bool)
    axis = np.array([0.0, 0.0, 1.0])
    norm = np.sqrt(np.einsum("ni,ni->n", inc, inc))
    for _ in range(3):
        # Rolling increments share one axis; a fall or a hand turning the wheel adds others: the axis is
        # refitted on the increments within 30 deg of it.
        sel = inc[use] if use.any() else inc
        w, v = np.linalg.eigh(sel.T @ sel)
        del sel
        axis = v[:, -1]
        use = np.abs(inc @ axis) >= np.cos(np.radians(30.0)) * norm
    steps = inc @ axis
    if steps.sum() < 0:
        axis, steps = -axis, -steps
    angle[ok[0]] = 0.0
    angle[ok[1:]] = np.cumsum(steps)
    return angle, axis


def hub_from_markers(points_m: np.ndarray, min_markers: int = 3) -> HubEstimate:
    """Hub and wheel angle from markers fixed on the wheel (e.g. four in one plane around the hub).

    The hub is the markers' centroid in the reference frame (the first frame where all are seen), carried
    through each frame by the rigid motion fitted (weighted Kabsch) to the visible markers, so it equals
    the centroid when all are seen and stays unbiased when one is occluded.

    Parameters
    ----------
    points_m : (n, k, 3) marker positions, m; NaN where occluded.
    min_markers : least number of visible markers for a frame to count (3 fixes a rigid pose).
    """
    p = np.asarray(points_m, dtype=np.float64)
    n, k, _ = p.shape
    if k == 1:
        return HubEstimate(p[:, 0].copy(), None, None, "single marker taken as the hub")
    vis = ~np.any(np.isnan(p), axis=2)  # (n, k)
    full = np.flatnonzero(vis.all(axis=1))
    if full.size == 0:
        raise ValueError("no frame shows all markers: no reference shape")
    ref = p[full[0]]
    ref.mean(axis=0)
    good = vis.sum(axis=1) >= min(min_markers, k)
    rot, hub, res = _kabsch_frames(ref, p, vis)
    n_repaired = n_dropped = 0
    if k >= 3:
        n_repaired, n_dropped = _relabel(ref, p, vis, good, rot, hub, res)
    hub[~good] = np.nan
    rot[~good] = np.nan
    angle = axis = None
    if k >= 3:
        angle, axis = wheel_angle_from_rotations(rot)
    return HubEstimate(
        hub,
        angle,
        axis,
        f"rigid fit of {k} markers (centroid of the reference frame)",
        rotation=rot,
        n_relabelled=n_repaired,
        n_inconsistent=n_dropped,
    )


def _rot_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of ``a^T b`` for stacks of rotations, rad."""
    c = 0.5 * (np.einsum("...ij,...ij->...", a, b) - 1.0)
    return np.arccos(np.clip(c, -1.0, 1.0))


def _relabel(
    ref: np.ndarray, p: np.ndarray, vis: np.ndarray, good: np.ndarray, rot: np.ndarray, hub: np.ndarray, res: np.ndarray
) -> tuple[int, int]:
    """Rigid-body consistency of a marker set, in place: a frame whose markers do not fit the reference shape
    (RMS above `RIGID_TOL_M` or 8x the median) or whose rotation jumps from the last consistent frame (more than
    `MAX_TURN_PER_FRAME_RAD` per frame: a symmetric marker layout fits a swap with a flipped pose) had labels
    swapped or a ghost marker. Every relabelling (sets of up to 5 markers, else every exchange of two) is tried; the one that fits the shape and continues
    the rotation is kept, else the frame becomes a gap (``good`` False). Returns (repaired, dropped) frames."""
    n, k, _ = p.shape
    ok_res = res[good]
    tol = max(RIGID_TOL_M, 8.0 * float(np.median(ok_res))) if ok_res.size else RIGID_TOL_M
    idx = np.flatnonzero(good)
    if idx.size < 2:
        return 0, 0
    jump = _rot_angle(rot[idx[:-1]], rot[idx[1:]]) / np.diff(idx)
    flag = np.zeros(n, bool)
    flag[idx[1:][jump > MAX_TURN_PER_FRAME_RAD]] = True
    flag[idx[res[idx] > tol]] = True
    if not flag.any():
        return 0, 0
    if k <= 5:  # every relabelling of a small set; else every exchange of two labels
        swaps = [np.array(q) for q in itertools.permutations(range(k))][1:]
    else:
        swaps = []
        for i in range(k):
            for j in range(i + 1, k):
                perm = np.arange(k)
                perm[[i, j]] = perm[[j, i]]
                swaps.append(perm)
    first = int(np.flatnonzero(flag)[0])
    prev = idx[idx < first]
    last_i = int(prev[-1]) if prev.size else None
    repaired = dropped = 0
    stop = int(np.flatnonzero(flag)[-1])
    i = first
    while i < n:
        if not good[i]:
            i += 1
            continue
        if i > stop and last_i is not None and last_i >= i - 1 and not flag[i]:
            break  # back to consistent frames after the last flagged one
        lim = MAX_TURN_PER_FRAME_RAD * (i - last_i) if last_i is not None else np.inf
        turn = float(_rot_angle(rot[last_i], rot[i])) if last_i is not None else 0.0
        if res[i] <= tol and turn <= lim:
            last_i = i
            i += 1
            continue
        if last_i is not None and np.linalg.norm(hub[i] - hub[last_i]) > SEAM_M + SEAM_M_PER_FRAME * (i - last_i):
            break  # the whole set jumps: a seam between two takes, not a relabelling (left to the seam check)
        best = None
        for perm in swaps:
            r2, h2, e2 = _kabsch_frames(ref, p[i : i + 1, perm], vis[i : i + 1, perm])
            t2 = float(_rot_angle(rot[last_i], r2[0])) if last_i is not None else 0.0
            if e2[0] <= tol and t2 <= lim and (best is None or e2[0] < best[2]):
                best = (r2[0], h2[0], float(e2[0]))
        if best is not None:
            rot[i], hub[i] = best[0], best[1]
            repaired += 1
            last_i = i
        else:
            good[i] = False
            dropped += 1
        i += 1
    return repaired, dropped


def _kabsch_frames(ref: np.ndarray, p: np.ndarray, vis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted Kabsch per frame: (rotations (n, 3, 3), the reference centroid carried (n, 3), RMS residual of the
    visible markers (n,), m); frames with under 3 visible markers have residual 0 (nothing to check)."""
    n, k, _ = p.shape
    c_ref = ref.mean(axis=0)
    w = vis.astype(np.float64)
    q = np.where(vis[..., None], p, 0.0)
    wsum = np.maximum(w.sum(axis=1, keepdims=True), 1.0)
    cq = (w[..., None] * q).sum(axis=1) / wsum  # (n, 3)
    cr = (w[..., None] * ref[None]).sum(axis=1) / wsum
    a = (ref[None] - cr[:, None]) * w[..., None]
    b = q - cq[:, None]
    h = np.einsum("nki,nkj->nij", a, b)  # (n, 3, 3)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.transpose(vt, (0, 2, 1)) @ np.transpose(u, (0, 2, 1))))
    dm = np.zeros((n, 3, 3))
    dm[:, 0, 0] = 1
    dm[:, 1, 1] = 1
    dm[:, 2, 2] = d
    rot = np.transpose(vt, (0, 2, 1)) @ dm @ np.transpose(u, (0, 2, 1))  # current = R @ ref
    hub = np.einsum("nij,nj->ni", rot, c_ref - cr) + cq
    fit = np.einsum("nij,nkj->nki", rot, ref[None] - cr[:, None]) + cq[:, None]
    err = np.where(vis, np.sum((fit - q) ** 2, axis=2), 0.0)
    res = np.sqrt(err.sum(axis=1) / wsum[:, 0])
    res[vis.sum(axis=1) < 3] = 0.0
    return rot, hub, res


def fit_hub_offset(
    rot: np.ndarray | RotationStack,
    trans_m: np.ndarray,
    *,
    alpha_rad: float = np.pi / 4,
    harmonics: int | None = None,
    mask: np.ndarray | None = None,
    angle_axis: tuple[np.ndarray, np.ndarray] | None = None,
) -> HubOffsetFit | None:
    """Hub offset in the object frame of a wheel rolling down a plane, with its standard error.

    A body point off the hub by e rises and falls by e once per turn, the hub only by the per-step bumps
    (period alpha in the wheel angle), so the hub is the body point whose world height is best explained by
    a straight line in the horizontal distance s travelled along the hub's path plus a periodic function of
    period alpha in the wheel angle (``harmonics`` Fourier terms, by default a fifth of the frames per step
    within `BUMP_HARMONICS`, which keep the per-step bumps from leaking into the offset); only frames where
    ``mask`` is True (the walking window) are used: minimise
    sum_t (T_z + (R d)_z - a - b s - bumps)^2 over d, a, b and the bumps (linear least squares for a given s).
    s is measured along the path of the hub being fitted, so the fit is repeated, each pass on the s of the
    last, until the offset settles (`MAX_OFFSET_PASSES`, `OFFSET_TOL_M`): with s from the tracked point's own
    path, its once-a-turn wobble times the slope b reads as an offset, and each pass leaves about tan(slope)
    of the previous error (two passes left 0.3 % of the offset, 0.1 mm for a 36 mm offset). d is sought in the
    wheel plane only: the component along the wheel axis is not observable (the axis is horizontal) and is set
    to 0. Needs about a full turn; None with fewer than 10 frames.

    The fit on the chosen frames is `hub_offset.fit_offset`: its covariance takes the noise's level at once a turn
    as the noise's variance (`hub_offset.noise_level`: not what the bump model leaves at the steps, more where the
    residuals' power beside once a turn is larger), plus what the height model misses when the wheel's speed
    changes when an F test at `MISFIT_FALSE_ALARM` finds it (``misfit_sd_m``, ``misfit_p_value``). ``cov_m2`` is
    the 2 x 2 covariance in the wheel plane (as a rank-2 3 x 3), ``sd_m`` its worst axis.
    """
    ok = _valid_rows(rot) & ~np.isnan(trans_m).any(axis=1)
    if mask is not None:
        ok &= mask
    if angle_axis is None:
        angle, axis = wheel_angle_from_rotations(
            rot.masked(ok) if isinstance(rot, RotationStack) else np.where(ok[:, None, None], rot, np.nan)
        )
    else:
        angle, axis = angle_axis
        angle = np.where(ok, angle, np.nan)
    ok &= np.isfinite(angle)
    if ok.sum() > MAX_FIT_FRAMES:  # the fit needs turns, not every frame: an even subsample
        keep = np.flatnonzero(ok)
        sub = np.zeros_like(ok)
        sub[keep[:: int(np.ceil(keep.size / MAX_FIT_FRAMES))]] = True
        ok = sub
    if ok.sum() < 10:
        return None
    frame = np.flatnonzero(ok)
    return fit_offset(
        rot[ok], trans_m[ok], angle[ok], axis, frame.astype(np.float64), alpha_rad=alpha_rad, harmonics=harmonics
    )


def estimate_hub_offset(
    rot: np.ndarray | RotationStack,
    trans_m: np.ndarray,
    *,
    alpha_rad: float = np.pi / 4,
    harmonics: int | None = None,
    mask: np.ndarray | None = None,
    angle_axis: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, float, float]:
    """`fit_hub_offset` as (offset_m (3,) in the object frame, RMS residual of the height fit m, total rotation
    seen rad); (0, NaN, rotation) with fewer than 10 frames."""
    fit = fit_hub_offset(rot, trans_m, alpha_rad=alpha_rad, harmonics=harmonics, mask=mask, angle_axis=angle_axis)
    if fit is not None:
        return fit.offset_m, fit.residual_m, fit.rotation_rad
    if angle_axis is None:
        angle, _ = wheel_angle_from_rotations(rot)
    else:
        angle = angle_axis[0]
    if mask is not None:
        angle = np.where(mask, angle, np.nan)
    total = float(np.nanmax(angle) - np.nanmin(angle)) if np.isfinite(angle).any() else 0.0
    return np.zeros(3), float("nan"), total


def hub_from_pose(
    rot: np.ndarray | RotationStack,
    trans: np.ndarray,
    *,
    hub_offset_m: np.ndarray | Sequence[float] | None = None,
    mask: np.ndarray | None = None,
    what: str = "object origin",
    angle_axis: tuple[np.ndarray, np.ndarray] | None = None,
) -> HubEstimate:
    """Hub = ``trans + rot @ offset``: the offset given, or fitted as the centre of rotation in the wheel plane.

    ``rot`` (n, 3, 3) world-from-body, ``trans`` (n, 3) m the path of the body point called ``what``; the fit
    (`fit_hub_offset`) uses the frames of ``mask`` and needs the body to turn more than 180 deg there.
    """
    angle, axis = wheel_angle_from_rotations(rot) if angle_axis is None else angle_axis
    sel = angle if mask is None else np.where(mask, angle, np.nan)
    total = float(np.nanmax(sel) - np.nanmin(sel)) if np.isfinite(sel).any() else 0.0
    residual = sd = None
    if hub_offset_m is not None:
        d = np.asarray(hub_offset_m, dtype=np.float64).reshape(3)
        source = (
            f"{what} (given offset 0)"
            if not d.any()
            else f"{what} + given offset [{d[0] * 1e3:.1f}, {d[1] * 1e3:.1f}, {d[2] * 1e3:.1f}] mm"
        )
    elif total < MIN_ROTATION_FOR_OFFSET_RAD:
        d = np.zeros(3)
        source = (
            f"{what} (it turns only {np.degrees(total):.1f} deg: the centre of rotation is not observable, "
            "no offset applied)"
        )
    else:
        fit = fit_hub_offset(rot, trans, mask=mask, angle_axis=(angle, axis))
        if fit is None:
            d = np.zeros(3)
            source = f"{what} (fewer than 10 frames to fit the centre of rotation on: no offset applied)"
        else:
            d, residual, sd = fit.offset_m, fit.residual_m, fit.sd_m
            source = f"{what} + estimated offset {describe_offset_fit(fit)}"
    hub = trans + apply_rotations(rot, d)
    return HubEstimate(hub, angle, axis, source, d, residual, rot, offset_sd_m=sd)


def hub_from_object(
    angles_rad: np.ndarray,
    trans_m: np.ndarray,
    *,
    hub_offset_m: np.ndarray | None = None,
    convention: str = "helical",
) -> HubEstimate:
    """Hub and wheel angle from a tracked object's pose (Vicon RX..RZ in rad, TX..TZ in m).

    Parameters
    ----------
    angles_rad, trans_m : (n, 3) each.
    hub_offset_m : (3,) hub position in the object frame, m. None: estimate it by `fit_hub_offset`
        when the object turns more than 180 deg, else take the object origin as the hub. Give ``(0, 0, 0)``
        when the object's origin is the hub.
    convention : see `rotations_from_angles`.
    """
    rot = rotations_from_angles(angles_rad, convention)
    trans = np.asarray(trans_m, dtype=np.float64)
    angle, axis = wheel_angle_from_rotations(rot)
    total = float(np.nanmax(angle) - np.nanmin(angle)) if np.isfinite(angle).any() else 0.0
    residual = sd = None
    if hub_offset_m is not None:
        d = np.asarray(hub_offset_m, dtype=np.float64).reshape(3)
        source = (
            "object origin (given offset 0)"
            if not d.any()
            else "object origin + given offset [{:.1f}, {:.1f}, {:.1f}] mm".format(*(d * 1e3))
        )
    elif total < MIN_ROTATION_FOR_OFFSET_RAD:
        d = np.zeros(3)
        source = (
            f"object origin (it turns only {np.degrees(total):.1f} deg: a hub offset is not observable, none applied)"
        )
    else:
        fit = fit_hub_offset(rot, trans, angle_axis=(angle, axis))
        if fit is None:
            d = np.zeros(3)
            source = "object origin (fewer than 10 frames to fit the centre of rotation on: no offset applied)"
        else:
            d, residual, sd = fit.offset_m, fit.residual_m, fit.sd_m
            source = f"object origin + estimated offset {describe_offset_fit(fit)}"
    hub = trans + np.einsum("nij,j->ni", rot, d)
    return HubEstimate(hub, angle, axis, source, d, residual, rot, offset_sd_m=sd)
