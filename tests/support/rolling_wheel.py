"""A rigid rimless wheel rolling down a plane at a given turn, the body tracked at a point off its hub.

Written apart from ``rimless.analysis`` (it imports nothing from it), for the hub offset's tests: eight legs, the
hub over the stance foot at L (sin theta, cos theta) in the slope frame, the body turned by the wheel's angle about
the wheel axis. No dynamics: the turn is given.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

#: the angle between legs, rad (eight legs)
ALPHA_RAD = math.pi / 4


def rolling_wheel(
    beta_rad: np.ndarray, origin_body_m: np.ndarray, *, slope_deg: float = 4.0, leg_m: float = 0.22
) -> tuple[np.ndarray, np.ndarray]:
    """(world-from-body rotations (n, 3, 3), the tracked point (n, 3) m) of a wheel turned by ``beta_rad`` (n,) rad
    since a stance began (increasing), rolling without slip down a ``slope_deg`` plane on legs of ``leg_m``, its
    body point ``origin_body_m`` (3,) m off the hub. World Z up, the slope down along +x; the body frame at beta 0
    is (down the slope, the slope's normal, the wheel axis)."""
    phi = math.radians(slope_deg)
    theta = np.mod(beta_rad, ALPHA_RAD) - ALPHA_RAD / 2  # the stance leg's angle from the slope's normal
    step = np.floor(beta_rad / ALPHA_RAD)
    x = step * 2 * leg_m * math.sin(ALPHA_RAD / 2) + leg_m * np.sin(theta)  # hub down the slope, m
    h = leg_m * np.cos(theta)  # hub along the slope's normal, m
    down = np.array([math.cos(phi), 0.0, -math.sin(phi)])
    nrm = np.array([math.sin(phi), 0.0, math.cos(phi)])
    axis = np.cross(down, nrm)
    hub = np.outer(x, down) + np.outer(h, nrm)
    rot = Rotation.from_rotvec(np.outer(-beta_rad, axis)) * Rotation.from_matrix(np.column_stack([down, nrm, axis]))
    return rot.as_matrix(), hub + rot.apply(np.asarray(origin_body_m, float))
