"""Independent truth model for import tests: a rigid rimless wheel rolling over its feet, recorded the messy way.

Written apart from ``rimless.analysis`` (it imports nothing from it): kinematics, the Vicon Tracker CSV text and
the expected results all come from here.

Slope frame: x down the slope, y the outward normal, z lateral. During step k (0-based) the stance foot is
at x = k * 2 L sin(alpha/2) and the stance angle runs from -alpha/2 to +alpha/2 with a non-uniform profile;
the hub is at foot + L (sin th, cos th); the wheel has turned k alpha + th + alpha/2 since the release.
The recording: a hold before the release, the walk, then an ending (``walked`` = the data stop while walking,
``left`` = the wheel leaves the volume (markers vanish), ``caught`` = stops and is lifted along world Z,
``fell`` = tips about the down-slope axis through the foot, ``stalled`` = rocks back onto its feet and rests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

ALPHA = math.pi / 4
L = 0.237  # paper Table 1 leg length, m


@dataclass
class Truth:
    rate_hz: float
    time_s: np.ndarray
    hub_world: np.ndarray  # (n, 3) m
    rot: Rotation  # world-from-body
    com_height: np.ndarray  # hub height normal to the slope plane, m
    walking: np.ndarray  # (n,) bool, inside [release, last impact]
    impact_time_s: np.ndarray  # every impact (step boundaries) inside the walk, s
    release_s: float
    outcome: str
    slope_deg: float
    axis_world: np.ndarray
    normal_world: np.ndarray
    down_world: np.ndarray
    ramp_pose: np.ndarray | None = None  # (6,) helical rad + m of a static Ramp object (z = slope normal)
    ramp_markers: np.ndarray | None = None  # (4, 3) m on the slope surface
    gaps: list[tuple[float, float]] = field(default_factory=list)


def _stance(u: np.ndarray) -> np.ndarray:
    return -ALPHA / 2 + ALPHA * (u + 0.25 * np.sin(2 * np.pi * u) / (2 * np.pi))


def make_truth(
    *,
    slope_deg: float = 2.0,
    periods_s=(0.46, 0.44, 0.42, 0.41, 0.40, 0.39, 0.38, 0.38),
    hold_s: float = 0.6,
    ending: str = "walked",
    end_fraction: float = 0.5,
    lift_m: float = 0.02,
    rate_hz: float = 100.0,
    yaw_deg: float = 35.0,
    origin=(0.3, -0.8, 0.45),
    after_s: float = 1.0,
    ramp: bool = False,
) -> Truth:
    """Sample the wheel; ``end_fraction`` is how far into the step after the last impact the ending starts."""
    phi = math.radians(slope_deg)
    yaw = math.radians(yaw_deg)
    tr = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(phi) * tr - math.sin(phi) * up
    nrm = math.sin(phi) * tr + math.cos(phi) * up
    w = np.cross(d, nrm)
    org = np.asarray(origin, float)
    bounds = hold_s + np.concatenate([[0.0], np.cumsum(periods_s)])
    n_steps = len(periods_s)
    last_T = periods_s[-1]
    t_end_walk = bounds[-1]
    if ending in ("walked", "left"):
        total = t_end_walk + end_fraction * last_T
    else:
        total = t_end_walk + end_fraction * last_T + after_s
    t = np.arange(0.0, total, 1.0 / rate_hz)
    x = np.zeros(t.size)
    y = np.zeros(t.size)
    np.zeros(t.size)
    beta = np.zeros(t.size)
    tip = np.zeros(t.size)  # tipping angle about the down-slope axis
    lift = np.zeros(t.size)
    step_len = 2 * L * math.sin(ALPHA / 2)
    for i, ti in enumerate(t):
        if ti < bounds[0]:
            k, th = 0, -ALPHA / 2
        elif ti < bounds[-1]:
            k = int(np.searchsorted(bounds, ti, side="right") - 1)
            th = float(_stance(np.array([(ti - bounds[k]) / periods_s[k]]))[0])
        else:
            k = n_steps
            u = (ti - bounds[-1]) / last_T
            if ending in ("walked", "left"):
                th = float(_stance(np.array([u]))[0])
            else:
                ue = min(u, end_fraction)
                th = float(_stance(np.array([ue]))[0])
                tau = ti - (bounds[-1] + end_fraction * last_T)
                if ending == "stalled":
                    # rocks back: theta returns to -alpha/2 with decaying bounces, then rests
                    th_peak = float(_stance(np.array([end_fraction]))[0])
                    amp = th_peak + ALPHA / 2
                    if tau > 0:
                        th = -ALPHA / 2 + amp * abs(math.cos(math.pi * tau / 0.5 * 0.5)) * math.exp(-tau / 0.15)
                elif ending == "caught" and tau > 0:
                    lift[i] = lift_m * min(tau / 0.3, 1.0) ** 2 * (3 - 2 * min(tau / 0.3, 1.0))
                elif ending == "fell" and tau > 0:
                    s = min(tau / 0.5, 1.0)
                    tip[i] = math.radians(80) * s * s
        x[i] = k * step_len + L * math.sin(th)
        y[i] = L * math.cos(th)
        beta[i] = k * ALPHA + th + ALPHA / 2
    foot = org + np.outer(np.floor(np.maximum(beta - 1e-12, 0) / ALPHA).clip(0, n_steps) * step_len, d)
    hub = org + np.outer(x, d) + np.outer(y, nrm) + np.outer(lift, up)
    rot = Rotation.from_rotvec(np.outer(-beta, w)) * Rotation.from_matrix(np.column_stack([d, nrm, w]))
    if ending == "fell":
        k_foot = org + n_steps * step_len * d
        tipper = Rotation.from_rotvec(np.outer(tip, d))
        rel = hub - k_foot
        hub = k_foot + tipper.apply(rel)
        rot = tipper * rot
        del foot
    com = (hub - org) @ nrm
    release = bounds[0]
    impacts = bounds[1:]  # the release is not an impact
    last_imp = impacts[-1]
    if ending in ("walked", "left"):
        impacts = impacts[impacts <= t[-1]]
        last_imp = impacts[-1]
    walking = (t >= release) & (t <= last_imp + 1e-9)
    out = {"walked": "walked", "left": "walked", "caught": "caught", "fell": "fell", "stalled": "stalled"}[ending]
    truth = Truth(rate_hz, t, hub, rot, com, walking, impacts, release, out, slope_deg, w, nrm, d)
    if ramp:
        # a Ramp object beside the path whose z axis is the slope normal; corner markers on the surface
        base = org - 0.3 * w - 0.5 * d
        r = Rotation.from_matrix(np.column_stack([d, np.cross(nrm, d), nrm]))
        truth.ramp_pose = np.concatenate([r.as_rotvec(), base])
        truth.ramp_markers = np.array([base, base + 2.0 * d, base + 2.0 * d - 0.6 * w, base - 0.6 * w]) - 0.006 * nrm
    return truth


def body_points(truth: Truth, pts_body: np.ndarray) -> np.ndarray:
    """World positions (n, k, 3) of body-frame points (x, y in the wheel plane, z along the axis), m."""
    mats = truth.rot.as_matrix()
    return truth.hub_world[:, None, :] + np.einsum("nij,kj->nki", mats, pts_body)


#: Four wheel markers on the face, 3 cm out along the axis, unevenly placed: centroid 14 mm off the hub.
UNEVEN_MARKERS = np.array([[0.110, 0.000, 0.03], [0.000, 0.095, 0.03], [-0.080, 0.010, 0.03], [0.026, -0.105, 0.03]])
EVEN_MARKERS = np.array([[0.1, 0.0, 0.03], [0.0, 0.1, 0.03], [-0.1, 0.0, 0.03], [0.0, -0.1, 0.03]])


def centroid_offset_mm(pts: np.ndarray) -> float:
    return float(np.linalg.norm(pts[:, :2].mean(axis=0)) * 1e3)


# ------------------------------------------------------------------------------------------- writing


def _fmt(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.6f}"


def section_text(
    kind: str,
    rate: str,
    groups: list[tuple[str, str, np.ndarray]],
    *,
    comps: tuple[str, ...],
    units: tuple[str, ...],
    scale: tuple[float, ...],
    first_frame: int = 1,
    frames: np.ndarray | None = None,
) -> list[str]:
    """Lines of one Tracker/Nexus section; ``groups`` = (name-row text, unused, (n, k) values in SI)."""
    names = ["", ""]
    comp = ["Frame", "Sub Frame"]
    unit = ["", ""]
    cols = []
    for name, _, arr in groups:
        names += [name] + [""] * (len(comps) - 1)
        comp += list(comps)
        unit += list(units)
        cols.append(np.asarray(arr, float) / np.asarray(scale))
    data = np.concatenate(cols, axis=1)
    n = data.shape[0]
    fr = np.arange(first_frame, first_frame + n) if frames is None else frames
    lines = [kind, rate, ",".join(names), ",".join(comp), ",".join(unit)]
    for i in range(n):
        lines.append(",".join([str(int(fr[i])), "0", *(_fmt(v) for v in data[i])]))
    return lines


def markers_section(markers: dict[str, np.ndarray], rate: str = "100", unit: str = "mm", **kw) -> list[str]:
    s = {"mm": 1e-3, "m": 1.0}[unit]
    return section_text(
        "Trajectories",
        rate,
        [(k, "", v) for k, v in markers.items()],
        comps=("X", "Y", "Z"),
        units=(unit,) * 3,
        scale=(s,) * 3,
        **kw,
    )


def objects_section(objects: dict[str, np.ndarray], rate: str = "100", **kw) -> list[str]:
    return section_text(
        "Objects",
        rate,
        [(f"Global Angle {k}:{k}", "", v) for k, v in objects.items()],
        comps=("RX", "RY", "RZ", "TX", "TY", "TZ"),
        units=("rad",) * 3 + ("mm",) * 3,
        scale=(1.0,) * 3 + (1e-3,) * 3,
        **kw,
    )


def write(path, *sections: list[str]) -> str:
    text = "\n".join("\n".join(s) + "\n" for s in sections)
    with open(path, "w", newline="") as f:
        f.write(text)
    return str(path)


def noisy(a: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    return a + np.random.default_rng(seed).normal(0.0, sigma, a.shape)


def blank(a: np.ndarray, truth: Truth, t0: float, t1: float) -> np.ndarray:
    """Copy of ``a`` (time on axis 0) with NaN over t0 <= t < t1 (an occlusion); records the gap."""
    b = np.array(a, float, copy=True)
    m = (truth.time_s >= t0) & (truth.time_s < t1)
    b[m] = np.nan
    truth.gaps.append((t0, t1))
    return b


def pose_of(truth: Truth, origin_body: np.ndarray, sigma: float = 0.3e-3, seed: int = 0) -> np.ndarray:
    """(n, 6) Tracker object pose: helical rotation vector (rad), origin (m) at a body point."""
    trans = truth.hub_world + truth.rot.apply(origin_body)
    return np.column_stack([truth.rot.as_rotvec(), noisy(trans, sigma, seed)])
