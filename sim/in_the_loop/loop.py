"""Firmware in the loop: the robot's own controller decides when the simulated legs lock and release.

The firmware runs unchanged (`rimless.firmware`): its `Controller` reads an `Adns3080` driver over the
register-level `FakeAdns3080` bus, runs its `LegDetector`, and switches a `ClutchBank` on gpiozero's
MockFactory pins. Only the clock is virtual and the fake's trajectory is the simulated leg.

What the sensor sees: the compression of the stance leg b, accumulated over the walk (each touchdown
starts the count of the next leg where the previous one stopped), quantised by the fake at `cpi`
(floor of counts + Gaussian noise of `noise_counts`), with its SQUAL, 8-bit deltas and accumulator.

Sampling: read k is due at t0 + k / rate_hz and happens late by |N(0, jitter_s)|, at most half a period
(the firmware's sampler skips a deadline it misses by more). Each read is timestamped with the virtual
clock, as `monotonic_ns` would be.

Clutches: a pin change at time t acts on the leg `engage_delay_s` or `release_delay_s` later. The leg is
locked where it is: an engagement while the leg moves is an inelastic stop (the lost energy is reported).
Physical legs are numbered like the firmware's clutches: the stance leg b advances by one at every
touchdown; a clutch of a leg in the air at L0 changes nothing. The touchdown is detected by the firmware
after it happened, so the trailing leg is always released late: the impact then has it locked
(`clutch_hardware.touchdown_with_locks`), foot a lifts, and when the clutch lets go the leg extends and
its foot may come down again (a foot-a re-contact, an inelastic impact of that foot), pushing off in
double support as the ideal clutch would.

Warm start: the firmware watches one step of the ideal clutch (its commands ignored) before it takes over,
so that it enters the first controlled step knowing the stance leg and the last touchdown, as on a robot
that has been walking.

Integration: scipy's DOP853 on the mode's constrained dynamics (reference path, Python), stepped freely;
samples and clutch actions are taken from its dense output, and a clutch action ends the continuous phase.
The guards are those of rimless.sim.model.guards (codes, directions, force guards), located by the one
engine rimless.sim.integrate.events: sign change on a step (strictly from the non-firing side), Brent on the
dense output, and the normal forces' dips between step ends, searched on the interpolants of the last two
steps. A dip found in the step before the current one is located after the firmware already sampled that
step: the firmware then saw up to one solver step of the motion past the event.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from rimless.firmware.control.controller import Channel, Controller, EventRecord
from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.control.faults import HealthLimits, HealthMonitor
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.clutch import ClutchBank
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080
from rimless.sim.integrate.events import EventLocator, Piecewise
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import clutch as ch
from rimless.sim.model.clutch import Mode
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.guards import (
    FOOT_A_DOWN,
    LIFTOFF_A,
    LIFTOFF_B,
    SLIP_END_1,
    SLIP_END_2,
    STALL,
    STICK_END_1,
    STICK_END_2,
    TOUCHDOWN,
    clutch_forces,
    failure_of,
    mode_guard_value,
)
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.hybrid import simulate_step

N_LEGS = 8
CLUTCH_PINS = (12, 13, 14, 15, 22, 23, 24, 26)  # the mock pins of the eight clutches (any distinct GPIOs)
STEP_TIME_LIMIT_S = 5.0
PRIMING_RECORD_DT_S = 5e-5

ROOT_TOL_S = 1e-13  # Brent's tolerance on an event time (absolute and relative)
PEAK_RATE_M_S = 1e-3  # |L1'| below this at the lock: locked at the compression peak


@dataclass(frozen=True)
class FirmwareLoopConfig:
    """The robot as the simulation sees it (SI units)."""

    rate_hz: float = 300.0  # sensor read rate (the paper's 300 Hz)
    jitter_s: float = 5e-5  # standard deviation of a read's lateness behind its deadline
    noise_counts: float = 1.0  # position noise of the sensor, counts (standard deviation)
    squal: int = 60  # surface quality the sensor reports
    cpi: int = 1600  # sensor resolution, counts per inch (400 or 1600)
    counts_per_m_1600: float = DEFAULT_COUNTS_PER_M  # calibration at 1600 cpi (datasheet lens geometry)
    engage_delay_s: float = 0.005  # pin on -> leg locked
    release_delay_s: float = 0.005  # pin off -> leg free
    holding_force_N: float = 100.0  # the clutch slips beyond this force along the leg (inf: rigid)
    max_hold_s: float = 1.0  # the firmware's clutch timeout ([clutch] max_hold_s): a longer hold is a fault
    # "one": the prototype's single sensor on the stance-leg mechanism, the stance leg counted;
    # "per-leg": one sensor per leg (legs = [k]), each seeing its own leg's compression, the leg measured
    sensors: str = "one"
    detector: DetectorParams = field(default_factory=DetectorParams)
    health: HealthLimits = field(default_factory=HealthLimits)
    seed: int = 0

    def validated(self) -> FirmwareLoopConfig:
        """Return self, or raise ValueError naming the bad field."""
        checks = [
            ("rate_hz", 1.0 <= self.rate_hz <= 1e6, "in [1, 1e6] Hz"),
            ("jitter_s", 0.0 <= self.jitter_s <= 0.1, "in [0, 0.1] s"),
            ("noise_counts", 0.0 <= self.noise_counts <= 1000.0, "in [0, 1000] counts"),
            ("squal", 0 <= self.squal <= 169, "in 0..169"),
            ("cpi", self.cpi in (400, 1600), "400 or 1600"),
            ("counts_per_m_1600", self.counts_per_m_1600 > 0.0, "> 0"),
            ("engage_delay_s", 0.0 <= self.engage_delay_s <= 1.0, "in [0, 1] s"),
            ("release_delay_s", 0.0 <= self.release_delay_s <= 1.0, "in [0, 1] s"),
            ("holding_force_N", self.holding_force_N > 0.0, "> 0 N (inf: a rigid clutch)"),
            ("max_hold_s", 0.01 <= self.max_hold_s <= 60.0, "in [0.01, 60] s"),
        ]
        for name, ok, what in checks:
            value = getattr(self, name)
            if (
                isinstance(value, float)
                and math.isnan(value)
                or not ok
                or (name != "holding_force_N" and isinstance(value, float) and not math.isfinite(value))
            ):
                raise ValueError(f"{name} must be {what}, got {value!r}")
        if self.sensors not in ("one", "per-leg"):
            raise ValueError(f"sensors must be 'one' or 'per-leg', got {self.sensors!r}")
        self.detector.validated()
        return self

    @property
    def counts_per_m(self) -> float:
        """Counts per metre at the configured resolution."""
        return self.counts_per_m_1600 * (1.0 if self.cpi == 1600 else 0.25)


@dataclass
class FirmwareStep:
    """One step under the firmware: section points, timing of the clutch against the motion, energies (J)."""

    z_start: np.ndarray
    z_end: np.ndarray
    t_start_s: float
    period_s: float
    modes: list[tuple[str, float, float]]  # (mode name, start, end), s
    lock_time_s: float | None  # stance clutch physically engaged (None: never in this step)
    lock_rate_m_s: float | None  # L1' just before the lock: < 0 still compressing, > 0 rebounding
    # "compression" (before the step's first compression peak), "peak" (|L1'| < PEAK_RATE_M_S), "rebound" (after
    # the peak, leg extending), "after-rebound" (after the peak, the leg compressing again or at rest), "none"
    lock_class: str
    peak_time_s: float | None  # L1' crossing 0 upwards (maximum compression) before the lock, if any
    stored_energy_J: float  # 1/2 k (L0 - L1)^2 at the lock (0 when nothing locked)
    release_lateness_s: float | None  # trailing clutch released this long after touchdown (None: was free)
    foot_a_lifted_at_impact: bool
    foot_a_recontact: bool
    energy_start_J: float
    energy_end_J: float
    damper_J: float
    clutch_loss_J: float  # lock impulses (an engaged leg stopped while moving)
    recontact_loss_J: float
    impact_loss_J: float  # E(q-, q'-) - E(q+, q'+), relabelling included
    firmware_events: list[tuple[float, str]]

    @property
    def energy_residual_J(self) -> float:
        """E_start - losses - E_end: closes to the integration tolerance."""
        losses = self.damper_J + self.clutch_loss_J + self.recontact_loss_J + self.impact_loss_J
        return self.energy_start_J - losses - self.energy_end_J

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["z_start"] = [float(v) for v in self.z_start]
        out["z_end"] = [float(v) for v in self.z_end]
        out["energy_residual_J"] = self.energy_residual_J
        return out


class _VirtualClock:
    """The time the firmware and the fake sensor read (s); ns values are offset to stay positive."""

    OFFSET_NS = 10**12

    def __init__(self) -> None:
        self.t_s = 0.0

    def seconds(self) -> float:
        return self.t_s

    def ns(self) -> int:
        return self.OFFSET_NS + int(round(self.t_s * 1e9))


class FirmwareLoop:
    """A simulated ER wheel whose clutches are driven by the firmware's controller.

    `walk(z0, n)` warms the firmware up on one ideal step from z0 and then simulates n steps under it.
    """

    def __init__(
        self, params: WheelParams, config: FirmwareLoopConfig | None = None, *, rtol: float = 1e-9, atol: float = 1e-11
    ) -> None:
        from gpiozero.pins.mock import MockFactory

        self.params = params
        self.config = (config or FirmwareLoopConfig()).validated()
        self.mech = Mechanics.of(params)
        self.rtol, self.atol = rtol, atol
        self.L0 = params.leg_length_m
        self.clock = _VirtualClock()
        self._rng = random.Random(self.config.seed)
        self._sensed_m = 0.0  # what the fake sensor's trajectory returns now
        cfg = self.config
        self._leg_compression_m = [0.0] * N_LEGS  # what each per-leg sensor sees: L0 - L of its leg (m)

        def sensor(trajectory: Callable[[float], float], seed: int) -> tuple[FakeAdns3080, Adns3080]:
            fake = FakeAdns3080(
                trajectory,
                counts_per_m=cfg.counts_per_m_1600,
                noise_counts=cfg.noise_counts,
                squal=cfg.squal,
                seed=seed,
                clock=self.clock.seconds,
                needs_reset=False,
            )
            drv = Adns3080(
                fake,
                counts_per_m=cfg.counts_per_m,
                sleep=lambda _s: None,
                clock_ns=self.clock.ns,
            )
            drv.set_resolution(cfg.cpi)
            return fake, drv

        def leg_compression(k: int) -> Callable[[float], float]:
            return lambda _t: self._leg_compression_m[k]

        channels = []
        if cfg.sensors == "per-leg":  # robot.toml with one [[sensor]] per leg, legs = [k]: the leg is measured
            self.fakes = []
            for k in range(N_LEGS):
                fake, drv = sensor(leg_compression(k), cfg.seed * N_LEGS + k)
                self.fakes.append(fake)
                channels.append(Channel(drv, LegDetector(cfg.detector, [k]), HealthMonitor(cfg.health)))
        else:  # the prototype: one sensor on the stance-leg mechanism, the stance leg counted
            fake, drv = sensor(lambda _t: self._sensed_m, cfg.seed)
            self.fakes = [fake]
            channels.append(Channel(drv, LegDetector(cfg.detector, list(range(N_LEGS))), HealthMonitor(cfg.health)))
        self.fake, self.sensor, self.detector = self.fakes[0], channels[0].sensor, channels[0].detector
        self.clutches = ClutchBank(CLUTCH_PINS, pin_factory=MockFactory())
        self.controller = Controller(channels, self.clutches, max_hold_s=cfg.max_hold_s, clock_ns=self.clock.ns)
        self.stance_leg = 0  # physical leg b
        self._pins: set[int] = set()  # clutch pins on, as last read
        self._engaged: set[int] = set()  # clutches physically engaged
        self._pending: list[tuple[float, int, bool]] = []  # (time, leg, engage)
        self._period = 1.0 / cfg.rate_hz
        self._deadline_k = 0
        self._t_origin = 0.0
        self._next_sample = 0.0
        self.samples = 0
        self.events: list[tuple[float, str, dict[str, Any]]] = []
        # (t, position, velocity, phase, clutch mask) of every sample, when a walk records them
        self.sample_log: list[tuple[float, float, float, int, int]] | None = None
        # (t, true accumulated compression the sensor saw, engaged clutches as a bit mask) at every sample,
        # when a walk records them: the simulated leg motion at the firmware's sample instants
        self.truth_log: list[tuple[float, float, int]] | None = None
        self.records: list[Any] | None = None  # the controller's raw records (for a trial log), when kept

    def close(self) -> None:
        """Release the mock pins."""
        self.clutches.close()

    # --- sampling ----------------------------------------------------------------------------------
    def _schedule_next(self) -> None:
        self._deadline_k += 1
        late = abs(self._rng.gauss(0.0, self.config.jitter_s)) if self.config.jitter_s else 0.0
        self._next_sample = self._t_origin + self._deadline_k * self._period + min(late, 0.49 * self._period)

    def _sample(self, t: float, sensed_m: float, legs_m: tuple[float, float], *, apply: bool = True) -> None:
        """One firmware control step at time t: the stance-leg sensor sees `sensed_m` of accumulated
        compression; per-leg sensors see their own leg, `legs_m` = (L1, L2) the stance and trailing legs'
        lengths (a leg in the air keeps its last length)."""
        self.clock.t_s = t
        self._sensed_m = sensed_m
        self._leg_compression_m[self.stance_leg] = self.L0 - legs_m[0]
        self._leg_compression_m[(self.stance_leg - 1) % N_LEGS] = self.L0 - legs_m[1]
        self.controller.step()
        self.samples += 1
        if self.truth_log is not None:
            self.truth_log.append((t, sensed_m, sum(1 << leg for leg in self._engaged)))
        while self.controller.outbox:
            rec = self.controller.outbox.popleft()
            if self.records is not None:
                self.records.append(rec)
            if isinstance(rec, EventRecord):
                self.events.append((t, rec.name, rec.fields))
            elif self.sample_log is not None:
                self.sample_log.append((t, rec.position_m, rec.velocity_m_s, rec.phase, rec.clutch_mask))
        pins = set(self.clutches.engaged())
        if apply:
            cfg = self.config
            for leg in sorted(pins - self._pins):
                self._pending.append((t + cfg.engage_delay_s, leg, True))
            for leg in sorted(self._pins - pins):
                self._pending.append((t + cfg.release_delay_s, leg, False))
            self._pending.sort(key=lambda p: p[0])
        self._pins = pins
        self._schedule_next()

    # --- the walk -----------------------------------------------------------------------------------
    def walk(
        self,
        z0: np.ndarray,
        n_steps: int,
        *,
        progress: Callable[[int], None] | None = None,
        record_samples: bool = False,
    ) -> FirmwareWalk:
        """Prime the firmware on one ideal step from z0, then simulate up to n_steps under it.

        A failing step ends the walk; it is returned in `failure` with the steps done so far."""
        self.sample_log = [] if record_samples else None
        self.truth_log = [] if record_samples else None
        y, t, offset = self._prime(np.asarray(z0, dtype=float))
        steps: list[FirmwareStep] = []
        failure: StepFailure | None = None
        lifted = False
        for k in range(n_steps):
            try:
                step, y, t, offset, lifted = self._step(y, t, offset, lifted)
            except StepFailure as err:
                failure = err
                break
            steps.append(step)
            if progress:
                progress(k + 1)
        return FirmwareWalk(self.params, self.config, steps, failure, list(self.events), self.samples)

    def _prime(self, z0: np.ndarray) -> tuple[np.ndarray, float, float]:
        """One ideal step watched by the firmware (armed, commands without effect); returns the post-impact
        state, the time, and the sensor's accumulated compression at the impact."""
        res = simulate_step(
            self.mech,
            "er",
            state_from_section(self.mech, z0),
            ScipyIntegrator(rtol=self.rtol, atol=self.atol),
            record_dt=PRIMING_RECORD_DT_S,
        )
        tt = np.concatenate([s.t for s in res.segments or []])
        l1 = np.concatenate([s.y[:, 3] for s in res.segments or []])
        l2 = np.concatenate([s.y[:, 4] for s in res.segments or []])
        order = np.argsort(tt, kind="stable")
        tt, l1, l2 = tt[order], l1[order], l2[order]
        self.controller.arm(stance_leg=self.stance_leg)
        self._t_origin = self._rng.random() * self._period  # sampling phase
        self._deadline_k = 0
        self._next_sample = self._t_origin
        while self._next_sample < res.period_s:
            ts = self._next_sample
            l1_s = float(np.interp(ts, tt, l1))
            self._sample(ts, self.L0 - l1_s, (l1_s, float(np.interp(ts, tt, l2))), apply=False)
        self._pins = set(self.clutches.engaged())
        for leg in self._pins:  # a lock the firmware decided while watching acts from the take-over on
            self._pending.append((res.period_s + self.config.engage_delay_s, leg, True))
        offset = self.L0 - float(res.y_minus[3])
        self.stance_leg = (self.stance_leg + 1) % N_LEGS
        return res.y_plus.copy(), res.period_s, offset

    # --- clutch states -----------------------------------------------------------------------------
    def _engaged_state(self, mode: Mode, which: int, y: np.ndarray) -> int:
        """The state of leg `which` (1 or 2) whose clutch is engaged now (finite holding force)."""
        rate = float(y[5 + (ch.L1_INDEX if which == 1 else ch.L2_INDEX)])
        if rate > 0.0:
            return ch.SLIP_UP
        if rate < 0.0:
            return ch.SLIP_DOWN
        return self._stick_or_slip(mode, which, y)

    def _stick_or_slip(self, mode: Mode, which: int, y: np.ndarray) -> int:
        """At L' = 0: STUCK if the clutch can hold the leg, else the direction it slips."""
        trial = replace(mode, leg1=ch.STUCK) if which == 1 else replace(mode, leg2=ch.STUCK)
        lam = clutch_forces(self.mech, trial, y, self.config.holding_force_N)[ch.clutch_force_index(trial, which)]
        if abs(lam) <= self.config.holding_force_N:
            return ch.STUCK
        return ch.SLIP_DOWN if lam > 0.0 else ch.SLIP_UP

    @property
    def _friction(self) -> float:
        f = self.config.holding_force_N
        return f if math.isfinite(f) else 0.0

    # --- one step from a post-impact state ---------------------------------------------------------
    def _step(
        self, y: np.ndarray, t0: float, offset: float, lifted: bool
    ) -> tuple[FirmwareStep, np.ndarray, float, float, bool]:
        mech = self.mech
        rigid = not math.isfinite(self.config.holding_force_N)
        y = np.asarray(y, dtype=float).copy()
        b_leg = self.stance_leg
        a_leg = (b_leg - 1) % N_LEGS
        mode = Mode(foot_a=not lifted)
        for which, leg in ((1, b_leg), (2, a_leg)):
            if leg in self._engaged:
                st = ch.STUCK if rigid else self._engaged_state(mode, which, y)
                mode = replace(mode, leg1=st) if which == 1 else replace(mode, leg2=st)
        recontact_armed = lifted
        e_start = mech.energy(y[:5], y[5:])
        z_start = np.array([y[2], y[7]])
        t = t0
        modes: list[tuple[str, float, float]] = []
        damper = clutch_loss = recontact_loss = 0.0
        lock_time = lock_rate = peak_time = None
        stick_stored = 0.0
        release_late: float | None = None
        recontact = False
        ev_start = len(self.events)
        if not y[7] > 0.0:
            raise StepFailure(FailureReason.STALL, "theta' <= 0 at the start of the step", time_s=t, phase="dlsp")
        while True:
            if t - t0 > STEP_TIME_LIMIT_S:
                raise StepFailure(
                    FailureReason.STALL, f"no touchdown within {STEP_TIME_LIMIT_S} s", time_s=t, phase=mode.name
                )
            while self._pending and self._pending[0][0] <= t + 1e-15:  # clutch actions due now
                _, leg, on = self._pending.pop(0)
                if on:
                    self._engaged.add(leg)
                else:
                    self._engaged.discard(leg)
                    if leg == a_leg and release_late is None and mode.leg2 != ch.FREE:
                        release_late = t - t0
                if leg not in (a_leg, b_leg):
                    continue  # a leg in the air at L0: its clutch changes nothing
                which = 1 if leg == b_leg else 2
                current = mode.leg1 if which == 1 else mode.leg2
                if not on:
                    mode = replace(mode, leg1=ch.FREE) if which == 1 else replace(mode, leg2=ch.FREE)
                    continue
                if current != ch.FREE:
                    continue
                if which == 1 and lock_time is None:
                    lock_time, lock_rate = t, float(y[8])
                if rigid:
                    e0 = mech.energy(y[:5], y[5:])
                    target = replace(mode, leg1=ch.STUCK) if which == 1 else replace(mode, leg2=ch.STUCK)
                    tr = ch.inelastic_transition(mech, target, y[:5], y[5:])
                    if tr.wheel_stopped:
                        raise StepFailure(
                            FailureReason.STALL,
                            "a rigid clutch engaged on the trailing leg in double "
                            "support: the rigid triangle stops the wheel",
                            time_s=t,
                            phase=mode.name,
                        )
                    y = np.concatenate((y[:5], tr.qd_plus))
                    mode = tr.mode
                    recontact_armed = recontact_armed or tr.foot_a_lifts
                    clutch_loss += e0 - mech.energy(y[:5], y[5:])
                else:
                    st = self._engaged_state(mode, which, y)
                    mode = replace(mode, leg1=st) if which == 1 else replace(mode, leg2=st)
                if which == 1 and mode.leg1 == ch.STUCK and not stick_stored:
                    stick_stored = 0.5 * self.params.k * (self.L0 - y[3]) ** 2
            if mode.foot_a and mode_guard_value(mech, mode, LIFTOFF_A, y, self.config.holding_force_N) <= 0.0:
                mode = replace(mode, foot_a=False)
                recontact_armed = mode.leg2 != ch.FREE
            guards = [TOUCHDOWN, STALL, LIFTOFF_B]
            if mode.foot_a:
                guards.append(LIFTOFF_A)
            elif recontact_armed and not mode.lock2:
                guards.append(FOOT_A_DOWN)
            for which, st in ((1, mode.leg1), (2, mode.leg2)):
                if st in (ch.SLIP_UP, ch.SLIP_DOWN):
                    guards.append(SLIP_END_1 if which == 1 else SLIP_END_2)
                elif st == ch.STUCK and not rigid:
                    guards.append(STICK_END_1 if which == 1 else STICK_END_2)
            t_mode = t
            kind, code, t, y, diss, slip, peak = self.integrate_mode(
                mode, y, t, t0 + STEP_TIME_LIMIT_S + 1e-9, tuple(guards), offset
            )
            damper += diss
            clutch_loss += slip
            if peak is not None and peak_time is None and lock_time is None:
                peak_time = peak
            modes.append((mode.name, t_mode, t))
            if kind in ("action", "limit"):
                continue
            failure = failure_of(code, t, mode.name)  # stall or stance lift-off
            if failure is not None:
                raise failure
            if code == LIFTOFF_A:
                mode = replace(mode, foot_a=False)
                # a foot lifted by the clutch still holding its spring comes down again when it lets go
                recontact_armed = mode.leg2 != ch.FREE
                continue
            if code in (SLIP_END_1, SLIP_END_2, STICK_END_1, STICK_END_2):
                which = 1 if code in (SLIP_END_1, STICK_END_1) else 2
                y = y.copy()
                if code in (SLIP_END_1, SLIP_END_2):
                    y[5 + (ch.L1_INDEX if which == 1 else ch.L2_INDEX)] = 0.0
                    st = self._stick_or_slip(mode, which, y)
                else:
                    idx = ch.clutch_force_index(mode, which)
                    st = (
                        ch.SLIP_DOWN
                        if clutch_forces(self.mech, mode, y, self.config.holding_force_N)[idx] > 0.0
                        else ch.SLIP_UP
                    )
                mode = replace(mode, leg1=st) if which == 1 else replace(mode, leg2=st)
                if which == 1 and st == ch.STUCK and not stick_stored:
                    stick_stored = 0.5 * self.params.k * (self.L0 - y[3]) ** 2
                continue
            if code == FOOT_A_DOWN:
                e0 = mech.energy(y[:5], y[5:])
                tr = ch.inelastic_transition(mech, replace(mode, foot_a=True), y[:5], y[5:])
                y = np.concatenate((y[:5], tr.qd_plus))
                recontact_loss += e0 - mech.energy(y[:5], y[5:])
                mode = tr.mode
                recontact = True
                recontact_armed = False
                continue
            break  # touchdown
        # impact
        y_minus = y
        e_minus = mech.energy(y[:5], y[5:])
        stance_engaged = b_leg in self._engaged  # the stance leg becomes the trailing leg
        # td: the locked touchdown's transition (None: the reference impact, both legs free)
        imp, q_plus, qd_plus, td = ch.touchdown_with_locks(mech, y[:5], y[5:], trailing_locked=stance_engaged and rigid)
        if td is not None and td.wheel_stopped:
            raise StepFailure(
                FailureReason.STALL,
                "touchdown with the rigid trailing clutch still engaged stopped the "
                "wheel (both feet down, the locked leg holds the wheel rigid)",
                time_s=t,
                phase="impact",
            )
        if imp is not None and not (imp.impulse[1] > 0.0 and imp.impulse[3] > 0.0):
            raise StepFailure(
                FailureReason.NEGATIVE_IMPULSE,
                f"normal impulses b = {imp.impulse[1]:.4g} N s, a = {imp.impulse[3]:.4g} N s must be > 0",
                time_s=t,
                phase="impact",
            )
        if td is not None and not (td.impulse_b[1] > 0.0 and ch.foot_a_normal_velocity(mech, q_plus, qd_plus) >= 0.0):
            raise StepFailure(
                FailureReason.NEGATIVE_IMPULSE,
                "touchdown with the rigid trailing clutch engaged has no "
                "consistent rigid-contact outcome (foot a can neither stay down nor lift)",
                time_s=t,
                phase="impact",
            )
        y_plus = np.concatenate((q_plus, qd_plus))
        if not np.all(np.isfinite(y_plus)):
            raise StepFailure(FailureReason.INTEGRATION, "non-finite impact", time_s=t, phase="impact")
        e_plus = mech.energy(q_plus, qd_plus)
        offset += self.L0 - float(y_minus[3])
        if lock_time is None:
            lock_class = "none"
        elif lock_rate is not None and abs(lock_rate) < PEAK_RATE_M_S:
            lock_class = "peak"
        elif peak_time is None:
            lock_class = "compression"  # before the first compression peak of the step
        elif lock_rate is not None and lock_rate > 0.0:
            lock_class = "rebound"
        else:
            lock_class = "after-rebound"  # the leg has rebounded and oscillates (or rests) again
        step = FirmwareStep(
            z_start=z_start,
            z_end=np.array([y_plus[2], y_plus[7]]),
            t_start_s=t0,
            period_s=t - t0,
            modes=modes,
            lock_time_s=None if lock_time is None else lock_time - t0,
            lock_rate_m_s=lock_rate,
            lock_class=lock_class,
            peak_time_s=None if peak_time is None else peak_time - t0,
            stored_energy_J=0.5 * self.params.k * (self.L0 - float(y_minus[3])) ** 2 if stance_engaged else 0.0,
            release_lateness_s=release_late,
            foot_a_lifted_at_impact=lifted,
            foot_a_recontact=recontact,
            energy_start_J=e_start,
            energy_end_J=e_plus,
            damper_J=damper,
            clutch_loss_J=clutch_loss,
            recontact_loss_J=recontact_loss,
            impact_loss_J=e_minus - e_plus,
            firmware_events=[(te - t0, name) for te, name, _ in self.events[ev_start:]],
        )
        self.stance_leg = (b_leg + 1) % N_LEGS
        return step, y_plus, t, offset, td is not None and td.foot_a_lifts

    def integrate_mode(
        self, mode: Mode, y0: np.ndarray, t0: float, t_bound: float, guards: tuple[int, ...], offset: float
    ) -> tuple[str, int | None, float, np.ndarray, float, float, float | None]:
        """Integrate clutch mode `mode` from (t0 s, y0), taking the firmware's samples on the way (the sensor's
        accumulated compression is `offset` m plus the stance leg's), until a guard of `guards` (codes of
        rimless.sim.model.guards) fires ("guard"), a clutch action is due ("action") or t_bound ("limit").
        Returns (kind, guard, t, y, damper energy J, clutch slip energy J, first L1' upward zero crossing s)."""
        from scipy.integrate import DOP853
        from scipy.optimize import brentq

        mech = self.mech
        fric = self._friction

        def fun(_t: float, y: np.ndarray) -> np.ndarray:
            with np.errstate(over="ignore", invalid="ignore"):
                qdd, _ = ch.accel(mech, mode, y[:5], y[5:10], fric)
            return np.concatenate(
                (y[5:10], qdd, [ch.damping_power(mech, mode, y[5:10]), ch.slip_power(mode, y[5:10], fric)])
            )

        yy = np.concatenate((y0, [0.0, 0.0]))
        solver = DOP853(fun, t0, yy, t_bound, rtol=self.rtol, atol=self.atol)
        pieces: deque[tuple[float, float, Callable[[float], np.ndarray]]] = deque(maxlen=2)  # the last two steps

        def dense_on(ta: float, _ya: np.ndarray, tb: float) -> Piecewise:
            return Piecewise([piece for piece in pieces if piece[0] >= ta and piece[1] <= tb])

        holding = self.config.holding_force_N
        locator = EventLocator(
            guards,
            lambda code, y: mode_guard_value(mech, mode, code, y[:10], holding),
            t0,
            yy,
            dense_on=dense_on,
            strict=True,
            xtol=ROOT_TOL_S,
            rtol=ROOT_TOL_S,
            check_finite=False,
        )
        peak: float | None = None
        while True:
            solver.step()
            if solver.status == "failed" or not np.all(np.isfinite(solver.y)):
                raise StepFailure(FailureReason.INTEGRATION, "the integrator failed", time_s=solver.t, phase=mode.name)
            ta, tb = solver.t_old, solver.t
            sol = solver.dense_output()
            pieces.append((ta, tb, sol))
            event = locator.step(ta, tb, solver.y, lambda: sol, last_step=solver.status == "finished")  # noqa: B023
            t_ev, code = (event[0], guards[event[1]]) if event is not None else (math.inf, None)
            if mode.leg1 != ch.STUCK and peak is None:
                l1a, l1b = sol(ta)[8], solver.y[8]
                if l1a < 0.0 <= l1b:
                    peak = brentq(lambda s: sol(s)[8], ta, tb, xtol=1e-13)  # noqa: B023
            t_lim = min(tb, t_ev)
            while True:
                t_act = self._pending[0][0] if self._pending else math.inf
                ts = self._next_sample
                if t_act <= t_lim and t_act <= ts:
                    ys = sol(t_act)
                    return "action", None, float(t_act), ys[:10], float(ys[10]), float(ys[11]), peak
                if ts <= t_lim:
                    ys = sol(ts)
                    self._sample(ts, offset + self.L0 - float(ys[3]), (float(ys[3]), float(ys[4])))
                    continue
                break
            if event is not None:
                ys = event[2]
                return "guard", code, float(t_ev), ys[:10], float(ys[10]), float(ys[11]), peak
            if solver.status == "finished":
                ys = solver.y
                return "limit", None, float(tb), ys[:10].copy(), float(ys[10]), float(ys[11]), peak


@dataclass
class FirmwareWalk:
    """Consecutive steps under the firmware; `failure` ends the walk early."""

    params: WheelParams
    config: FirmwareLoopConfig
    steps: list[FirmwareStep]
    failure: StepFailure | None
    events: list[tuple[float, str, dict[str, Any]]]
    samples: int

    @property
    def section_points(self) -> np.ndarray:
        """(n + 1, 2): z at the start of the first step, then after each step (rad, rad/s)."""
        if not self.steps:
            return np.empty((0, 2))
        return np.vstack([self.steps[0].z_start] + [s.z_end for s in self.steps])
