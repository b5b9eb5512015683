"""Replay a robot trial log (JSON Lines from `rimless robot run`) against the simulator.

The log is read with the firmware's own reader (rimless.firmware.service.triallog). Its steps are the intervals
between the firmware's `touchdown` events; each is set beside two simulated ER steps at the given
parameters: the ideal-clutch fixed point, and a step of the walk under the firmware in the loop
(rimless.sim.in_the_loop.loop, the last of `FIRMWARE_STEPS` steps from the ideal fixed point, with the
sampling rate, delays and noise given): recorded compression (sensor position since the step's touchdown
event) over the simulated stance-leg compression L0 - L1, all from their own touchdown. For the
firmware step, the leg motion is taken at the firmware's sample instants, with the instant its
`lock` command was issued and the interval in which the stance clutch was physically engaged. The firmware
detects a touchdown after it happened, so each recorded curve starts a few milliseconds later than the
simulated one (from the impact); the lag is not corrected here, and the summary compares step periods
(touchdown event to touchdown event, where the lag cancels), the lock time after the touchdown event and
the maximum compression.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class ReplayStep:
    """One recorded step beside the simulated one (SI; times from the step's touchdown event, s)."""

    index: int
    t_touchdown_s: float  # monotonic time of the touchdown event in the log
    recorded_period_s: float
    recorded_lock_s: float | None  # lock event after the touchdown event
    recorded_max_compression_m: float
    t: np.ndarray  # recorded sample times from the touchdown event
    compression_m: np.ndarray  # recorded compression
    clutch_mask: np.ndarray


@dataclass
class FirmwareReplayStep:
    """One simulated step under the firmware in the loop (times from its impact, s; SI)."""

    rate_hz: float
    engage_delay_s: float
    release_delay_s: float
    noise_counts: float
    t: np.ndarray  # the firmware's sample instants in the step
    compression_m: np.ndarray  # true stance-leg compression at those instants
    sensed_compression_m: np.ndarray  # what the firmware's detector integrated (quantised, noisy)
    stance_engaged: np.ndarray  # the stance clutch physically engaged at the instant (bool)
    period_s: float
    lock_command_s: float | None  # the firmware's `lock` event
    lock_s: float | None  # the clutch physically engaged
    lock_class: str
    stored_energy_J: float
    failure: str | None  # the walk failed before the step (then the arrays are empty)


FIRMWARE_STEPS = 4


@dataclass
class Replay:
    """A trial log's steps beside the simulated step."""

    path: Path
    steps: list[ReplayStep]
    sim_t: np.ndarray  # from the simulated impact, s
    sim_compression_m: np.ndarray  # L0 - L1
    sim_period_s: float
    sim_peak_s: float  # maximum compression after the impact
    sim_max_compression_m: float
    faults: list[str]
    torn_tail: bool
    firmware: FirmwareReplayStep | None = None  # the step under the firmware in the loop (None: not simulated)

    def summary(self) -> dict[str, Any]:
        rec_periods = [s.recorded_period_s for s in self.steps]
        locks = [s.recorded_lock_s for s in self.steps if s.recorded_lock_s is not None]
        return {
            "log": str(self.path),
            "steps": len(self.steps),
            "torn_tail": self.torn_tail,
            "faults": self.faults,
            "recorded_period_s": {"mean": _mean(rec_periods), "min": _min(rec_periods), "max": _max(rec_periods)},
            "simulated_period_s": self.sim_period_s,
            "recorded_lock_after_touchdown_s": {"mean": _mean(locks), "min": _min(locks), "max": _max(locks)},
            "simulated_peak_after_impact_s": self.sim_peak_s,
            "recorded_max_compression_m": _mean([s.recorded_max_compression_m for s in self.steps]),
            "simulated_max_compression_m": self.sim_max_compression_m,
            "firmware_in_the_loop": None
            if self.firmware is None
            else {
                "rate_hz": self.firmware.rate_hz,
                "engage_delay_ms": self.firmware.engage_delay_s * 1e3,
                "release_delay_ms": self.firmware.release_delay_s * 1e3,
                "noise_counts": self.firmware.noise_counts,
                "simulated_period_s": self.firmware.period_s if self.firmware.failure is None else None,
                "lock_command_after_impact_s": self.firmware.lock_command_s,
                "lock_after_impact_s": self.firmware.lock_s,
                "lock_class": self.firmware.lock_class,
                "max_compression_m": float(self.firmware.compression_m.max()) if len(self.firmware.t) else None,
                "stored_energy_J": self.firmware.stored_energy_J,
                "failure": self.firmware.failure,
            },
            "per_step": [
                {
                    "index": s.index,
                    "period_s": s.recorded_period_s,
                    "lock_after_touchdown_s": s.recorded_lock_s,
                    "max_compression_m": s.recorded_max_compression_m,
                }
                for s in self.steps
            ],
        }


def _mean(v: list[float]) -> float | None:
    return float(np.mean(v)) if v else None


def _min(v: list[float]) -> float | None:
    return float(np.min(v)) if v else None


def _max(v: list[float]) -> float | None:
    return float(np.max(v)) if v else None


def firmware_step(params: Any, config: Any, z_ideal: np.ndarray, *, steps: int = FIRMWARE_STEPS) -> FirmwareReplayStep:
    """The last step of a walk of `steps` under the firmware from the ideal fixed point, at the firmware's samples."""
    from rimless.sim.in_the_loop.loop import N_LEGS, FirmwareLoop

    loop = FirmwareLoop(params, config)
    try:
        walk = loop.walk(z_ideal, steps, record_samples=True)
    finally:
        loop.close()
    cfg = config
    if not walk.steps:
        empty = np.empty(0)
        return FirmwareReplayStep(
            cfg.rate_hz,
            cfg.engage_delay_s,
            cfg.release_delay_s,
            cfg.noise_counts,
            empty,
            empty,
            empty,
            np.empty(0, dtype=bool),
            float("nan"),
            None,
            None,
            "none",
            0.0,
            str(walk.failure),
        )
    st = walk.steps[-1]
    b_leg = (loop.stance_leg - 1) % N_LEGS  # the stance leg of the last step
    truth = np.array(loop.truth_log or [], dtype=float).reshape(-1, 3)
    est = np.array([(t, pos) for t, pos, *_ in (loop.sample_log or [])], dtype=float).reshape(-1, 2)
    t0, t1 = st.t_start_s, st.t_start_s + st.period_s
    sel = (truth[:, 0] >= t0) & (truth[:, 0] <= t1)
    t = truth[sel, 0]
    x = truth[sel, 1]
    x0 = float(np.interp(t0, truth[:, 0], truth[:, 1]))
    sel_e = (est[:, 0] >= t0) & (est[:, 0] <= t1)
    e0 = float(np.interp(t0, est[:, 0], est[:, 1]))
    engaged = (truth[sel, 2].astype(int) >> b_leg) & 1 == 1
    lock_cmd = next((te for te, name in st.firmware_events if name == "lock"), None)
    return FirmwareReplayStep(
        cfg.rate_hz,
        cfg.engage_delay_s,
        cfg.release_delay_s,
        cfg.noise_counts,
        t - t0,
        x - x0,
        est[sel_e, 1] - e0,
        engaged,
        st.period_s,
        lock_cmd,
        st.lock_time_s,
        st.lock_class,
        st.stored_energy_J,
        None if walk.failure is None or len(walk.steps) == steps else str(walk.failure),
    )


def replay_trial(path: str | Path, params: Any, *, channel: int = 0, firmware_config: Any = None) -> Replay:
    """Read a trial log and pair its steps with the simulated ideal-clutch step and, with `firmware_config`
    (a FirmwareLoopConfig), the simulated step under the firmware in the loop.
    Raises rimless.firmware.service.triallog.TrialLogError on a corrupt log and ValueError when it has no step."""
    from rimless.firmware.service.triallog import read_trial_log
    from rimless.sim.in_the_loop.ideal import ideal_fixed_point
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section
    from rimless.sim.step.hybrid import simulate_step

    path = Path(path)
    log = read_trial_log(path)
    samples = [s for s in log.samples if s.get("ch", 0) == channel and "leg" in s]
    t = np.array([s["t_mono_s"] for s in samples], dtype=float)
    pos = np.array([s["leg"]["position_m"] for s in samples], dtype=float)
    mask = np.array([s["leg"].get("clutch_mask", 0) for s in samples], dtype=int)
    events = [(e["t_mono_s"], e["event"]) for e in log.events]
    touch = [te for te, ev in events if ev.get("name") == "touchdown" and ev.get("channel", 0) == channel]
    locks = [te for te, ev in events if ev.get("name") == "lock" and ev.get("channel", 0) == channel]
    faults = [str(ev.get("fault")) for _, ev in events if ev.get("name") == "fault"]
    if len(touch) < 2 or len(t) == 0:
        raise ValueError(f"{path}: fewer than two touchdown events on channel {channel}: no complete step to replay")
    steps = []
    for k, (t0, t1) in enumerate(zip(touch[:-1], touch[1:])):
        sel = (t >= t0) & (t < t1)
        if not sel.any():
            continue
        p0 = float(np.interp(t0, t, pos))
        comp = pos[sel] - p0
        lock = next((tl - t0 for tl in locks if t0 <= tl < t1), None)
        steps.append(ReplayStep(k, t0, t1 - t0, lock, float(comp.max()), t[sel] - t0, comp, mask[sel]))
    fp = ideal_fixed_point(params, backend="reference", rtol=1e-9)
    mech = Mechanics.of(params)
    res = simulate_step(
        mech, "er", state_from_section(mech, fp.z), ScipyIntegrator(rtol=1e-9, atol=1e-11), record_dt=5e-4
    )
    st = np.concatenate([s.t for s in res.segments or []])
    sl = np.concatenate([s.y[:, 3] for s in res.segments or []])
    order = np.argsort(st, kind="stable")
    sim_t, sim_c = st[order], params.leg_length_m - sl[order]
    i_peak = int(np.argmax(sim_c))
    fw = firmware_step(params, firmware_config, fp.z) if firmware_config is not None else None
    return Replay(
        path,
        steps,
        sim_t,
        sim_c,
        float(res.period_s),
        float(sim_t[i_peak]),
        float(sim_c[i_peak]),
        faults,
        log.torn_tail,
        fw,
    )


def plot_replay(replay: Replay, path: str | Path) -> Path:
    """Recorded compression of every step (grey, clutch-engaged samples marked) over the simulated step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for s in replay.steps:
        ax.plot(s.t * 1e3, s.compression_m * 1e3, color="0.6", lw=0.8)
        on = s.clutch_mask != 0
        ax.plot(s.t[on] * 1e3, s.compression_m[on] * 1e3, ".", color="tab:red", ms=2)
    ax.plot(
        replay.sim_t * 1e3, replay.sim_compression_m * 1e3, color="tab:blue", lw=2, label="simulated (ideal clutch)"
    )
    ax.axvline(replay.sim_peak_s * 1e3, color="tab:blue", ls=":", lw=1)
    fw = replay.firmware
    if fw is not None and len(fw.t):
        ax.plot(
            fw.t * 1e3,
            fw.compression_m * 1e3,
            color="tab:green",
            lw=1.6,
            label=f"simulated, firmware in the loop ({fw.rate_hz:g} Hz, {fw.engage_delay_s * 1e3:g} ms)",
        )
        ax.plot(
            fw.t * 1e3,
            fw.sensed_compression_m * 1e3,
            "x",
            color="tab:green",
            ms=3,
            label="its samples as the firmware integrated them",
        )
        on = fw.stance_engaged
        ax.plot(
            fw.t[on] * 1e3,
            fw.compression_m[on] * 1e3,
            ".",
            color="darkgreen",
            ms=4,
            label="stance clutch engaged (simulated)",
        )
        if fw.lock_command_s is not None:
            ax.axvline(fw.lock_command_s * 1e3, color="tab:green", ls="--", lw=1, label="firmware lock command")
    ax.plot([], [], color="0.6", label="recorded steps")
    ax.plot([], [], ".", color="tab:red", label="clutch engaged (recorded)")
    ax.set_xlabel("time since touchdown (ms)")
    ax.set_ylabel("leg compression (mm)")
    ax.set_title(f"{replay.path.name}: {len(replay.steps)} steps")
    ax.legend(loc="lower right", fontsize=7)
    from rimless.sim.studies.figures import save_figure

    return save_figure(fig, path, dpi=120, option="--plot")


def replay_log(path: Path, params: Any, *, firmware_config: Any = None, plot: Path | None = None) -> dict[str, Any]:
    """`rimless sim replay`: `replay_trial` and, with `plot`, its figure (key `plot`: its path); returns the
    command's JSON object. A corrupt log is a ParameterError, a log without a step a RunFailure."""
    from rimless.errors import ParameterError, RunFailure
    from rimless.firmware.service.triallog import TrialLogError

    if not path.is_file():
        raise ParameterError(f"{path}: no such trial log")
    try:
        rep = replay_trial(path, params, firmware_config=firmware_config)
    except TrialLogError as err:
        raise ParameterError(str(err)) from None
    except ValueError as err:
        raise RunFailure(str(err)) from None
    out = rep.summary()
    out["plot"] = str(plot_replay(rep, plot)) if plot is not None else None
    return out
