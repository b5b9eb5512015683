"""Independent truth model for the per-trial slope, hub and ending: a compliant ER wheel (not Table 1) recorded
as a Vicon Tracker object, the messy way.

The dynamics come from the simulator (`rimless.sim`, ER model with other c and k); everything the analysis
estimates is written here apart from ``rimless.analysis`` (it imports nothing from it): the slope frame, the
world embedding, the object origin off the hub (up to 4 cm, plus an axial offset), the hold before the release
(standing on its legs: `release_angle`), the stall (a rigid stance that rises, turns back and rests), the
endings (caught with a little sideways motion, fell = tipped about the travel axis, walked = the data stop
mid-step), noise and gaps.

Slope frame (model.md section 2): x down the slope, y the outward normal, z = x cross y; stance foot b at
(x_b, y_b); hub = foot + L1 (sin theta, cos theta); the body turns by -beta about z with beta = theta + k alpha.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from tests.support.analysis_truth_wheel import objects_section, write

ALPHA = math.pi / 4
#: Leg damping and stiffness of the truth wheel (Table 1: 8 N s/m, 2700 N/m).
C_NS_PER_M = 14.0
K_N_PER_M = 2000.0
#: How the wheel stands before its release: ``static`` (standing on its legs: the trailing leg carries the weight,
#: compressed by M g cos(slope) / k, the leading one touches; `release_angle`) or ``uncompressed`` (both legs at
#: L0, the hub held 5-9 mm above where any step of the gait puts it: the truth until session 18; the first
#: stance then drops the hub onto its legs and its impact lands up to 0.6 mm deeper than the later impacts'
#: trend, which the importer's impact line read as slope: tests/analysis/kinematics/test_trial_truth_release.py).
RELEASE_LEG = "static"


@dataclass
class ErTruth:
    name: str
    slope_deg: float
    time_s: np.ndarray
    pose: np.ndarray  # (n, 6) helical rad + origin m (NaN rows = gaps)
    hub_world: np.ndarray
    impact_time_s: np.ndarray
    steps: int
    stalled: bool
    outcome: str
    origin_body_m: np.ndarray
    feet_world: list = field(default_factory=list)
    rot: Rotation | None = None  # world-from-body, noise-free


def _params(slope_deg: float):
    from rimless.sim.model.params import WheelParams

    return WheelParams(damping_ns_per_m=C_NS_PER_M, stiffness_n_per_m=K_N_PER_M, slope_rad=math.radians(slope_deg))


def release_angle(p, release_leg: str = "static") -> float:
    """The stance angle theta (rad) of the pose the wheel is held in (both feet on the slope; model.md section 6:
    L1 = L0, L2 from foot a on the slope): -alpha/2 with both legs uncompressed, or (``static``) the angle at
    which the trailing leg is compressed by the wheel's weight, L2 = L0 - M g cos(slope) / k (M = hub + 8 legs)."""
    from scipy.optimize import brentq

    from rimless.sim.model.section import trailing_length

    if release_leg == "uncompressed":
        return -ALPHA / 2
    if release_leg != "static":
        raise ValueError(f"release_leg must be 'static' or 'uncompressed', got {release_leg!r}")
    L0 = p.leg_length_m
    squeeze = (p.hub_mass_kg + 8 * p.leg_mass_kg) * p.gravity_m_s2 * math.cos(p.slope_rad) / p.stiffness_n_per_m
    return float(brentq(lambda th: trailing_length(th, L0) - (L0 - squeeze), -ALPHA / 2 - 0.5, -ALPHA / 2))


def _rigid_stance(p, y_plus: np.ndarray, dt: float, *, t_max: float, stop_at_top: bool = False):
    """A rigid stance on foot b from the post-impact state (RK4, 0.1 ms): (t, theta) sampled every dt, and
    whether it turned back; it rises, and if it turns back, rolls back to its start angle and rests."""
    m_all = p.hub_mass_kg + 8 * p.leg_mass_kg
    ell = float(y_plus[3])
    inertia = p.inertia_kg_m2 + 8 * p.leg_mass_kg * p.leg_length_m**2 + m_all * ell**2
    kk = m_all * p.gravity_m_s2 * ell / inertia
    phi = p.slope_rad
    th0 = th = float(y_plus[2])
    w = float(y_plus[7])
    h = 1e-4

    def f(a: float) -> float:
        return kk * math.sin(a + phi)

    ts, ths, t, back, nxt = [0.0], [th], 0.0, False, dt
    while t < t_max:
        k1v, k1a = f(th), w
        k2v, k2a = f(th + 0.5 * h * k1a), w + 0.5 * h * k1v
        k3v, k3a = f(th + 0.5 * h * k2a), w + 0.5 * h * k2v
        k4v, k4a = f(th + h * k3a), w + h * k3v
        th += h * (k1a + 2 * k2a + 2 * k3a + k4a) / 6
        w += h * (k1v + 2 * k2v + 2 * k3v + k4v) / 6
        t += h
        if w < 0:
            back = True
            if stop_at_top:
                break
        if back and th <= th0:
            th = th0
            break
        if t >= nxt:
            ts.append(t)
            ths.append(th)
            nxt += dt
    return np.array(ts), np.array(ths), back, ell


def simulate(
    slope_deg: float,
    release_rad_s: float,
    *,
    max_steps: int = 8,
    ending: str = "caught",
    hold_s: float = 0.4,
    rate_hz: float = 100.0,
    origin_body_m=(0.03, -0.025, 0.012),
    yaw_deg: float = 20.0,
    noise_m: float = 0.3e-3,
    angle_noise_rad: float = 1e-3,
    gaps: tuple[tuple[float, float], ...] = (),
    seed: int = 0,
    name: str = "er",
    release_leg: str | None = None,
) -> ErTruth:
    """Hold (standing on its legs, `release_angle`; ``release_leg`` None: `RELEASE_LEG`), release with theta' =
    release, walk up to ``max_steps`` (a stall ends the walk with a rock back and a rest), then ``ending``:
    ``caught`` (lifted 8 cm with 15 mm of sideways motion), ``walked`` (the data stop 40 % into the next step),
    ``fell`` (tips 60 deg about the travel axis)."""
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.hybrid import simulate_step

    p = _params(slope_deg)
    mech = Mechanics.of(p)
    integ = make_integrator("auto", rtol=1e-9)
    th_rel = release_angle(p, RELEASE_LEG if release_leg is None else release_leg)
    y = state_from_section(mech, np.array([th_rel, release_rad_s]))
    dt = 1e-3
    t_list, x_list, h_list, b_list = [np.arange(0.0, hold_s, dt)], [], [], []
    x_list.append(np.full(t_list[0].size, p.leg_length_m * math.sin(th_rel)))
    h_list.append(np.full(t_list[0].size, p.leg_length_m * math.cos(th_rel)))
    b_list.append(np.full(t_list[0].size, th_rel))
    t0, impacts, stalled, k = hold_s, [], False, 0
    feet = [np.array([0.0, 0.0])]
    for k in range(max_steps):
        try:
            res = simulate_step(mech, "er", y, integ, t0=0.0, record_dt=dt)
        except StepFailure:
            stalled = True
            break
        for seg in res.segments:
            q = seg.y
            t_list.append(t0 + seg.t)
            x_list.append(q[:, 0] + q[:, 3] * np.sin(q[:, 2]))
            h_list.append(q[:, 1] + q[:, 3] * np.cos(q[:, 2]))
            b_list.append(q[:, 2] + k * ALPHA)
        t0 += res.period_s
        impacts.append(t0)
        y = res.y_plus
        feet.append(np.array([y[0], y[1]]))
    n_steps = len(impacts) if not stalled else k
    beta_off = n_steps * ALPHA

    def stance(ts, ths, ell):
        return (t0 + ts, y[0] + ell * np.sin(ths), y[1] + ell * np.cos(ths), ths + beta_off)

    outcome = ending
    lift = None
    if stalled:
        ts, ths, back, ell = _rigid_stance(p, y, dt, t_max=3.0)
        tt, xx, hh, bb = stance(ts, ths, ell)
        rest = np.arange(tt[-1] + dt, tt[-1] + 0.8, dt)
        t_list += [tt, rest]
        x_list += [xx, np.full(rest.size, xx[-1])]
        h_list += [hh, np.full(rest.size, hh[-1])]
        b_list += [bb, np.full(rest.size, bb[-1])]
        outcome = "stalled"
    else:
        period = impacts[-1] - (impacts[-2] if len(impacts) > 1 else hold_s)
        frac = 0.4 if ending == "walked" else 0.3
        ts, ths, back, ell = _rigid_stance(p, y, dt, t_max=frac * period, stop_at_top=True)
        tt, xx, hh, bb = stance(ts, ths, ell)
        t_list.append(tt)
        x_list.append(xx)
        h_list.append(hh)
        b_list.append(bb)
        if ending in ("caught", "fell"):
            after = np.arange(tt[-1] + dt, tt[-1] + 0.6, dt)
            s = np.clip((after - after[0]) / 0.3, 0, 1)
            lift = (after, s)
            t_list.append(after)
            x_list.append(np.full(after.size, xx[-1]))
            h_list.append(np.full(after.size, hh[-1]))
            b_list.append(np.full(after.size, bb[-1]))
    t = np.concatenate(t_list)
    order = np.argsort(t, kind="stable")
    t = t[order]
    keep = np.concatenate([[True], np.diff(t) > 1e-12])
    t = t[keep]
    x, hgt, beta = (np.concatenate(v)[order][keep] for v in (x_list, h_list, b_list))
    beta = beta - th_rel  # 0 at the release pose

    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, t[-1], 1.0 / rate_hz) + float(rng.uniform(0, 1.0 / rate_hz))
    tf = tf[tf <= t[-1]]
    xs, hs, bs = (np.interp(tf, t, v) for v in (x, hgt, beta))
    phi = math.radians(slope_deg)
    yaw = math.radians(yaw_deg)
    trv = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(phi) * trv - math.sin(phi) * up
    nrm = math.sin(phi) * trv + math.cos(phi) * up
    w = np.cross(d, nrm)
    org = np.array([0.4, -0.6, 0.3])
    hub = org + np.outer(xs, d) + np.outer(hs, nrm)
    base = Rotation.from_matrix(np.column_stack([d, nrm, w]))
    rot = Rotation.from_rotvec(np.outer(-bs, w)) * base
    if lift is not None:
        after, s = lift
        sf = np.interp(tf, after, s, left=0.0, right=1.0)
        if outcome == "caught":
            hub = hub + np.outer(0.08 * sf, up) + np.outer(0.015 * sf, w)
        else:  # fell: tips about the travel axis through the foot
            foot = org + y[0] * d + y[1] * nrm
            tip = Rotation.from_rotvec(np.outer(math.radians(60) * sf, d))
            hub = foot + tip.apply(hub - foot)
            rot = tip * rot
    o = np.asarray(origin_body_m, float)
    trans = hub + rot.apply(o)
    noisy_rot = Rotation.from_rotvec(rng.normal(0, angle_noise_rad, (tf.size, 3))) * rot
    pose = np.column_stack([noisy_rot.as_rotvec(), trans + rng.normal(0, noise_m, trans.shape)])
    for a, b in gaps:
        pose[(tf >= a) & (tf < b)] = np.nan
    feet_w = [org + f[0] * d + f[1] * nrm for f in feet]
    return ErTruth(name, slope_deg, tf, pose, hub, np.array(impacts), n_steps, stalled, outcome, o, feet_w, rot)


def write_csv(path, truth: ErTruth) -> str:
    """The trial as a Vicon Tracker export (object ``Wheel``, rad and mm)."""
    return write(path, objects_section({"Wheel": truth.pose}))


def write_markers_csv(path, truth: ErTruth, body_m: np.ndarray, *, noise_m: float = 0.3e-3, seed: int = 0) -> str:
    """The trial as a Trajectories section of markers ``wheel:M0..`` at body points ``body_m`` (k, 3) m (body
    frame: x, y in the wheel plane about the hub, z along the axis), with noise; gaps of the pose are gaps."""
    from tests.support.analysis_truth_wheel import markers_section

    rng = np.random.default_rng(seed)
    pts = truth.hub_world[:, None, :] + np.einsum("nij,kj->nki", truth.rot.as_matrix(), np.asarray(body_m))
    pts = pts + rng.normal(0, noise_m, pts.shape)
    pts[np.isnan(truth.pose).any(axis=1)] = np.nan
    return write(path, markers_section({f"wheel:M{i}": pts[:, i] for i in range(pts.shape[1])}))


#: A Y-up lab (X right, Y up, Z toward the viewer) from the model's Z-up frame: (x, y, z) -> (x, z, -y).
Y_UP_FROM_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def in_lab(truth: ErTruth, lab_from_model: np.ndarray) -> ErTruth:
    """The same trial recorded in another lab frame: positions ``M p`` and orientations ``M R`` (M a proper
    rotation, e.g. `Y_UP_FROM_Z_UP`); the gaps stay gaps. The truth's slope and impacts do not change."""
    from dataclasses import replace

    m = np.asarray(lab_from_model, float)
    rm = Rotation.from_matrix(m)
    pose = truth.pose.copy()
    ok = ~np.isnan(pose).any(axis=1)
    pose[ok, :3] = (rm * Rotation.from_rotvec(pose[ok, :3])).as_rotvec()
    pose[ok, 3:] = pose[ok, 3:] @ m.T
    return replace(
        truth,
        pose=pose,
        hub_world=truth.hub_world @ m.T,
        feet_world=[m @ f for f in truth.feet_world],
        rot=None if truth.rot is None else rm * truth.rot,
    )


def _embed(
    name: str,
    slope_deg: float,
    t: np.ndarray,
    x: np.ndarray,
    hgt: np.ndarray,
    beta: np.ndarray,
    impacts: np.ndarray,
    *,
    rate_hz: float,
    origin_body_m,
    yaw_deg: float,
    noise_m: float,
    angle_noise_rad: float,
    seed: int,
    steps: int,
    stalled: bool,
    outcome: str,
) -> ErTruth:
    """Sample a slope-frame motion (hub x, height, body turn beta since the release; fine time grid ``t``) at
    ``rate_hz`` with a random sub-frame offset and embed it in a Z-up world as `simulate` does."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, t[-1], 1.0 / rate_hz) + float(rng.uniform(0, 1.0 / rate_hz))
    tf = tf[tf <= t[-1]]
    xs, hs, bs = (np.interp(tf, t, v) for v in (x, hgt, beta))
    phi, yaw = math.radians(slope_deg), math.radians(yaw_deg)
    trv = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(phi) * trv - math.sin(phi) * up
    nrm = math.sin(phi) * trv + math.cos(phi) * up
    w = np.cross(d, nrm)
    org = np.array([-0.2, 0.5, 0.25])
    hub = org + np.outer(xs, d) + np.outer(hs, nrm)
    rot = Rotation.from_rotvec(np.outer(-bs, w)) * Rotation.from_matrix(np.column_stack([d, nrm, w]))
    o = np.asarray(origin_body_m, float)
    trans = hub + rot.apply(o)
    noisy_rot = Rotation.from_rotvec(rng.normal(0, angle_noise_rad, (tf.size, 3))) * rot
    pose = np.column_stack([noisy_rot.as_rotvec(), trans + rng.normal(0, noise_m, trans.shape)])
    return ErTruth(name, slope_deg, tf, pose, hub, np.asarray(impacts, float), steps, stalled, outcome, o, [], rot)


def rigid_walk(
    slope_deg: float,
    omega0_rad_s: float,
    *,
    truth=None,
    ramp_steps: int = 11,
    hold_s: float = 0.3,
    rate_hz: float = 100.0,
    origin_body_m=(0.02, -0.03, 0.01),
    yaw_deg: float = -25.0,
    noise_m: float = 0.3e-3,
    angle_noise_rad: float = 1e-3,
    seed: int = 0,
) -> ErTruth:
    """A rigid wheel (`tests.support.analysis_rigid_truth.RigidTruth`: a pendulum stance integrated by scipy,
    angular momentum kept about the new foot at impact) held for ``hold_s``, released at theta = -alpha/2 with
    ``omega0``, walking ``ramp_steps`` steps (or stalling), recorded as `simulate` records: the impact times are
    the truth's own (the touchdown events located by solve_ivp)."""
    from tests.support.analysis_rigid_truth import RigidTruth

    rt = RigidTruth() if truth is None else truth
    tt, xx, yy, ang, imp, stalled = rt.walk(slope_deg, omega0_rad_s, ramp_steps, dt=2e-4)
    hold = np.arange(0.0, hold_s, 2e-4)
    t = np.concatenate([hold, hold_s + tt])
    x = np.concatenate([np.full(hold.size, xx[0]), xx])
    h = np.concatenate([np.full(hold.size, yy[0]), yy])
    b = np.concatenate([np.zeros(hold.size), ang])
    outcome = "stalled" if stalled else "walked"
    return _embed(
        f"rigid_{slope_deg}deg",
        slope_deg,
        t,
        x,
        h,
        b,
        hold_s + imp,
        rate_hz=rate_hz,
        origin_body_m=origin_body_m,
        yaw_deg=yaw_deg,
        noise_m=noise_m,
        angle_noise_rad=angle_noise_rad,
        seed=seed,
        steps=len(imp),
        stalled=stalled,
        outcome=outcome,
    )


def simulate_wheel(slope_deg: float, release_rad_s: float, *, c_ns_per_m: float, k_n_per_m: float, **kw) -> ErTruth:
    """`simulate` with another leg damping and stiffness (the module's `C_NS_PER_M`, `K_N_PER_M` for the call)."""
    global C_NS_PER_M, K_N_PER_M
    old = C_NS_PER_M, K_N_PER_M
    C_NS_PER_M, K_N_PER_M = c_ns_per_m, k_n_per_m
    try:
        return simulate(slope_deg, release_rad_s, **kw)
    finally:
        C_NS_PER_M, K_N_PER_M = old


def mid_stance_gaps(truth: ErTruth, keep: tuple[int, ...], fraction: float, hold_s: float = 0.4) -> tuple:
    """Occlusions of the middle ``fraction`` of every stance but those numbered in ``keep`` (0 = the stance after
    the release): the impacts stay in view (the CoM minima), the stance feet only in the kept stances. Pass the
    result as ``gaps=`` to `simulate` with the same arguments."""
    imp = np.concatenate([[hold_s], truth.impact_time_s])
    f = fraction / 2
    return tuple(
        (a + (0.5 - f) * (b - a), a + (0.5 + f) * (b - a))
        for j, (a, b) in enumerate(zip(imp[:-1], imp[1:]))
        if j not in keep
    )


#: the walks the first-touchdown tests import (hold, slope deg, release rad/s, c N s/m, k N/m): both holds, wheels
#: away from Table 1 (tests/analysis/kinematics/test_steps_first_touchdown*.py)
FIRST_TOUCHDOWN_WALKS = [
    ("uncompressed", 2.2, 2.3, 9.0, 2200.0),
    ("uncompressed", 2.8, 2.0, 16.0, 3500.0),
    ("static", 1.8, 2.4, 5.0, 1800.0),
    ("static", 2.5, 2.6, 12.0, 3000.0),
]
