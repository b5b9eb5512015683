"""The slope frame (model.md section 2) from the hub path, and the CoM height.

Slope frame: x down the slope (the walking direction), y the outward slope normal, z = x cross y
(lateral). The vertical world axis is Z (Vicon). CoM height = hub height normal to the slope.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SlopeFrame", "travel_direction", "robust_line", "fit_slope"]

#: Points used by the whole-path slope fit (evenly subsampled beyond).
MAX_PATH_POINTS = 20_000


@dataclass(frozen=True, eq=False)
class SlopeFrame:
    """A slope plane direction and origin in world coordinates.

    Attributes
    ----------
    slope_rad : inclination, rad, positive when the wheel goes down along ``travel``.
    travel : (3,) unit horizontal walking direction (world).
    origin_m : (3,) world point on the reference line (the hub line at impacts when known), m.
    residual_m : RMS residual of the line fit, m (NaN when the slope was given and not fitted).
    source : ``"given"`` or how it was estimated.
    n_points : points used by the fit.
    se_rad : standard error of the fitted slope, rad (NaN when given or from two points).
    """

    slope_rad: float
    travel: np.ndarray
    origin_m: np.ndarray
    residual_m: float
    source: str
    n_points: int = 0
    se_rad: float = float("nan")

    @property
    def slope_deg(self) -> float:
        """Inclination, deg."""
        return float(np.degrees(self.slope_rad))

    def axes(self) -> np.ndarray:
        """(3, 3) rows: x down the slope, y outward normal, z lateral, in world coordinates."""
        up = np.array([0.0, 0.0, 1.0])
        c, s = np.cos(self.slope_rad), np.sin(self.slope_rad)
        x = c * self.travel - s * up
        y = s * self.travel + c * up
        return np.vstack([x, y, np.cross(x, y)])

    def to_slope(self, points_m: np.ndarray) -> np.ndarray:
        """World points (n, 3) -> slope-frame coordinates (n, 3), m, relative to ``origin_m``."""
        # einsum, not BLAS: for (n, 3) x (3, 3) it is as fast and does not spin threads on a busy machine
        return np.einsum("ni,ji->nj", np.asarray(points_m) - self.origin_m, self.axes())


def travel_direction(hub_m: np.ndarray) -> np.ndarray:
    """Unit horizontal direction of travel: main axis of the horizontal hub path, signed by the net motion."""
    xy = hub_m[~np.isnan(hub_m).any(axis=1), :2]
    if xy.shape[0] > MAX_PATH_POINTS:
        xy = np.concatenate([xy[:: int(np.ceil(xy.shape[0] / MAX_PATH_POINTS))], xy[-1:]])
    if xy.shape[0] < 2:
        raise ValueError("fewer than 2 hub samples: no direction of travel")
    c = xy - xy.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    u = vt[0]
    if (xy[-1] - xy[0]) @ u < 0:
        u = -u
    return np.array([u[0], u[1], 0.0])


def robust_line(
    x: np.ndarray, y: np.ndarray, *, slope: float | None = None, iterations: int = 20
) -> tuple[float, float, np.ndarray]:
    """Huber-weighted line ``y = a + b x`` (b fixed when ``slope`` is given). Returns a, b, residuals."""
    w = np.ones_like(x)
    a = b = 0.0
    for _ in range(iterations):
        if slope is None:
            sw = w.sum()
            xm, ym = (w * x).sum() / sw, (w * y).sum() / sw
            sxx = (w * (x - xm) ** 2).sum()
            b = float((w * (x - xm) * (y - ym)).sum() / sxx) if sxx > 0 else 0.0
            a = float(ym - b * xm)
        else:
            b = slope
            a = float((w * (y - b * x)).sum() / w.sum())
        r = y - a - b * x
        scale = 1.4826 * np.median(np.abs(r - np.median(r))) + 1e-12
        k = 1.345 * scale
        w = np.where(np.abs(r) <= k, 1.0, k / np.maximum(np.abs(r), 1e-300))
    return a, b, y - a - b * x


def fit_slope(
    hub_m: np.ndarray,
    *,
    slope_deg: float | None = None,
    points_m: np.ndarray | None = None,
    travel: np.ndarray | None = None,
) -> SlopeFrame:
    """Slope frame from the hub path: robust line of Z against horizontal distance along the travel.

    Parameters
    ----------
    hub_m : (n, 3) world hub path, m (NaN rows ignored).
    slope_deg : known slope, deg; then only the line's offset is fitted.
    points_m : optional (k, 3) world points to fit instead of the whole path, e.g. the hub at the
        CoM-height minima (impacts), which lie on a line parallel to the slope for rigid legs.
    travel : horizontal travel direction; default `travel_direction`.
    """
    u = travel_direction(hub_m) if travel is None else travel
    ok = np.flatnonzero(~np.isnan(hub_m).any(axis=1))
    # The whole-path fit is a first guess: an even subsample of at most MAX_PATH_POINTS points is enough.
    pts = (
        hub_m[ok[:: max(1, int(np.ceil(ok.size / MAX_PATH_POINTS)))]]
        if points_m is None
        else np.asarray(points_m, dtype=np.float64)
    )
    if pts.shape[0] < 2:
        raise ValueError("fewer than 2 hub samples: cannot fit the slope")
    p0 = hub_m[ok[0]]
    s = (pts - p0) @ u
    z = pts[:, 2]
    given = None if slope_deg is None else -np.tan(np.radians(slope_deg))
    a, b, r = robust_line(s, z, slope=given)
    phi = float(np.arctan(-b))
    origin = p0 + np.array([0.0, 0.0, a - p0[2]])
    source = (
        "given"
        if slope_deg is not None
        else (
            "robust line through the whole hub path"
            if points_m is None
            else f"robust line through the hub at {pts.shape[0]} CoM-height minima"
        )
    )
    resid = float(np.sqrt(np.mean(r**2)))
    se = float("nan")
    if given is None and s.size > 2:
        sxx = float(np.sum((s - s.mean()) ** 2))
        if sxx > 0:  # standard error of the line's slope (from the residual scatter), in angle
            se = float(np.sqrt(np.sum(r**2) / (s.size - 2) / sxx)) / (1.0 + b * b)
    # The residual is vertical; express it normal to the slope.
    return SlopeFrame(phi, u, origin, resid * float(np.cos(phi)), source, int(pts.shape[0]), se)
