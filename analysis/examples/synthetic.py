"""A kinematic rigid rimless wheel rolling down a slope, seen by Vicon: ground truth for tests and demos.

The stance leg angle theta runs from -alpha/2 to +alpha/2 in each step (not uniformly), the stance foot
advances 2 L sin(alpha/2) per step, the hub is at foot + L (sin theta, cos theta) in the slope frame,
so the CoM height is L cos theta and impacts are the step boundaries.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SyntheticWheel", "rolling_wheel"]


@dataclass(frozen=True, eq=False)
class SyntheticWheel:
    """Ground truth and simulated measurements (world frame, Z up; m, rad, s)."""

    time_s: np.ndarray  # (n,)
    hub_m: np.ndarray  # (n, 3) true hub
    com_height_m: np.ndarray  # (n,) true height of the hub above the slope plane
    wheel_angle_rad: np.ndarray  # (n,) true rotation
    impact_time_s: np.ndarray  # (m,) true impacts inside the sampled time
    markers_m: np.ndarray  # (n, 4, 3) noisy markers
    object_rotvec_rad: np.ndarray  # (n, 3) helical angles of the object (noise-free orientation)
    object_trans_m: np.ndarray  # (n, 3) noisy object origin
    hub_offset_m: np.ndarray  # (3,) hub in the object frame
    slope_deg: float
    rate_hz: float
    leg_length_m: float


def rolling_wheel(
    *,
    slope_deg: float = 2.0,
    periods_s: tuple[float, ...] = (0.42, 0.40, 0.39, 0.38, 0.37, 0.37, 0.36, 0.36, 0.35),
    leg_length_m: float = 0.15,
    marker_radius_m: float = 0.1,
    rate_hz: float = 100.0,
    noise_m: float = 0.3e-3,
    yaw_deg: float = 30.0,
    origin_m: tuple[float, float, float] = (0.4, -1.2, 0.5),
    object_origin_in_body_m: tuple[float, float, float] = (0.03, -0.02, 0.01),
    alpha_rad: float = np.pi / 4,
    unevenness: float = 0.3,
    seed: int = 42,
) -> SyntheticWheel:
    """Sample a rolling rigid rimless wheel; ``periods_s`` are the step durations (steps start at t=0)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    bounds = np.concatenate([[0.0], np.cumsum(periods_s)])
    t = np.arange(0.0, bounds[-1], 1.0 / rate_hz)
    k = np.clip(np.searchsorted(bounds, t, side="right") - 1, 0, len(periods_s) - 1)
    u = (t - bounds[k]) / np.asarray(periods_s)[k]
    theta = -alpha_rad / 2 + alpha_rad * (u + unevenness * np.sin(2 * np.pi * u) / (2 * np.pi))
    step_len = 2 * leg_length_m * np.sin(alpha_rad / 2)
    x = k * step_len + leg_length_m * np.sin(theta)
    y = leg_length_m * np.cos(theta)
    beta = k * alpha_rad + theta + alpha_rad / 2

    phi = np.radians(slope_deg)
    yaw = np.radians(yaw_deg)
    travel = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = np.cos(phi) * travel - np.sin(phi) * up
    nrm = np.sin(phi) * travel + np.cos(phi) * up
    w = np.cross(d, nrm)
    hub = np.asarray(origin_m) + np.outer(x, d) + np.outer(y, nrm)

    # Body frame = (d, nrm, w) at beta = 0, turning about w by -beta (rolling forward in +x).
    base = np.column_stack([d, nrm, w])
    rot = Rotation.from_rotvec(np.outer(-beta, w)) * Rotation.from_matrix(base)
    gam = np.radians([10.0, 100.0, 190.0, 280.0])
    body_markers = marker_radius_m * np.column_stack([np.cos(gam), np.sin(gam), np.zeros(4)])
    mats = rot.as_matrix()
    markers = hub[:, None, :] + np.einsum("nij,kj->nki", mats, body_markers)
    markers = markers + rng.normal(0.0, noise_m, markers.shape)
    o = np.asarray(object_origin_in_body_m, dtype=np.float64)
    trans = hub + mats @ o + rng.normal(0.0, noise_m, hub.shape)
    impacts = bounds[(bounds >= t[0]) & (bounds <= t[-1])]
    return SyntheticWheel(
        t, hub, y, beta, impacts, markers, rot.as_rotvec(), trans, -o, slope_deg, rate_hz, leg_length_m
    )
