"""The bundled SYNTHETIC example dataset: simulated energy-recycling wheel trials written as Vicon Tracker CSVs.

``python -m rimless.analysis.examples.bundled [OUT_DIR]`` regenerates ``analysis/data/`` (or OUT_DIR) from a fixed seed.

Each trial: the ER wheel with paper Table 1 parameters on a slope of 1.5, 2 or 2.5 deg is released at the
rigid-touchdown state theta = -alpha/2 with a chosen theta' (rad/s) and simulated for `N_STEPS` steps
(`rimless.sim.step.gait.simulate_steps`). The slope-frame hub path (x down the slope, y normal) is rotated into a
world frame with Z up and the travel direction at a random heading; the wheel turns by theta + alpha * step.
What Vicon Tracker would export is written: a static object ``Ramp`` and the tracked object ``Wheel`` (helical
angles in rad, origin in mm) whose origin sits a few cm off the hub in the wheel plane, 100 Hz, Gaussian noise
(0.3 mm on the origin, 1 mrad on the orientation), the wheel held still before the release and caught and lifted
at the end, a few occlusions (empty cells, one long gap in one trial), CRLF line ends and printf-style numbers
with 3-digit exponents (``7.2e-006``). The truth (slope, parameters, release state, impact times,
hub offset, heading) goes to ``SYNTHETIC_truth.toml``.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rimless.analysis.io.trial import ALPHA_RAD

__all__ = ["TRIALS", "SEED", "DATA_DIR", "TRUTH_FILE", "ExampleTrial", "simulate_trial", "generate", "data_files"]

#: Where the bundled dataset lives (package data of rimless.analysis).
DATA_DIR = Path(__file__).resolve().parents[1] / "data"
TRUTH_FILE = "SYNTHETIC_truth.toml"
SEED = 20260501
RATE_HZ = 100.0
N_STEPS = 9  # simulated; the wheel is caught inside step 9, so 8 impacts (7 periods) are inside the data
HOLD_S = (0.3, 0.6)  # held still before the release, s (uniform)
LIFT_M = 0.08  # the catch lifts the wheel this much, m
CATCH_HOLD_S = 0.8  # recording time after the catch, s
LONG_GAP_S = 0.45  # one trial has a long occlusion mid-walk, s
LONG_GAP_TRIAL = 3  # index in TRIALS
RAMP_TRIAL = 4  # index in TRIALS: this recording also tracks the static Ramp object
NOISE_M = 0.3e-3
ANGLE_NOISE_RAD = 1e-3
RECORD_DT_S = 1e-3
RTOL = 1e-9
#: (slope deg, release theta' rad/s): two releases per slope.
TRIALS: tuple[tuple[float, float], ...] = ((1.5, 1.88), (1.5, 1.95), (2.0, 1.88), (2.0, 1.95), (2.5, 1.88), (2.5, 1.95))


@dataclass(frozen=True, eq=False)
class ExampleTrial:
    """One synthetic trial: world-frame Tracker object pose and ground truth (SI)."""

    name: str
    slope_deg: float
    release_theta_rad: float
    release_theta_dot_rad_s: float
    time_s: np.ndarray  # (n,) frame times from the release, s
    pose: np.ndarray  # (n, 6) RX RY RZ rad (helical), TX TY TZ m; NaN at occlusions
    short_rows: np.ndarray  # (n,) bool, occluded frames written as short rows (only Frame, Sub Frame)
    com_height_m: np.ndarray  # (n,) true hub height above the slope, m
    impact_time_s: np.ndarray  # true impacts (end of each simulated step), s from the release
    step_period_s: np.ndarray  # simulated period of each step (step 1 starts at the release), s
    post_impact_theta_dot_rad_s: np.ndarray  # theta'+ after each impact, rad/s
    hub_offset_m: np.ndarray  # (3,) hub in the object frame, m
    heading_deg: float  # travel direction in the world XY plane, deg from +X
    origin_m: np.ndarray  # (3,) world position of the first stance foot, m
    first_frame_time_s: float
    hold_s: float = 0.0  # held still before the release, s
    catch_time_s: float = 0.0  # caught (stops turning, then lifted LIFT_M), s from the release
    long_gap_s: tuple[float, float] | None = None  # a long occlusion mid-walk, s from the release
    ramp_pose: np.ndarray | None = None  # (n, 6) static Ramp object, helical rad + m


def _trial_name(slope_deg: float, index: int) -> str:
    return f"SYNTHETIC_er_slope{slope_deg:.1f}deg_run{index}"


def simulate_trial(
    slope_deg: float,
    release_theta_dot_rad_s: float,
    rng: np.random.Generator,
    *,
    name: str = "trial",
    noise_m: float = NOISE_M,
    angle_noise_rad: float = ANGLE_NOISE_RAD,
    occlusions: bool = True,
    n_steps: int = N_STEPS,
    long_gap: bool = False,
    ramp: bool = False,
) -> ExampleTrial:
    """Simulate one ER trial from the rigid-touchdown release and sample it as a Tracker recording at 100 Hz.

    The recording: the wheel held still (`HOLD_S`) at the release pose, the simulated walk, then caught inside
    step ``n_steps``: it stops turning and is lifted `LIFT_M` along world Z over 0.3 s and held (`CATCH_HOLD_S`).
    ``long_gap``: a 0.45 s occlusion in the middle of the walk. ``ramp``: a static ``Ramp`` object (z axis
    along the slope normal) is tracked beside the wheel.
    """
    from scipy.spatial.transform import Rotation

    from rimless.sim.model.params import WheelParams
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.gait import simulate_steps

    params = WheelParams(slope_rad=math.radians(slope_deg))
    z0 = np.array([-ALPHA_RAD / 2, release_theta_dot_rad_s])
    gait = simulate_steps(params, "er", z0, n_steps, make_integrator("auto", rtol=RTOL), record_dt=RECORD_DT_S)
    if gait.failure is not None or len(gait.steps) < n_steps:
        raise RuntimeError(f"{name}: the simulation did not walk {n_steps} steps ({gait.failure})")
    tab = gait.table
    ts = np.asarray(tab["t_s"], float)
    order = np.argsort(ts, kind="stable")
    ts = ts[order]
    keep = np.concatenate([[True], np.diff(ts) > 0])
    ts = ts[keep]
    hx, hy = tab["hub_x_m"][order][keep], tab["hub_y_m"][order][keep]
    com = tab["com_height_normal_m"][order][keep]
    beta = (tab["theta_rad"] + ALPHA_RAD * tab["step"])[order][keep] + ALPHA_RAD / 2  # 0 at the release

    periods = np.array([s.period_s for s in gait.steps])
    starts = np.array([s.t_start_s for s in gait.steps])
    impacts = starts + periods
    t_catch = starts[-1] + 0.4 * periods[-1]
    hold = float(rng.uniform(*HOLD_S))
    t_first = -hold  # the recording starts while the wheel is held at the release pose
    t = np.arange(t_first, t_catch + CATCH_HOLD_S, 1.0 / RATE_HZ)
    tc = np.clip(t, 0.0, t_catch)  # held before the release, frozen from the catch on
    x, y, h, b = (np.interp(tc, ts, v) for v in (hx, hy, com, beta))
    tau = np.clip((t - t_catch) / 0.3, 0.0, 1.0)
    lift = LIFT_M * tau * tau * (3 - 2 * tau)

    phi = math.radians(slope_deg)
    heading = float(rng.uniform(0.0, 360.0))
    yaw = math.radians(heading)
    travel = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(phi) * travel - math.sin(phi) * up  # down the slope
    nrm = math.sin(phi) * travel + math.cos(phi) * up  # slope normal
    w = np.cross(d, nrm)  # lateral = wheel axis
    origin = np.array([rng.uniform(-1.5, 0.5), rng.uniform(-1.5, 0.5), 0.40 + 1.3 * math.tan(phi)])
    hub = origin + np.outer(x, d) + np.outer(y, nrm) + np.outer(lift, up)

    # Object frame: the wheel-plane frame (d, nrm, w) turned by a fixed angle about the axis, then rolling.
    base = Rotation.from_rotvec(rng.uniform(0, 2 * np.pi) * w) * Rotation.from_matrix(np.column_stack([d, nrm, w]))
    rot = Rotation.from_rotvec(np.outer(-b, w)) * base
    r_off = rng.uniform(0.03, 0.05)
    g_off = rng.uniform(0, 2 * np.pi)
    origin_in_body = np.array([r_off * math.cos(g_off), r_off * math.sin(g_off), 0.0])  # object origin, body frame
    trans = hub + rot.apply(origin_in_body)
    noisy_rot = Rotation.from_rotvec(rng.normal(0.0, angle_noise_rad, (t.size, 3))) * rot
    pose = np.column_stack([noisy_rot.as_rotvec(), trans + rng.normal(0.0, noise_m, trans.shape)])

    short = np.zeros(t.size, bool)
    if occlusions:
        # Mid-step occlusions (2-4 frames of empty cells, 1-frame short rows), and a long one after the last impact.
        mids = starts[1:-1] + 0.5 * periods[1:-1]
        for k, tm in enumerate(rng.choice(mids, size=3, replace=False)):
            i = int(np.searchsorted(t, tm))
            n = 1 if k == 2 else int(rng.integers(2, 5))
            pose[i : i + n] = np.nan
            if k == 2:
                short[i : i + n] = True
        i = int(np.searchsorted(t, impacts[-2] + 0.15 * periods[-1]))
        pose[i : i + 12] = np.nan
    gap_s = None
    if long_gap:
        t0 = float(impacts[2] + 0.1 * periods[3])
        gap_s = (t0, t0 + LONG_GAP_S)
        pose[(t >= gap_s[0]) & (t < gap_s[1])] = np.nan
    # the static ramp: an object whose z axis is the slope normal, 30 cm beside the path
    ramp_rot = Rotation.from_matrix(np.column_stack([d, np.cross(nrm, d), nrm]))
    ramp_pos = origin - 0.3 * w - 0.4 * d
    ramp_noisy = Rotation.from_rotvec(rng.normal(0.0, angle_noise_rad, (t.size, 3))) * ramp_rot
    ramp_pose = np.column_stack([ramp_noisy.as_rotvec(), ramp_pos + rng.normal(0.0, noise_m, (t.size, 3))])
    post = np.array([s.y_plus[7] for s in gait.steps])
    return ExampleTrial(
        name,
        slope_deg,
        -ALPHA_RAD / 2,
        release_theta_dot_rad_s,
        t,
        pose,
        short,
        h,
        impacts,
        periods,
        post,
        -origin_in_body,
        heading,
        origin,
        t_first,
        hold,
        float(t_catch),
        gap_s,
        ramp_pose if ramp else None,
    )


_EXP = re.compile(r"e([+-])(\d{1,2})$")


def format_number(v: float) -> str:
    """printf("%.7g") with Windows' 3-digit exponent, as Tracker on Windows writes numbers."""
    if not math.isfinite(v):
        return ""
    s = f"{v:.7g}"
    return _EXP.sub(lambda m: f"e{m.group(1)}{int(m.group(2)):03d}", s)


def write_trial_csv(trial: ExampleTrial, path: Path) -> Path:
    """Write the trial in Tracker CSV layout (via `write_tracker_csv`), then reformat numbers and short rows."""
    from rimless.analysis.io.tracker_csv import write_tracker_csv

    objects = {"Wheel": trial.pose} if trial.ramp_pose is None else {"Ramp": trial.ramp_pose, "Wheel": trial.pose}
    write_tracker_csv(path, rate_hz=RATE_HZ, objects=objects, length_unit="mm", angle_unit="rad", newline="\r\n")
    lines = path.read_bytes().decode("utf-8").split("\r\n")
    out = lines[:5]
    for i, line in enumerate(lines[5:]):
        if not line:
            out.append(line)
            continue
        cells = line.split(",")
        if trial.short_rows[i]:
            # the wheel's cells are written empty (the ramp is still seen); without a ramp, a short row
            # the wheel's cells are empty; with the ramp (first) still seen, the row ends after it
            out.append(",".join(cells[:8]) if trial.ramp_pose is not None else ",".join(cells[:2]))
            continue
        out.append(",".join(cells[:2] + [format_number(float(c)) if c else "" for c in cells[2:]]))
    path.write_bytes("\r\n".join(out).encode("utf-8"))
    return path


def _toml_value(v: object) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(float(x) if isinstance(x, (np.floating, float)) else x) for x in v) + "]"
    if isinstance(v, (float, np.floating)):
        return repr(round(float(v), 9))
    return str(v)


def generate(out_dir: str | Path = DATA_DIR, *, seed: int = SEED) -> list[Path]:
    """Write the six SYNTHETIC trial CSVs and ``SYNTHETIC_truth.toml`` to out_dir; returns the CSV paths."""
    from rimless.sim.model.params import WheelParams

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    count: dict[float, int] = {}
    paths: list[Path] = []
    toml = [
        "# SYNTHETIC example dataset: simulated, NOT measured. Generated by `python -m rimless.analysis.examples.bundled`.",
        f"# seed = {seed}; ER wheel (rimless.sim), paper Table 1 parameters except the slope; rtol = {RTOL};",
        "# release: post-impact section state (theta, theta') one step before the first impact; times in s from",
        "# the release (the first frame is at first_frame_time_s).",
        "",
        "[dataset]",
        f"seed = {seed}",
        f"rate_hz = {RATE_HZ!r}",
        f"noise_translation_m = {NOISE_M!r}",
        f"noise_orientation_rad = {ANGLE_NOISE_RAD!r}",
        'model = "er"',
        f"simulated_steps = {N_STEPS}",
        'object = "Wheel"',
        "",
        "[params]",
    ]
    for k, v in WheelParams().to_dict().items():
        if k != "slope_rad":
            toml.append(f"{k} = {_toml_value(v)}")
    for index, (slope, wdot) in enumerate(TRIALS):
        count[slope] = count.get(slope, 0) + 1
        name = _trial_name(slope, count[slope])
        tr = simulate_trial(slope, wdot, rng, name=name, long_gap=index == LONG_GAP_TRIAL, ramp=index == RAMP_TRIAL)
        paths.append(write_trial_csv(tr, out / f"{name}.csv"))
        toml += [
            "",
            f'[trials."{name}"]',
            f'file = "{name}.csv"',
            f"slope_deg = {slope!r}",
            f"release_theta_rad = {_toml_value(tr.release_theta_rad)}",
            f"release_theta_dot_rad_s = {wdot!r}",
            f"first_frame_time_s = {_toml_value(tr.first_frame_time_s)}",
            f"impact_time_s = {_toml_value(tr.impact_time_s)}",
            f"step_period_s = {_toml_value(tr.step_period_s)}",
            f"post_impact_theta_dot_rad_s = {_toml_value(tr.post_impact_theta_dot_rad_s)}",
            f"hub_offset_in_object_m = {_toml_value(tr.hub_offset_m)}",
            f"heading_deg = {_toml_value(tr.heading_deg)}",
            f"first_foot_world_m = {_toml_value(tr.origin_m)}",
            f"occluded_frames = {int(np.isnan(tr.pose[:, 0]).sum())}",
            f"hold_s = {_toml_value(tr.hold_s)}",
            f"catch_time_s = {_toml_value(tr.catch_time_s)}",
            f"lift_m = {LIFT_M!r}",
            'outcome = "caught"',
            f"long_gap_s = {_toml_value(list(tr.long_gap_s)) if tr.long_gap_s else '[]'}",
        ]
        if tr.ramp_pose is not None:
            toml.append(f"ramp_slope_deg = {slope!r}")
    (out / TRUTH_FILE).write_text("\n".join(toml) + "\n", encoding="utf-8")
    return paths


def data_files() -> list[Path]:
    """The bundled SYNTHETIC trial CSVs, sorted."""
    return sorted(DATA_DIR.glob("SYNTHETIC_*.csv"))


def load_truth(path: str | Path | None = None) -> dict:
    """The ground truth TOML of the bundled dataset as a dict."""
    import tomllib

    p = Path(path) if path is not None else DATA_DIR / TRUTH_FILE
    with open(p, "rb") as fh:
        return tomllib.load(fh)


if __name__ == "__main__":  # pragma: no cover
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else DATA_DIR
    for p in generate(target):
        print(p)
    print(target / TRUTH_FILE)
