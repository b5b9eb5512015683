"""Truth models for `trials floquet`: wheels that wander about their gait, recorded as Vicon Tracker objects.

Written apart from the trial methods (it imports nothing from `rimless.analysis.inference` or `.kinematics`; the
Vicon CSV comes from its own writer, `rimless.analysis.validation.vicon_writer`). Each step's slope is drawn
N(slope, slope_sd^2) (the rough-slope model of Byl and Tedrake: gravity's direction per step), so the walk
wanders about its fixed point; the recorded geometry stays on the nominal slope (the importer sees one ramp).
The recording: a hold, the release, the walk, the data stop 40 % into the step after the last impact (at the
last impact when the ER wheel stalls on a shallow step);
100 Hz, sub-frame start drawn at random, Tracker-like noise on the object's origin (mm) and orientation (mrad),
the object origin off the hub.

- `rigid_walk`: a rigid rimless wheel (point mass M at the hub, inertia I_hub about it, legs L, 8 legs):
  the stance is a pendulum integrated here (RK4, 0.1 ms), the impact keeps the angular momentum about the new
  foot, omega+ = beta omega-, beta = (I_hub + M L^2 cos alpha) / (I_hub + M L^2). The map of the post-impact
  speed at a fixed slope is omega_{k+1}^2 = beta^2 (omega_k^2 + 4 (M g L / I_foot) sin(phi) sin(alpha/2)):
  its multiplier at the fixed point is exactly **beta^2** (`rigid_multiplier`), whatever the section angle.
- `er_walk`: the ER wheel of `rimless.sim` (its dynamics, per-step slope) with chosen parameters away from
  Table 1; its multiplier is the model's dominant eigenvalue (what the analysis puts beside the estimate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rimless.analysis.validation.vicon_writer import objects_section, write

ALPHA = math.pi / 4
G = 9.81


@dataclass
class Walk:
    """Samples of a walk in the slope frame (x down the slope, h along the normal, body angle from the release
    pose) and its truth."""

    t: np.ndarray
    x: np.ndarray
    h: np.ndarray
    body: np.ndarray
    impacts: np.ndarray
    post_impact_speed: np.ndarray  # true omega+ per impact, rad/s
    slope_deg: float
    stalled: bool = False  # the walk ended in a stall (the data stop at its last impact)
    #: the slope each step walked (deg; the ER walks': one per step taken, the one after the last impact too)
    step_slope_deg: np.ndarray | None = None


@dataclass(frozen=True)
class RigidWheel:
    mass_kg: float = 2.6
    inertia_hub_kg_m2: float = 0.05
    leg_m: float = 0.21

    @property
    def inertia_foot(self) -> float:
        return self.inertia_hub_kg_m2 + self.mass_kg * self.leg_m**2

    @property
    def beta(self) -> float:
        ml2 = self.mass_kg * self.leg_m**2
        return (self.inertia_hub_kg_m2 + ml2 * math.cos(ALPHA)) / self.inertia_foot

    def fixed_point(self, slope_deg: float) -> float:
        """Post-impact speed of the gait, rad/s: e = b^2 (e + c) -> e = b^2 c / (1 - b^2)."""
        b2 = self.beta**2
        c = (
            4
            * self.mass_kg
            * G
            * self.leg_m
            / self.inertia_foot
            * math.sin(math.radians(slope_deg))
            * math.sin(ALPHA / 2)
        )
        return math.sqrt(b2 * c / (1 - b2))


def rigid_multiplier(wheel: RigidWheel) -> float:
    return wheel.beta**2


def _pendulum(wheel: RigidWheel, omega: float, phi: float, dt: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Stance from -alpha/2 to alpha/2 (RK4, 0.1 ms): samples every dt (t, theta) and omega at the end."""
    kk = wheel.mass_kg * G * wheel.leg_m / wheel.inertia_foot
    h = 1e-4
    th, w, t = -ALPHA / 2, omega, 0.0
    ts, ths, nxt = [0.0], [th], dt

    def f(a: float) -> float:
        return kk * math.sin(a + phi)

    while th < ALPHA / 2:
        k1a, k1v = w, f(th)
        k2a, k2v = w + 0.5 * h * k1v, f(th + 0.5 * h * k1a)
        k3a, k3v = w + 0.5 * h * k2v, f(th + 0.5 * h * k2a)
        k4a, k4v = w + h * k3v, f(th + h * k3a)
        th_new = th + h * (k1a + 2 * k2a + 2 * k3a + k4a) / 6
        w_new = w + h * (k1v + 2 * k2v + 2 * k3v + k4v) / 6
        if w_new <= 0:
            raise RuntimeError("stalled")
        if th_new >= ALPHA / 2:  # end of stance inside this step: linear in theta
            frac = (ALPHA / 2 - th) / (th_new - th)
            t += frac * h
            w = w + frac * (w_new - w)
            th = ALPHA / 2
            break
        th, w, t = th_new, w_new, t + h
        if t >= nxt:
            ts.append(t)
            ths.append(th)
            nxt += dt
    ts.append(t)
    ths.append(th)
    return np.array(ts), np.array(ths), w


def rigid_walk(
    wheel: RigidWheel,
    slope_deg: float,
    slope_sd_deg: float,
    steps: int,
    rng: np.random.Generator,
    *,
    start: float | None = None,
) -> Walk:
    """``steps`` impacts of the rigid wheel released at its gait's speed (or ``start``, rad/s) at theta = -alpha/2."""
    dt = 1e-3
    omega = wheel.fixed_point(slope_deg) if start is None else start
    t0, foot = 0.0, 0.0
    chord = 2 * wheel.leg_m * math.sin(ALPHA / 2)
    T, X, H, B, impacts, speeds = [], [], [], [], [], []
    for k in range(steps + 1):
        phi = math.radians(slope_deg + slope_sd_deg * float(rng.standard_normal()))
        ts, ths, w_end = _pendulum(wheel, omega, phi, dt)
        T.append(t0 + ts)
        X.append(foot + wheel.leg_m * np.sin(ths))
        H.append(wheel.leg_m * np.cos(ths))
        B.append(ths + ALPHA / 2 + k * ALPHA)
        t0 += ts[-1]
        foot += chord
        omega = wheel.beta * w_end
        if k < steps:
            impacts.append(t0)
            speeds.append(omega)
    return _walk(T, X, H, B, impacts, speeds, slope_deg)


def er_walk(
    params, slope_deg: float, slope_sd_deg: float, steps: int, rng: np.random.Generator, *, release: float = 1.0
) -> Walk:
    """``steps`` impacts of the simulator's ER wheel (``params``: WheelParams) released from its gait at
    ``slope_deg`` with theta'+ times ``release`` (a hand release is never exactly at the gait)."""
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section
    from rimless.sim.step.backend import make_integrator, make_map
    from rimless.sim.step.hybrid import simulate_step
    from rimless.sim.step.poincare import default_guess, solve_fixed_point

    p0 = params.replace(slope_rad=math.radians(slope_deg))
    z = solve_fixed_point(make_map(p0, "er", rtol=1e-9), default_guess(p0, "er"), record=False).z
    integ = make_integrator("auto", rtol=1e-9)
    y = state_from_section(Mechanics.of(p0), np.asarray(z, float) * np.array([1.0, release]))
    dt = 1e-3
    t0 = 0.0
    T: list[np.ndarray] = []
    X: list[np.ndarray] = []
    H: list[np.ndarray] = []
    B: list[np.ndarray] = []
    impacts: list[float] = []
    speeds: list[float] = []
    slopes: list[float] = []
    for k in range(steps + 1):
        slope_k = slope_deg + slope_sd_deg * float(rng.standard_normal())
        p = params.replace(slope_rad=math.radians(slope_k))
        try:
            res = simulate_step(Mechanics.of(p), "er", y, integ, t0=0.0, record_dt=dt)
        except StepFailure:  # a stall (a slope drawn too shallow): the data stop at the last impact
            if len(impacts) < 2:
                raise
            return _walk(T, X, H, B, impacts, speeds, slope_deg, stalled=True, step_slopes=slopes)
        slopes.append(slope_k)
        for seg in res.segments or []:  # recorded: record_dt was given
            q = seg.y
            T.append(t0 + seg.t)
            X.append(q[:, 0] + q[:, 3] * np.sin(q[:, 2]))
            H.append(q[:, 1] + q[:, 3] * np.cos(q[:, 2]))
            B.append(q[:, 2] + ALPHA / 2 + k * ALPHA)
        t0 += res.period_s
        y = res.y_plus
        if k < steps:
            impacts.append(t0)
            speeds.append(float(y[7]))
    return _walk(T, X, H, B, impacts, speeds, slope_deg, step_slopes=slopes)


def assemble_walk(T, X, H, B, impacts, speeds, slope_deg, *, stalled: bool = False, step_slopes=None) -> Walk:
    """A `Walk` from per-step pieces (times s, hub x and h m, body angle rad), the impacts (s) and the post-impact
    speeds (rad/s): sorted, duplicates dropped, the data stopped 40 % into the step after the last impact (what
    `er_walk` and `rimless.analysis.validation.er_truth.er_truth_walk` record); ``step_slopes``: each step's
    slope, deg."""
    return _walk(T, X, H, B, impacts, speeds, slope_deg, stalled=stalled, step_slopes=step_slopes)


def _walk(T, X, H, B, impacts, speeds, slope_deg, *, stalled: bool = False, step_slopes=None) -> Walk:
    t = np.concatenate(T)
    order = np.argsort(t, kind="stable")
    t = t[order]
    keep = np.concatenate([[True], np.diff(t) > 1e-9])
    x, h, b = (np.concatenate(v)[order][keep] for v in (X, H, B))
    t = t[keep]
    last = impacts[-1]
    period = last - (impacts[-2] if len(impacts) > 1 else 0.0)
    stop = t <= last + 0.4 * period  # the data stop 40 % into the next step
    slopes = None if step_slopes is None else np.array(step_slopes, float)
    return Walk(t[stop], x[stop], h[stop], b[stop], np.array(impacts), np.array(speeds), slope_deg, stalled, slopes)


def slope_to_lab(
    x_m: np.ndarray, h_m: np.ndarray, body_rad: np.ndarray, slope_deg: float, heading_deg: float
) -> tuple[np.ndarray, Rotation]:
    """The hub (n, 3), m, and the body's rotation in a Z-up lab from slope-frame samples: x down the slope, h
    along its normal, the body angle; the ramp heads ``heading_deg`` off the lab's X axis."""
    phi, yaw = math.radians(slope_deg), math.radians(heading_deg)
    trv = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(phi) * trv - math.sin(phi) * up
    nrm = math.sin(phi) * trv + math.cos(phi) * up
    w = np.cross(d, nrm)
    hub = np.array([0.3, -0.5, 0.25]) + np.outer(x_m, d) + np.outer(h_m, nrm)
    rot = Rotation.from_rotvec(np.outer(-body_rad, w)) * Rotation.from_matrix(np.column_stack([d, nrm, w]))
    return hub, rot


def record(
    walk: Walk,
    path,
    rng: np.random.Generator,
    *,
    hold_s: float = 0.4,
    rate_hz: float = 100.0,
    noise_m: float = 0.3e-3,
    angle_noise_rad: float = 1e-3,
    origin_body_m=(0.03, -0.02, 0.01),
    yaw_deg: float = 25.0,
) -> str:
    """Write the walk as a Vicon Tracker export (object ``Wheel``): a hold at the release pose, then the walk."""
    t = np.concatenate([np.arange(0.0, hold_s, 1e-3), hold_s + walk.t])
    x = np.concatenate([np.full(t.size - walk.t.size, walk.x[0]), walk.x])
    h = np.concatenate([np.full(t.size - walk.t.size, walk.h[0]), walk.h])
    b = np.concatenate([np.full(t.size - walk.t.size, walk.body[0]), walk.body])
    tf = np.arange(0.0, t[-1], 1.0 / rate_hz) + float(rng.uniform(0, 1.0 / rate_hz))
    tf = tf[tf <= t[-1]]
    xs, hs, bs = (np.interp(tf, t, v) for v in (x, h, b))
    hub, rot = slope_to_lab(xs, hs, bs, walk.slope_deg, yaw_deg)
    trans = hub + rot.apply(np.asarray(origin_body_m, float))
    noisy = Rotation.from_rotvec(rng.normal(0, angle_noise_rad, (tf.size, 3))) * rot
    pose = np.column_stack([noisy.as_rotvec(), trans + rng.normal(0, noise_m, trans.shape)])
    return write(path, objects_section({"Wheel": pose}))


def main() -> None:
    """``python -m rimless.analysis.validation.floquet_truth --out DIR``: three SYNTHETIC ER trials that wander about their gait
    (k = 2000 N/m, c = 14 N s/m, 2.5 deg, per-step slope sd 0.6 deg, 15 impacts) and DIR/wheel.toml with k and c."""
    import argparse
    from pathlib import Path

    from rimless.sim.model.params import WheelParams

    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=5)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(a.seed)
    params = WheelParams(stiffness_n_per_m=2000.0, damping_ns_per_m=14.0)
    for i, rel in enumerate((0.95, 1.03, 1.08)):
        walk = er_walk(params, 2.5, 0.6, 15, rng, release=rel)
        print(f"wrote {record(walk, a.out / f'SYNTHETIC_er_wander_{i}.csv', rng)}")
    toml = a.out / "wheel.toml"
    toml.write_text("[wheel]\nk = {value = 2000, sd = 100}\nc = {value = 14, sd = 2}\n")
    print(f"wrote {toml}")


if __name__ == "__main__":
    main()
