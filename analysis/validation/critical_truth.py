"""Truth model of the critical-slope coverage through the importer: a rigid rimless wheel with a loss per step,
walked on a ramp, recorded as a Vicon export in a drawn lab.

Written apart from the trial methods: it imports nothing from `rimless.analysis.inference` or `.kinematics` (the
wheel is `rimless.analysis.validation.floquet_truth.RigidWheel`, the CSV comes from `vicon_writer`).

- `LossyWheel`: the rigid wheel (point mass M at the hub, inertia I_hub about it, eight massless legs of length L,
  alpha = 45 deg between them) plus a constant energy loss per step E = F_c * `GUIDE_TRAVEL_M` standing for
  Coulomb friction F_c in the leg guides (the guide's travel per step is an assumption: 2 x 10 mm, compression
  and release). At each impact the angular momentum about the new foot is kept (omega+ = beta omega-), then
  I_foot omega+^2 / 2 loses E; nothing else dissipates.
- Its map of the post-impact squared speed w (rad^2/s^2): w' = beta^2 (w + 4 K sin(phi) sin(alpha/2)) - 2 E / I_foot,
  K = M g L / I_foot. The true critical slope is where the map's fixed point just passes over the top of the
  stance (bisection on that map, `critical_slope_deg`); with E = 0 it is Coleman's closed form.
- `walk`: the stance pendulum theta'' = K sin(theta + phi) integrated by scipy (DOP853, rtol 1e-10) with events
  at the end of the stance and on the way back: a stall swings back to theta = -alpha/2 and rests on two feet.
- `record`: a hold at the release pose, the walk, then 40 % of the step after the last impact (a walk) or a rest
  of 1.5 s (a stall); in a `Lab`: Z-up or Y-up, any ramp heading, a Tracker object (origin off the hub) or four
  markers ``Wheel:M0..M3`` on the wheel's face; 0.3 mm and 1 mrad of noise, a random sub-frame start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from rimless.analysis.validation.floquet_truth import RigidWheel, Walk, slope_to_lab
from rimless.analysis.validation.vicon_writer import markers_section, objects_section, write

__all__ = [
    "ALPHA",
    "G",
    "GUIDE_TRAVEL_M",
    "LossyWheel",
    "Lab",
    "MARKERS_BODY_M",
    "Y_UP_FROM_Z_UP",
    "walk",
    "record",
]

ALPHA = math.pi / 4
G = 9.81
#: the leg's travel in its guide per step (compression and release, 2 x 10 mm): E = F_c * this, J (assumed)
GUIDE_TRAVEL_M = 0.02
#: four markers on the wheel's face (body frame: x, y in the wheel plane about the hub, z along the axis), m;
#: unevenly placed (their centroid is 14 mm off the hub)
MARKERS_BODY_M = np.array([[0.110, 0.000, 0.03], [0.000, 0.095, 0.03], [-0.080, 0.010, 0.03], [0.026, -0.105, 0.03]])
#: a Y-up lab (X right, Y up, Z toward the viewer) from the Z-up frame: (x, y, z) -> (x, z, -y)
Y_UP_FROM_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class LossyWheel(RigidWheel):
    """The rigid truth wheel with guide friction ``friction_n`` (N) standing as a constant loss per step."""

    friction_n: float = 0.0

    @property
    def inertia_ratio(self) -> float:
        """I_hub / (M L^2)."""
        return self.inertia_hub_kg_m2 / (self.mass_kg * self.leg_m**2)

    @property
    def loss_j(self) -> float:
        """Energy lost per step, J."""
        return self.friction_n * GUIDE_TRAVEL_M

    @property
    def k(self) -> float:
        """K = M g L / I_foot, 1/s^2."""
        return self.mass_kg * G * self.leg_m / self.inertia_foot

    def top_threshold(self, phi: float) -> float:
        """The least squared speed (rad^2/s^2) at theta = -alpha/2 that carries the stance over its top."""
        return 2 * self.k * (1.0 - math.cos(phi - ALPHA / 2))

    def next_w(self, w: float, phi: float) -> float:
        """The map: squared post-impact speed after a stance started with squared speed ``w``."""
        gain = 4 * self.k * math.sin(phi) * math.sin(ALPHA / 2)
        return self.beta**2 * (w + gain) - 2 * self.loss_j / self.inertia_foot

    def fixed_point_w(self, phi: float) -> float:
        b2 = self.beta**2
        gain = 4 * self.k * math.sin(phi) * math.sin(ALPHA / 2)
        return (b2 * gain - 2 * self.loss_j / self.inertia_foot) / (1 - b2)

    def critical_slope_deg(self) -> float:
        """The slope (deg) above which the map's fixed point passes over the top of the stance (bisection)."""
        lo, hi = 1e-9, ALPHA / 2 - 1e-9
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if self.fixed_point_w(mid) - self.top_threshold(mid) < 0:
                lo = mid
            else:
                hi = mid
        return math.degrees(0.5 * (lo + hi))

    def wheel_params(self):  # -> rimless.sim.model.params.WheelParams
        """The `WheelParams` a user would write for this wheel (tiny legs: M = m_H + 8 m, I_hub = I_c + 8 m L^2; k and
        c Table 1's). The compliant models do not reach this rigid wheel as m -> 0 (model.md section 9: the free legs
        slide during the impulse and the springs give the energy back): at 4 deg the ER impact keeps T+/T- = 0.845 of
        the kinetic energy (0.889 at k = 1e5 N/m) where this wheel keeps beta^2 = 0.634, so the simulated ER wheel
        speeds up where the truth does not, and an ER comparison of its trials is `suspect` by design (CoM
        correlation r = 0.25 at 4 deg, F_c = 2 N, released at 3 rad/s: the periods 0.334-0.475 s measured,
        0.334-0.245 s simulated). The 0.1 g legs are stiff for the explicit integrator; the simulator integrates
        their single support implicitly (rimless.sim.fast.stiff)."""
        from rimless.sim.model.params import WheelParams

        m = 1e-4
        return WheelParams(
            hub_mass_kg=self.mass_kg - 8 * m,
            leg_mass_kg=m,
            inertia_kg_m2=self.inertia_hub_kg_m2 - 8 * m * self.leg_m**2,
            leg_length_m=self.leg_m,
        )


def _stance(wheel: LossyWheel, omega: float, phi: float) -> tuple[object, float, bool]:
    """One stance from theta = -alpha/2 with speed ``omega``: (solution, end time, whether it passed the top)."""
    kk = wheel.k

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        return [y[1], kk * math.sin(y[0] + phi)]

    def over(_t: float, y: np.ndarray) -> float:
        return y[0] - ALPHA / 2

    def back(_t: float, y: np.ndarray) -> float:
        return y[0] + ALPHA / 2 + 1e-9

    over.terminal, over.direction = True, 1  # type: ignore[attr-defined]
    back.terminal, back.direction = True, -1  # type: ignore[attr-defined]
    sol = solve_ivp(
        rhs, (0.0, 30.0), [-ALPHA / 2, omega], method="DOP853", rtol=1e-10, atol=1e-12, events=(over, back),
        dense_output=True,
    )  # fmt: skip
    if sol.t_events[0].size:
        return sol, float(sol.t_events[0][0]), True
    if sol.t_events[1].size:
        return sol, float(sol.t_events[1][0]), False
    raise RuntimeError(f"stance did not end in 30 s (omega {omega:.4g} rad/s, slope {math.degrees(phi):.3f} deg)")


def walk(wheel: LossyWheel, slope_deg: float, release_rad_s: float, ramp_steps: int, *, dt: float = 1e-3) -> Walk:
    """The wheel released at theta = -alpha/2 with ``release_rad_s``, up to ``ramp_steps`` impacts on the ramp
    (slope frame: x down the slope, h along the normal, body angle since the release). A walk's samples run 40 %
    into the step after its last impact; a stall's end where it rests on two feet (``stalled``)."""
    phi = math.radians(slope_deg)
    chord = 2 * wheel.leg_m * math.sin(ALPHA / 2)
    omega, t0, foot = float(release_rad_s), 0.0, 0.0
    T, X, H, B, impacts, speeds = [], [], [], [], [], []
    stalled = False
    for k in range(ramp_steps + 1):
        sol, te, passed = _stance(wheel, omega, phi)
        last_step = k == ramp_steps and passed
        t_end = 0.4 * te if last_step else te
        ts = np.append(np.arange(0.0, t_end, dt), t_end)
        th = sol.sol(ts)[0]  # type: ignore[attr-defined]
        T.append(t0 + ts)
        X.append(foot + wheel.leg_m * np.sin(th))
        H.append(wheel.leg_m * np.cos(th))
        B.append(th + ALPHA / 2 + k * ALPHA)
        if not passed:
            stalled = True
            break
        if last_step:
            break
        t0 += te
        foot += chord
        w_plus = wheel.beta**2 * float(sol.y_events[0][0][1]) ** 2 - 2 * wheel.loss_j / wheel.inertia_foot  # type: ignore[attr-defined]
        impacts.append(t0)
        if w_plus <= 0:  # the loss took the whole speed: it rests on its two feet at this impact
            speeds.append(0.0)
            stalled = True
            break
        omega = math.sqrt(w_plus)
        speeds.append(omega)
    t = np.concatenate(T)
    keep = np.concatenate([[True], np.diff(t) > 1e-9])
    x, h, b = (np.concatenate(v)[keep] for v in (X, H, B))
    return Walk(t[keep], x, h, b, np.array(impacts), np.array(speeds), slope_deg, stalled)


@dataclass(frozen=True)
class Lab:
    """How a trial is recorded: the lab's vertical (``"z"`` or ``"y"``), the ramp's heading in the horizontal
    plane (deg), a Tracker object or four markers, the rate and the noise."""

    up: str = "z"
    heading_deg: float = 25.0
    markers: bool = False
    rate_hz: float = 100.0
    noise_m: float = 0.3e-3
    angle_noise_rad: float = 1e-3

    def describe(self) -> str:
        return f"{self.up.upper()}-up, heading {self.heading_deg:.0f} deg, {'4 markers' if self.markers else 'object'}"


def recorded_frames(
    wk: Walk, rate_hz: float, offset_s: float, hold_s: float = 0.4, rest_s: float = 1.5
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The frames a recording of ``wk`` holds: their times (s from the hold's start; a hold of ``hold_s`` at the
    release pose, the walk, a rest of ``rest_s`` after a stall; frames every 1 / ``rate_hz`` from ``offset_s``)
    and the walk's x and h (m, slope frame) and body angle (rad) at them."""
    t = np.concatenate([np.arange(0.0, hold_s, 1e-3), hold_s + wk.t])
    n_hold = t.size - wk.t.size
    x, h, b = (np.concatenate([np.full(n_hold, v[0]), v]) for v in (wk.x, wk.h, wk.body))
    if wk.stalled:
        tail = t[-1] + np.arange(1e-3, rest_s, 1e-3)
        t = np.concatenate([t, tail])
        x, h, b = (np.concatenate([v, np.full(tail.size, v[-1])]) for v in (x, h, b))
    tf = np.arange(0.0, t[-1], 1.0 / rate_hz) + offset_s
    tf = tf[tf <= t[-1]]
    xs, hs, bs = (np.interp(tf, t, v) for v in (x, h, b))
    return tf, xs, hs, bs


def record(
    wk: Walk,
    path: str | Path,
    rng: np.random.Generator,
    lab: Lab,
    *,
    hold_s: float = 0.4,
    rest_s: float = 1.5,
    origin_body_m: tuple[float, float, float] = (0.03, -0.02, 0.01),
) -> str:
    """Write the walk as a Vicon export in ``lab``: a hold at the release pose, the walk, a rest after a stall."""
    tf, xs, hs, bs = recorded_frames(wk, lab.rate_hz, float(rng.uniform(0, 1.0 / lab.rate_hz)), hold_s, rest_s)
    hub, rot = slope_to_lab(xs, hs, bs, wk.slope_deg, lab.heading_deg)
    if lab.up == "y":
        m = Rotation.from_matrix(Y_UP_FROM_Z_UP)
        hub, rot = m.apply(hub), m * rot
    elif lab.up != "z":
        raise ValueError(f"lab.up must be 'z' or 'y', got {lab.up!r}")
    if lab.markers:
        mats = rot.as_matrix()
        pts = hub[:, None, :] + np.einsum("nij,kj->nki", mats, MARKERS_BODY_M)
        pts = pts + rng.normal(0.0, lab.noise_m, pts.shape)
        section = markers_section({f"Wheel:M{i}": pts[:, i] for i in range(pts.shape[1])}, rate=f"{lab.rate_hz:g}")
        return write(path, section)
    trans = hub + rot.apply(np.asarray(origin_body_m, float))
    noisy = Rotation.from_rotvec(rng.normal(0, lab.angle_noise_rad, (tf.size, 3))) * rot
    pose = np.column_stack([noisy.as_rotvec(), trans + rng.normal(0, lab.noise_m, trans.shape)])
    return write(path, objects_section({"Wheel": pose}, rate=f"{lab.rate_hz:g}"))
