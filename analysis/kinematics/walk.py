"""The walking window of a recording (release to last impact) and how the trial ended.

A recording holds more than the walk: the wheel held still before the release, and after the last impact
a hand catching and lifting it, a fall sideways, a stall (it rocks back and rests), or the wheel leaving the
capture volume. `find_motion` locates the release and the end of the forward rotation from the wheel angle
(or, without orientation, from the distance travelled); `classify_ending` tells the ending apart in the
slope frame (x down the slope, y the outward normal, z lateral; m, rad, s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Motion", "Ending", "OUTCOMES", "find_motion", "classify_ending"]

#: How a trial ends: walked (left the ramp or the volume still walking), stalled (slowed, rocked back, came to
#: rest), fell (left the plane of motion), caught (lifted off the slope), unknown.
OUTCOMES = ("walked", "stalled", "fell", "caught", "unknown")

#: Rotation (rad) that counts as the wheel moving off its rest pose (above the marker noise).
MOVE_TOL_RAD = np.radians(1.0)
#: Lateral drift or drop below the walking band, m, that means the wheel left its plane of motion.
FALL_DISTANCE_M = 0.03
#: Tilt of the wheel axis, rad, that means the wheel fell over.
FALL_TILT_RAD = np.radians(20.0)
#: Rise above the walking band, m, and how long it lasts, s, that mean the wheel was lifted.
LIFT_M = 0.005
LIFT_DURATION_S = 0.1
#: How long the wheel must stay put after its last impact to count as stalled, s.
REST_S = 0.3
#: At the end of the data a wheel turning forward at this fraction of its walking speed (and never back) walked.
WALKING_SPEED_FRACTION = 0.1


@dataclass(frozen=True)
class Motion:
    """Where the wheel moves.

    release_index : first frame of the walk (the last frame at rest when the wheel was held), index.
    end_index : frame where the forward rotation reaches its final maximum (later the wheel does not
        advance: it was caught, fell, stalled, or the recording ended), index.
    held : a hold (the wheel at rest for > 0.15 s) precedes the release.
    """

    release_index: int
    end_index: int
    held: bool


@dataclass(frozen=True)
class Ending:
    """How a trial ended: one of `OUTCOMES` and the evidence in words."""

    outcome: str
    reason: str


def _progress(time_s: np.ndarray, angle_rad: np.ndarray | None, hub_m: np.ndarray, leg_m: float) -> np.ndarray:
    """Forward progress, rad: the wheel angle, or the distance along the main path direction / leg length."""
    if angle_rad is not None and np.isfinite(angle_rad).sum() >= 2:
        return np.asarray(angle_rad, float)
    ok = ~np.isnan(hub_m).any(axis=1)
    xy = hub_m[:, :2]
    c = xy[ok] - xy[ok].mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    u = vt[0] if (xy[ok][-1] - xy[ok][0]) @ vt[0] >= 0 else -vt[0]
    return (xy - xy[ok][0]) @ u / leg_m


def find_motion(
    time_s: np.ndarray, angle_rad: np.ndarray | None, hub_m: np.ndarray, *, leg_length_m: float = 0.237
) -> Motion:
    """Release and end of the forward motion (see `Motion`); needs at least two valid frames."""
    p = _progress(time_s, angle_rad, hub_m, leg_length_m)
    ok = np.flatnonzero(np.isfinite(p))
    if ok.size < 2:
        return Motion(0, max(len(time_s) - 1, 0), False)
    pv, tv = p[ok], time_s[ok]
    from rimless.analysis.kinematics.steps import noise_sigma

    sigma = noise_sigma(pv)
    tol = max(MOVE_TOL_RAD, 6 * sigma if np.isfinite(sigma) else 0.0)
    rest = np.median(pv[tv <= tv[0] + 0.05])
    moved = np.flatnonzero(np.abs(pv - rest) > tol)
    if moved.size == 0:
        return Motion(int(ok[0]), int(ok[-1]), False)
    i0 = int(moved[0])
    held = tv[i0] - tv[0] > 0.15
    release = int(ok[max(i0 - 1, 0)]) if held else int(ok[0])
    cm = np.maximum.accumulate(pv)
    final = cm[-1]
    end = int(ok[int(np.argmax(pv >= final - tol))])
    return Motion(release, max(end, release), held)


def classify_ending(
    time_s: np.ndarray,
    hub_slope_m: np.ndarray,
    progress_rad: np.ndarray | None,
    window: tuple[int, int],
    *,
    axis_tilt_rad: np.ndarray | None = None,
    noise_m: float = 0.0,
) -> Ending:
    """Classify what happens after the walking window (indices ``window``, last = the last impact).

    ``hub_slope_m`` is the hub in the slope frame (y = height above the impact line); ``progress_rad`` the
    wheel angle (or travel / leg length); ``axis_tilt_rad`` the tilt of the wheel axis from its walking
    direction.
    """
    t = np.asarray(time_s, float)
    y, z = hub_slope_m[:, 1], hub_slope_m[:, 2]
    ok = ~np.isnan(hub_slope_m).any(axis=1)
    i0, i1 = window
    walk = ok.copy()
    walk[:i0] = False
    walk[i1 + 1 :] = False
    if walk.sum() < 3:
        return Ending("unknown", "too few frames in the walking window")
    post = ok.copy()
    post[: i1 + 1] = False
    h_lo, h_hi = np.percentile(y[walk], [0.5, 99.5])
    z_mid = float(np.median(z[walk]))
    if not post.any():
        return Ending("walked", "the recording ends at the last impact")
    # Lifted (caught) and out of the plane of motion (fell): whichever comes first. A catch often moves the
    # wheel a little sideways; that is not a fall unless the wheel tips or drops.
    lateral = np.abs(z - z_mid) > FALL_DISTANCE_M
    dropped = y < h_lo - FALL_DISTANCE_M
    tilted = np.zeros_like(post) if axis_tilt_rad is None else np.nan_to_num(axis_tilt_rad) > FALL_TILT_RAD
    lift = max(LIFT_M, 8 * noise_m)
    up = post & (y > h_hi + lift)
    t_lift = _first_run_start_s(t, up, LIFT_DURATION_S)
    tipped = post & (dropped | tilted)
    t_tip = float(t[int(np.argmax(tipped))]) if tipped.any() else math.inf
    if t_lift is not None and t_lift <= t_tip:
        k = int(np.argmax(up & (t >= t_lift)))
        side = float(np.nanmax(np.abs(np.where(post, z - z_mid, np.nan))))
        return Ending(
            "caught",
            f"the hub rises {(np.nanmax(np.where(post, y, np.nan)) - h_hi) * 1e3:.0f} mm "
            f"above the walking band from {t[k]:.2f} s: lifted off the slope"
            + (f" (moved {side * 1e3:.0f} mm sideways while lifted)" if side > FALL_DISTANCE_M else ""),
        )
    fell = post & (lateral | dropped | tilted)
    if fell.any():
        k = int(np.argmax(fell))
        why = (
            f"the wheel axis tilts by more than {np.degrees(FALL_TILT_RAD):.0f} deg"
            if tilted[k]
            else f"the hub drops {(h_lo - y[k]) * 1e3:.0f} mm below the walking band"
            if dropped[k]
            else f"the hub moves {abs(z[k] - z_mid) * 1e3:.0f} mm sideways"
        )
        return Ending(
            "fell", f"{why} at {t[k]:.2f} s: the wheel left its plane of motion (tipped about the travel axis)"
        )
    last_valid = int(np.flatnonzero(ok)[-1])
    trailing_gap_s = float(t[-1] - t[last_valid])
    if progress_rad is not None:
        pw = progress_rad[walk]
        speed_walk = (pw[-1] - pw[0]) / max(t[walk][-1] - t[walk][0], 1e-9)
        tail = post & (t >= t[last_valid] - 0.1)
        pp = progress_rad[tail]
        speed_end = (pp[-1] - pp[0]) / max(t[tail][-1] - t[tail][0], 1e-9) if pp.size >= 2 else np.nan
        back = float(np.nanmax(progress_rad[post | walk]) - progress_rad[last_valid])
        # A stall: the angular velocity goes through zero and back (the wheel rocks back), checked first.
        if back > MOVE_TOL_RAD:
            return Ending(
                "stalled",
                f"after the last impact the wheel turns back {np.degrees(back):.1f} deg "
                "(its angular velocity goes through zero and reverses): a stall",
            )
        still = np.isfinite(speed_end) and speed_walk > 0 and speed_end >= WALKING_SPEED_FRACTION * speed_walk
        if still:
            where = "the wheel leaves the capture volume" if trailing_gap_s > 0.05 else "the recording ends"
            return Ending(
                "walked",
                f"{where} while it still rolls forward ({speed_end:.2f} rad/s, "
                f"{speed_end / speed_walk:.0%} of its walking speed, never turning back)",
            )
        # Near the critical slope the wheel is slowest over the foot: slow is not at rest. A stall needs the
        # wheel to stay put for REST_S; a recording that ends sooner while it slows cannot tell.
        rest = post & (t >= t[last_valid] - REST_S)
        if t[last_valid] - t[np.flatnonzero(post)[0]] >= REST_S:
            spread = float(np.nanmax(progress_rad[rest]) - np.nanmin(progress_rad[rest]))
            if spread < MOVE_TOL_RAD:
                return Ending("stalled", f"after the last impact the wheel slows and stays at rest for {REST_S:.1f} s")
        if np.isfinite(speed_end) and abs(speed_end) < 0.1 * speed_walk:
            return Ending(
                "unknown",
                "the recording ends while the wheel slows over its foot, too soon to tell a stall from a slow step",
            )
    return Ending("unknown", "the end of the recording matches no known ending")


def _first_run_start_s(t: np.ndarray, m: np.ndarray, min_s: float) -> float | None:
    """Start time of the first run of True in ``m`` lasting at least ``min_s``, or None."""
    if not m.any():
        return None
    e = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    s, f = np.flatnonzero(e == 1), np.flatnonzero(e == -1) - 1
    for a, b in zip(s, f):
        if t[b] - t[a] >= min_s:
            return float(t[a])
    return None


def _longest_run_s(t: np.ndarray, m: np.ndarray) -> float:
    if not m.any():
        return 0.0
    e = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    s, f = np.flatnonzero(e == 1), np.flatnonzero(e == -1) - 1
    return float(np.max(t[f] - t[s])) if s.size else 0.0
