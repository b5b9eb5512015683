"""The bundled SYNTHETIC slope series around the critical slope (``data/critical/SYNTHETIC_crit_*.csv``).

``python -m rimless.analysis.examples.critical_series [OUT_DIR]`` regenerates them from a fixed seed.

Truth model (deliberately not the simulator's Table 1 model, so that the demo is not circular): the ER wheel
of `rimless.sim` with the leg damping c = `TRUTH_DAMPING_NS_PER_M` instead of 8 N s/m, plus a loss by a
constant force `GUIDE_FRICTION_N` against the wheel's travel along its whole path (named guide friction in the
code and the truth file's key, but not the simulator's F_c, which acts only over the legs' compression): it
removes F * (step length) of kinetic energy at every step (the post-impact velocities are scaled down
accordingly). A trial is released at the
rigid-touchdown state theta = -alpha/2 with a chosen theta' and walks a ramp of `RAMP_STEPS` steps; the
recording stops half a step after the last impact on the ramp (the wheel is caught), or, when the wheel stalls,
the stalled step is a rigid stance that rolls back to rest on two feet and stays there.

The truth's critical slope (the smallest slope where walking from a brisk release is sustained for
`SUSTAIN_STEPS` steps, to 0.001 deg) is written with everything else to ``SYNTHETIC_crit_truth.toml``.
Frames at 100 Hz as a Vicon Tracker object ``Wheel`` (helical angles in rad, translation in mm), 0.3 mm and
1 mrad noise, the object's origin 3-5 cm off the hub in the wheel plane.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rimless.analysis.io.trial import ALPHA_RAD

__all__ = ["SERIES", "TRUTH_FILE", "generate", "data_files", "truth_step", "truth_walk", "truth_critical_slope_deg"]

DATA_DIR = Path(__file__).resolve().parents[1] / "data" / "critical"
TRUTH_FILE = "SYNTHETIC_crit_truth.toml"
PREFIX = "SYNTHETIC_crit_"
SEED = 20261123
RATE_HZ = 100.0
NOISE_M = 0.3e-3
ANGLE_NOISE_RAD = 1e-3
RAMP_STEPS = 11
SUSTAIN_STEPS = 80
TRUTH_DAMPING_NS_PER_M = 10.0
GUIDE_FRICTION_N = 0.06
RTOL = 1e-9
RECORD_DT_S = 1e-3
#: slopes (deg) of the series, each with two release speeds (rad/s)
SLOPES_DEG = (1.3, 1.45, 1.6, 1.75, 1.9, 2.05)
RELEASES_RAD_S = (1.9, 2.5)
SERIES = tuple((s, w) for s in SLOPES_DEG for w in RELEASES_RAD_S)


def _truth_params(slope_deg: float):
    from rimless.sim.model.params import WheelParams

    return WheelParams(damping_ns_per_m=TRUTH_DAMPING_NS_PER_M, slope_rad=math.radians(slope_deg))


def _friction_scale(params, y_plus: np.ndarray) -> np.ndarray:
    """Post-impact state with the guide-friction work of one step removed from the kinetic energy."""
    m8 = 8 * params.leg_mass_kg
    mass = params.hub_mass_kg + m8
    L = params.leg_length_m
    inertia_foot = params.inertia_kg_m2 + m8 * L**2 + mass * L**2
    ke = 0.5 * inertia_foot * y_plus[7] ** 2
    loss = GUIDE_FRICTION_N * 2 * L * math.sin(ALPHA_RAD / 2)
    y = y_plus.copy()
    y[5:] *= math.sqrt(max(1.0 - loss / ke, 0.0)) if ke > 0 else 0.0
    return y


def truth_step(params, y: np.ndarray, integrator, *, t0: float = 0.0, record_dt: float | None = None):
    """One step of the truth model: the ER step, then the guide-friction loss. Raises StepFailure."""
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.step.hybrid import simulate_step

    res = simulate_step(Mechanics.of(params), "er", y, integrator, t0=t0, record_dt=record_dt)
    return res, _friction_scale(params, res.y_plus)


def truth_walk(slope_deg: float, release_rad_s: float, n_steps: int, *, record: bool = False):
    """(steps done, list of StepResult, stalled?, last post-impact state) of the truth model."""
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section
    from rimless.sim.step.backend import make_integrator

    p = _truth_params(slope_deg)
    integ = make_integrator("auto", rtol=RTOL if record else 1e-8)
    y = state_from_section(Mechanics.of(p), np.array([-ALPHA_RAD / 2, release_rad_s]))
    steps, t, stalled = [], 0.0, False
    for _ in range(n_steps):
        try:
            res, y = truth_step(p, y, integ, t0=t, record_dt=RECORD_DT_S if record else None)
        except StepFailure:
            stalled = True
            break
        steps.append(res)
        t += res.period_s
    return len(steps), steps, stalled, y


def truth_critical_slope_deg(tol_deg: float = 1e-3) -> float:
    """Smallest slope at which a brisk release (theta' = 2.5 rad/s) walks `SUSTAIN_STEPS` steps, by bisection."""
    lo, hi = 0.5, 3.0
    if truth_walk(hi, 2.5, SUSTAIN_STEPS)[2]:
        raise RuntimeError("the truth model does not walk at 3 deg")
    while hi - lo > tol_deg:
        mid = 0.5 * (lo + hi)
        if truth_walk(mid, 2.5, SUSTAIN_STEPS)[2]:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass
class CritTrial:
    name: str
    slope_deg: float
    release_rad_s: float
    time_s: np.ndarray
    pose: np.ndarray
    impact_time_s: np.ndarray
    stalled: bool
    steps: int


def _rollback(params, y_plus: np.ndarray, t_start: float, dt: float):
    """A rigid stance from post-impact y_plus that stalls: rises to its highest angle, rolls back to
    theta = -alpha/2 and rests. Returns (t, hub_x, hub_y, theta) in the slope frame, foot at y_plus[0:2]."""
    m8 = 8 * params.leg_mass_kg
    mass = params.hub_mass_kg + m8
    L = params.leg_length_m
    k = mass * params.gravity_m_s2 * L / (params.inertia_kg_m2 + m8 * L**2 + mass * L**2)
    phi = params.slope_rad
    th, w = float(y_plus[2]), float(y_plus[7])
    ts: list[float] = []
    ths: list[float] = []
    t = 0.0
    while True:  # semi-implicit Euler with a fine step: up and back
        w += k * math.sin(th + phi) * 1e-4
        th += w * 1e-4
        t += 1e-4
        if th <= -ALPHA_RAD / 2 and w < 0:
            break
        if len(ts) == 0 or t - ts[-1] >= dt:
            ts.append(t)
            ths.append(th)
    rest = np.arange(ts[-1] + dt, ts[-1] + 1.2, dt)
    t_all = np.concatenate([ts, rest])
    th_all = np.concatenate([ths, np.full(rest.size, -ALPHA_RAD / 2)])
    fx, fy = float(y_plus[0]), float(y_plus[1])
    return t_start + t_all, fx + L * np.sin(th_all), fy + L * np.cos(th_all), th_all


def simulate_crit_trial(slope_deg: float, release: float, rng: np.random.Generator, name: str) -> CritTrial:
    from scipy.spatial.transform import Rotation

    from rimless.sim.model.mechanics import hub_position

    n, steps, stalled, y_last = truth_walk(slope_deg, release, RAMP_STEPS, record=True)
    p = _truth_params(slope_deg)
    # pieces of the path: times, hub x and y, wheel angle
    ts: list[np.ndarray] = []
    hxs: list[np.ndarray] = []
    hys: list[np.ndarray] = []
    angs: list[np.ndarray] = []
    for k, s in enumerate(steps):
        for seg in s.segments or []:
            hub = np.array([hub_position(yi[:5]) for yi in seg.y])
            ts.append(seg.t)
            hxs.append(hub[:, 0])
            hys.append(hub[:, 1])
            angs.append(seg.y[:, 2] + ALPHA_RAD * k + ALPHA_RAD / 2)
    impacts = np.array([s.t_start_s + s.period_s for s in steps])
    t_end_walk = impacts[-1] if impacts.size else 0.0
    if stalled:
        tb, xb, yb, thb = _rollback(p, y_last, t_end_walk, RECORD_DT_S)
        ts.append(tb)
        hxs.append(xb)
        hys.append(yb)
        angs.append(thb + ALPHA_RAD * n + ALPHA_RAD / 2)
        t_stop = tb[-1]
    else:
        t_stop = t_end_walk + 0.5 * steps[-1].period_s if steps else 0.5
    tt = np.concatenate(ts)
    order = np.argsort(tt, kind="stable")
    tt = tt[order]
    keep = np.concatenate([[True], np.diff(tt) > 0])
    tt = tt[keep]
    hx, hy, ang = (np.concatenate(v)[order][keep] for v in (hxs, hys, angs))
    if not stalled:  # after the last impact: the next step's start, as a rigid stance (the ramp ends)
        tb, xb, yb, thb = _rollback(p, y_last, t_end_walk, RECORD_DT_S)
        # the wheel leaves the ramp still rolling forward: the recording ends before the rigid stance
        # would turn back (or half a step after the impact, whichever comes first)
        t_stop = min(t_stop, float(tb[int(np.argmax(thb))]))
        m = tb <= t_stop
        tt = np.concatenate([tt, tb[m][1:]])
        hx = np.concatenate([hx, xb[m][1:]])
        hy = np.concatenate([hy, yb[m][1:]])
        ang = np.concatenate([ang, (thb[m] + ALPHA_RAD * n + ALPHA_RAD / 2)[1:]])
    t_first = float(rng.uniform(0.15, 0.25))
    t = np.arange(t_first, min(t_stop, tt[-1]), 1.0 / RATE_HZ)
    x, yv, b = (np.interp(t, tt, v) for v in (hx, hy, ang))

    phi = math.radians(slope_deg)
    yaw = math.radians(float(rng.uniform(0.0, 360.0)))
    travel = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(phi) * travel - math.sin(phi) * up
    nrm = math.sin(phi) * travel + math.cos(phi) * up
    w = np.cross(d, nrm)
    origin = np.array([rng.uniform(-1.5, 0.5), rng.uniform(-1.5, 0.5), 0.40 + 1.3 * math.tan(phi)])
    hub = origin + np.outer(x, d) + np.outer(yv, nrm)
    base = Rotation.from_rotvec(rng.uniform(0, 2 * np.pi) * w) * Rotation.from_matrix(np.column_stack([d, nrm, w]))
    rot = Rotation.from_rotvec(np.outer(-b, w)) * base
    r_off, g_off = rng.uniform(0.03, 0.05), rng.uniform(0, 2 * np.pi)
    origin_in_body = np.array([r_off * math.cos(g_off), r_off * math.sin(g_off), 0.0])
    trans = hub + rot.apply(origin_in_body)
    noisy = Rotation.from_rotvec(rng.normal(0.0, ANGLE_NOISE_RAD, (t.size, 3))) * rot
    pose = np.column_stack([noisy.as_rotvec(), trans + rng.normal(0.0, NOISE_M, trans.shape)])
    return CritTrial(name, slope_deg, release, t, pose, impacts, stalled, n)


def truth_header() -> list[str]:
    """The comment lines that open ``SYNTHETIC_crit_truth.toml``: what the data are and the truth's loss."""
    return [
        "# SYNTHETIC slope series around the critical slope: simulated, NOT measured.",
        "# Generated by `python -m rimless.analysis.examples.critical_series`. Truth model: the ER wheel of rimless.sim",
        f"# with c = {TRUTH_DAMPING_NS_PER_M} N s/m (Table 1: 8) and a constant force of {GUIDE_FRICTION_N} N against the",
        "# wheel's travel along its whole path (the key guide_friction_n below; NOT the simulator's F_c, which acts",
        "# only over the legs' compression): its work per step, F x 2 L0 sin(alpha/2), is removed from the kinetic",
        "# energy after each impact. Times in s from the release.",
    ]


def generate(out_dir: str | Path = DATA_DIR, *, seed: int = SEED) -> list[Path]:
    """Write the SYNTHETIC_crit_*.csv series and SYNTHETIC_crit_truth.toml; returns the CSV paths."""
    from rimless.analysis.io.tracker_csv import write_tracker_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    crit = truth_critical_slope_deg()
    lines = [
        *truth_header(),
        "",
        "[dataset]",
        f"seed = {seed}",
        f"rate_hz = {RATE_HZ}",
        f"ramp_steps = {RAMP_STEPS}",
        f"noise_translation_m = {NOISE_M}",
        f"damping_ns_per_m = {TRUTH_DAMPING_NS_PER_M}",
        f"guide_friction_n = {GUIDE_FRICTION_N}",
        f"critical_slope_deg = {crit:.4f}  # smallest slope sustaining {SUSTAIN_STEPS} steps from 2.5 rad/s",
        "",
    ]
    paths = []
    for _i, (slope, w) in enumerate(SERIES):
        name = f"{PREFIX}slope{slope:.2f}deg_release{w:.1f}"
        tr = simulate_crit_trial(slope, w, rng, name)
        path = out / f"{name}.csv"
        tmp = path.with_suffix(".csv.tmp")
        write_tracker_csv(tmp, rate_hz=RATE_HZ, objects={"Wheel": tr.pose}, length_unit="mm", angle_unit="rad")
        tmp.replace(path)
        paths.append(path)
        lines += [
            f'[trials."{name}"]',
            f'file = "{name}.csv"',
            f"slope_deg = {slope}",
            f"release_theta_dot_rad_s = {w}",
            f"steps_on_ramp = {tr.steps}",
            f'outcome = "{"stalled" if tr.stalled else "walked"}"',
            f"first_frame_time_s = {tr.time_s[0]:.6f}",
            "impact_time_s = [" + ", ".join(f"{v:.6f}" for v in tr.impact_time_s) + "]",
            f"sustained = {'true' if slope > crit else 'false'}",
            "",
        ]
    (out / TRUTH_FILE).write_text("\n".join(lines), encoding="utf-8")
    return paths


def data_files() -> list[Path]:
    """The bundled SYNTHETIC_crit_*.csv files, sorted."""
    return sorted(DATA_DIR.glob(f"{PREFIX}*.csv"))


def load_truth(path: str | Path | None = None) -> dict:
    import tomllib

    with open(Path(path) if path else DATA_DIR / TRUTH_FILE, "rb") as fh:
        return tomllib.load(fh)


if __name__ == "__main__":  # pragma: no cover
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else DATA_DIR
    for p in generate(target):
        print(p)
    print(target / TRUTH_FILE)
