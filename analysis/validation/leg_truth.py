"""A truth model of the leg test: simulated `rimless robot leg-test` logs of a leg whose k, c and guide friction
are known, for the coverage study of the leg-test fit (`leg_fit_coverage`, `rimless trials leg-fit-coverage`)
and the tests.

Written apart from the fit's closed form (`rimless.analysis.inference.leg_fit.free_response`) and from the
firmware's fake leg (`rimless.firmware.drivers.fake_leg`): the leg's free motion is integrated numerically
(scipy's DOP853 with event location at every zero of the velocity, a stick test at each one), in metres, with
gravity as a force (not as a shifted equilibrium). The sensor side has the mess of a real recording:

- counts = floor(x * counts_per_m + noise), Gaussian position noise (`noise_counts`), a slow random-walk drift
  of the count (`drift_counts_per_s`, the flow sensor's integration error), and the sensor's zero anywhere;
- read times with jitter and bunches (a late read, then a few quick ones), as a Python loop on a Pi reads; each
  read logged at its start (`t_s`) with its duration (`read_us`, 150-300 us), the motion frozen 5-40 us after
  the start (`latch_us`); now and then the process is descheduled inside a read (1-5 ms), and the motion is
  frozen anywhere in it (the fit must leave those reads out);
- the clutch lets go an unknown 2-6 ms after the release command; the operator's compression differs per test.

`write_log` writes the same JSON Lines format as `rimless robot leg-test` (from its documentation, format
"rimless-leg-test/1"), so a log from here goes through the same reader as one from the robot.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["LegTruth", "free_motion", "position", "read_times", "write_log"]


@dataclass(frozen=True)
class LegTruth:
    """The leg (SI) and the recording (counts, s)."""

    k_n_per_m: float = 2700.0
    c_n_s_per_m: float = 8.0
    friction_n: float = 0.4
    mass_kg: float = 0.0378
    g_m_s2: float = 9.81
    counts_per_m: float = 1600 / 0.0254
    noise_counts: float = 0.3
    drift_counts_per_s: float = 0.5  # random-walk drift of the count: its standard deviation after 1 s
    rate_hz: float = 5000.0
    jitter: float = 0.3  # read interval's relative jitter
    record_s: float = 0.5
    latch_us: tuple[float, float] = (5.0, 40.0)  # the motion is frozen this long after a read's start (uniform)
    quantised: bool = True  # counts are floor(...) (False: the unrounded value, for studies of the fit)


def free_motion(truth: LegTruth, x0_m: float, t_end_s: float, v0_m_s: float = 0.0) -> tuple[list, list]:
    """Integrate the released leg from (x0, v0): returns (pieces, stops), `pieces` a list of (t_start, t_end,
    dense solution or None for a stuck leg, x when stuck), `stops` the times and positions where the velocity
    was zero. x is the compression (m) from the spring's free length; gravity pulls the hanging foot out."""
    k, c, fc, m, g = truth.k_n_per_m, truth.c_n_s_per_m, truth.friction_n, truth.mass_kg, truth.g_m_s2
    t, x, v = 0.0, x0_m, v0_m_s
    pieces: list = []
    stops: list = []
    for _ in range(100000):
        if t >= t_end_s:
            break
        if v == 0.0:
            f = -k * x - m * g
            if abs(f) <= fc:
                pieces.append((t, t_end_s, None, x))
                break
            direction = math.copysign(1.0, f)
        else:
            direction = math.copysign(1.0, v)

        def rhs(_t: float, y: np.ndarray, s: float = direction) -> list[float]:
            return [y[1], (-k * y[0] - m * g - c * y[1] - s * fc) / m]

        def turn(_t: float, y: np.ndarray) -> float:
            return y[1]

        turn.terminal = True  # type: ignore[attr-defined]
        turn.direction = -direction  # type: ignore[attr-defined]
        sol = solve_ivp(
            rhs,
            (t, t_end_s),
            [x, v],
            method="DOP853",
            rtol=1e-11,
            atol=1e-14,
            events=turn,
            dense_output=True,
            first_step=1e-7,
        )
        t_new = float(sol.t[-1])
        pieces.append((t, t_new, sol.sol, None))
        if sol.status == 1 and sol.t_events[0].size:
            t, x, v = float(sol.t_events[0][0]), float(sol.y_events[0][0][0]), 0.0
            stops.append((t, x))
        else:
            break
    return pieces, stops


def position(pieces: list, t: np.ndarray) -> np.ndarray:
    """The position (m) at times t (s since the release) from `free_motion`'s pieces."""
    out = np.empty_like(t, dtype=float)
    for t0, t1, sol, x_stuck in pieces:
        m = (t >= t0) & (t <= t1)
        if m.any():
            out[m] = x_stuck if sol is None else sol(t[m])[0]
    last = pieces[-1]
    late = t > last[1]
    if late.any():
        out[late] = last[3] if last[2] is None else last[2](last[1])[0]
    return out


def read_times(truth: LegTruth, t0: float, t1: float, rng: np.random.Generator) -> np.ndarray:
    """Read instants from t0 to t1: a nominal period with jitter, now and then a late read and a bunch."""
    period = 1.0 / truth.rate_hz
    out, t = [], t0
    while t < t1:
        out.append(t)
        if rng.random() < 0.01:
            t += period * rng.uniform(3, 6)  # the process was not scheduled
        else:
            t += period * max(0.2, 1 + truth.jitter * rng.standard_normal())
    return np.asarray(out)


def write_log(
    path: Path,
    truth: LegTruth,
    *,
    compression_m: float = 0.002,
    seed: int = 0,
    leg: int = 0,
    hold_s: float = 0.3,
    release_delay_s: float | None = None,
) -> dict:
    """A leg-test log of the truth leg: held at `compression_m` above its resting position for `hold_s`, then
    released (the clutch lets go `release_delay_s` after the command, 2-6 ms at random by default); returns
    what was simulated."""
    rng = np.random.default_rng(seed)
    k, m, g, fc = truth.k_n_per_m, truth.mass_kg, truth.g_m_s2, truth.friction_n
    rest = -m * g / k + rng.uniform(-1, 1) * fc / k  # anywhere in the friction band
    x_held = rest + compression_m
    delay = rng.uniform(0.002, 0.006) if release_delay_s is None else release_delay_s
    pieces, _ = free_motion(truth, x_held, truth.record_s + 0.01)
    t_release = 0.2 + hold_s
    t = read_times(truth, 0.0, t_release + truth.record_s, rng)
    read_s = rng.uniform(150e-6, 300e-6, t.size)
    latch = t + rng.uniform(truth.latch_us[0] * 1e-6, truth.latch_us[1] * 1e-6, t.size)
    slow = rng.random(t.size) < 0.005  # descheduled inside the read
    read_s[slow] = rng.uniform(1e-3, 5e-3, int(slow.sum()))
    latch[slow] = t[slow] + rng.uniform(0.0, 1.0, int(slow.sum())) * read_s[slow]
    # the loop is sequential: the read after a descheduled one starts when it has ended (and every later one
    # that much later), so a descheduled read keeps its long duration in the log
    late = np.zeros(t.size)
    late[1:] = np.where(slow[:-1], np.maximum(t[:-1] + read_s[:-1] + 1e-6 - t[1:], 0.0), 0.0)
    shift = np.cumsum(late)
    t, latch = t + shift, latch + shift
    t_next = np.append(t[1:], np.inf)
    read_s = np.minimum(read_s, np.maximum(t_next - t - 1e-6, 1e-6))  # reads do not overlap
    latch = np.minimum(latch, t + read_s)
    x = np.where(latch < t_release + delay, x_held, 0.0)
    free = latch >= t_release + delay
    x[free] = position(pieces, latch[free] - t_release - delay)
    zero = rng.uniform(-500, 500)  # the sensor's zero: anywhere
    drift = np.cumsum(rng.standard_normal(t.size) * truth.drift_counts_per_s * np.sqrt(np.diff(t, prepend=0.0)))
    counts = x * truth.counts_per_m + zero + drift + truth.noise_counts * rng.standard_normal(t.size)
    if truth.quantised:
        counts = np.floor(counts)
    counts -= counts[0]
    header = {
        "format": "rimless-leg-test/1",
        "leg": leg,
        "sensor": 0,
        "counts_per_m": truth.counts_per_m,
        "resolution_cpi": 1600,
        "frame_rate_hz": 6000.0,
        "rate_hz": truth.rate_hz,
        "hold_s": hold_s,
        "record_s": truth.record_s,
        "truth": asdict(truth),
    }
    with open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps(header) + "\n")
        engaged = released = False  # the clutch engages once (at 0.2 s) and is released once
        for ti, ci, ri in zip(t, counts, read_s):
            if not engaged and not released and ti >= 0.2:
                f.write(json.dumps({"t_s": 0.2, "event": "engage", "leg": leg}) + "\n")
                engaged = True
            if ti >= t_release and engaged:
                f.write(json.dumps({"t_s": t_release, "event": "release", "leg": leg}) + "\n")
                engaged, released = False, True
            f.write(
                json.dumps(
                    {
                        "t_s": round(float(ti), 7),
                        "counts": int(ci) if truth.quantised else float(ci),
                        "squal": 60,
                        "shutter": 133,
                        "read_us": round(float(ri) * 1e6, 1),
                    }
                )
                + "\n"
            )
        f.write(json.dumps({"event": "end", "t_s": float(t[-1]), "samples": int(t.size), "outcome": "ok"}) + "\n")
    return {"release_delay_s": delay, "x_held_m": x_held, "rest_m": rest}
