"""The leg test behind `rimless robot leg-test`: the wheel held up, one leg hanging free; the operator compresses
the leg by hand, the firmware engages that leg's clutch at maximum compression, releases it after `hold_s`, and
records the leg's free motion from its ADNS-3080 to a JSON Lines log (`rimless trials leg-fit` reads it).

Maximum compression is found as the walking controller finds it: the zero crossing of the compression velocity
by `LegDetector` (a quadratic fit over its velocity window), with thresholds for a hand's pace
(`HAND_DETECTOR`) and the leg measured, not counted. The detector sees the motion at most `DETECTOR_RATE_HZ`
(the counts are summed in between, so nothing is lost); the log gets every read.

Sensor settings (hardware.md, [DS p.10, 32-36]): 1600 cpi (the finest count, 15.9 um on the datasheet's lens
geometry) and a FIXED frame rate of `LEG_TEST_FRAME_RATE_HZ` = 6000 fps. The datasheet's maximum, 6469 fps
(Frame_Period 3710 counts = Frame_Period_Min_Bound), leaves no room for the shutter under the rule Max_Bound >=
Min_Bound + Shutter_Max_Bound; 6000 fps (4000 counts) leaves a shutter bound of 290 clock cycles (12 us), twice
the reset shutter value 0x85, and tracks about 0.94 m/s (the rating, 40 in/s, scaled from 6469 fps), while the
automatic rate may fall to 2000 fps (about 0.3 m/s) on a dark surface. A leg of the paper's k and c released
from 2 mm peaks at about 0.32 m/s and 14.6 g (its release acceleration k x / m). Reads: one Motion_Burst per
frame at most (faster reads only return zero deltas), paced to `rate_hz` with a busy wait; a bus or Python
slower than that reads back to back (each read is timestamped with `monotonic_ns` at its start, where the chip
freezes the motion at the burst's first byte, and its duration is logged as `read_us`: a read the process was
descheduled in has an uncertain instant, and the fit leaves it out; the achieved rate is reported). On a Pi 4
from Python expect 3-6 kHz (0.15-0.3 ms a read). With `--fake` the loop, the fake sensor and the fake leg run on
a `VirtualClock` (`rimless.firmware.clock`): every read is taken at its deadline, whatever the machine's load.

Safety, as for every command that drives a clutch: every stop signal releases the clutch at once
(`stop_on_signals`), a watchdog thread releases it when the read loop stalls for `[sampling] stall_timeout_s` while
it is engaged (which ends the test; a stall before the engage is only reported) or when the clutch is held beyond
`[clutch] max_hold_s`, the heartbeat pin toggles only while the watchdog sees the loop alive (the hardware enable
drops otherwise) and the loop sees the watchdog thread alive (a round completed within `[sampling] loop_stall_s`;
else the clutch is released and the test ends `watchdog_stalled`), a sensor fault (SPI error, SQUAL low, saturation,
a sensor reset, a wrong Product_ID: its identity and configuration are read back one register every
`READBACK_PERIOD_S` and all before the engage, classed as the walking controller classes them) releases it, and the
hardware is closed (clutches off) on every path. The log is written whole at the end (atomically, also after a
fault: it says which); an interrupted test writes nothing.

Times in seconds, displacement in sensor counts (the log) or metres (the detector).
"""

from __future__ import annotations

import json
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.errors import OutputFileError, ParameterError, RunFailure
from rimless.firmware.clock import Clock, MonotonicClock, VirtualClock, seconds
from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.control.faults import Fault, HealthMonitor
from rimless.firmware.control.watchdog import Watchdog
from rimless.firmware.drivers.fake_adns3080 import still
from rimless.firmware.drivers.fake_leg import FakeLeg, FakeLegParams
from rimless.firmware.drivers.gpio import mock_pin_factory, pin_histories
from rimless.firmware.errors import Interrupted, SensorError, SensorNotFound, SensorReset
from rimless.firmware.service.config import RobotConfig, load_config
from rimless.firmware.service.hardware import Hardware, build_fake, build_real
from rimless.firmware.service.safety import stop_on_signals
from rimless.output import atomic_file, check_output_folder

FORMAT = "rimless-leg-test/1"
LEG_TEST_FRAME_RATE_HZ = 6000.0  # fixed frame rate (see the module docstring)
LEG_TEST_CPI = 1600
DETECTOR_RATE_HZ = 1000.0  # the detector sees the summed counts at most this often
PRE_LOCK_KEEP_S = 1.0  # of the hand's press, the log keeps the last second before the lock
SENSOR_SPEED_RATING_M_S = 1.016  # 40 in/s [DS p.10]
SENSOR_ACCEL_RATING_M_S2 = 15 * 9.81  # 15 g [DS p.10]
WATCHDOG_FEED = "leg_test_loop"
READBACK_PERIOD_S = 1e-3  # one identity/configuration register read back this often (a round of 5 in 5 ms)
SLOW_READ_US = 500.0  # a read that took longer has an uncertain instant (the fit leaves such reads out too)
# The zero-velocity detector of the walking controller with a hand's pace: a press of a few mm over a fraction
# of a second moves at mm/s to cm/s, not at the 50 mm/s of a touchdown, and may take seconds.
HAND_DETECTOR = DetectorParams(
    velocity_window_s=0.03,
    touch_velocity_m_s=0.004,
    touch_debounce_samples=3,
    touch_compression_m=0.0002,
    lock_velocity_m_s=0.0,
    lock_debounce_samples=2,
    min_compression_m=0.0005,
    double_support_s=0.0,
    min_step_s=0.08,
    max_compression_s=10.0,
    max_step_s=10.0,
    confirm_steps=0,
    doubt_compression_m=0.0,
)


@dataclass(frozen=True)
class LegTestOptions:
    """What the operator chose (SI)."""

    leg: int
    hold_s: float = 0.5  # the clutch holds the compressed leg this long before the release
    record_s: float = 1.0  # free motion recorded after the release
    timeout_s: float = 30.0  # no maximum compression within this: the test fails
    rate_hz: float = LEG_TEST_FRAME_RATE_HZ  # reads per second (at most one per frame is useful)
    frame_rate_hz: float = LEG_TEST_FRAME_RATE_HZ
    fake_leg: FakeLegParams = field(default_factory=FakeLegParams)
    noise_counts: float = 0.3  # the fake sensor's position noise (counts, 1 sigma)
    seed: int = 0


@dataclass
class LegTestReport:
    """How the test went; `exit_code` 0 (log written), 1 (a fault or no compression found: the clutch was
    released, the log says why) or 128 + n after signal n (`interrupted`, nothing written)."""

    leg: int
    out: Path
    fake: bool
    written: bool = False
    samples: int = 0
    free_samples: int = 0
    achieved_rate_hz: float = math.nan
    frame_rate_hz: float = math.nan
    counts_per_m: float = math.nan
    lock_compression_mm: float = math.nan
    held_s: float = math.nan
    peak_speed_m_s: float = math.nan
    peak_accel_m_s2: float = math.nan
    fault: str | None = None
    detail: str = ""
    interrupted: str | None = None
    exit_code: int = 0
    fake_pins: str = ""
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """The JSON of `rimless robot leg-test --json`."""
        return {
            "leg": self.leg,
            "out": str(self.out) if self.written else None,
            "fake": self.fake,
            "samples": self.samples,
            "free_samples": self.free_samples,
            "achieved_rate_hz": _num(self.achieved_rate_hz),
            "frame_rate_hz": _num(self.frame_rate_hz),
            "counts_per_m": _num(self.counts_per_m),
            "lock_compression_mm": _num(self.lock_compression_mm),
            "held_s": _num(self.held_s),
            "peak_speed_m_s": _num(self.peak_speed_m_s),
            "peak_accel_m_s2": _num(self.peak_accel_m_s2),
            "fault": self.fault,
            "detail": self.detail,
            "warnings": self.warnings,
            "exit_code": self.exit_code,
        }


def _num(v: float) -> float | None:
    return v if math.isfinite(v) else None


def check_options(cfg: RobotConfig, opts: LegTestOptions) -> int:
    """Validate `opts` against `cfg`; return the index of the sensor watching the leg. `ParameterError` names
    the option."""
    n_legs = len(cfg.clutch.pins)
    if not 0 <= opts.leg < n_legs:
        raise ParameterError(f"--leg must be a clutch index 0..{n_legs - 1} ([clutch] pins), got {opts.leg}")
    sensors = [i for i, s in enumerate(cfg.sensors) if opts.leg in s.legs]
    if not sensors:
        raise ParameterError(f"--leg {opts.leg}: no [[sensor]] watches this leg (legs of each sensor in robot.toml)")
    margin = 0.05
    if not 0.0 < opts.hold_s <= cfg.clutch.max_hold_s - margin:
        raise ParameterError(
            f"--hold-s must be in (0, {cfg.clutch.max_hold_s - margin:g}] s (the clutch timeout "
            f"[clutch] max_hold_s {cfg.clutch.max_hold_s:g} s, less {margin:g} s), "
            f"got {opts.hold_s:g}"
        )
    if not 1000.0 <= opts.rate_hz <= 20000.0:
        raise ParameterError(f"--rate-hz must be in 1000..20000, got {opts.rate_hz:g}")
    if not 2000.0 <= opts.frame_rate_hz <= 6051.0:
        raise ParameterError(
            f"--frame-rate-hz must be in 2000..6051 fps (above 6051 the datasheet's rule "
            "Max_Bound >= Min_Bound + Shutter_Max_Bound leaves no shutter), "
            f"got {opts.frame_rate_hz:g}"
        )
    try:
        opts.fake_leg.validated()
    except ValueError as err:
        raise ParameterError(str(err)) from None
    return sensors[0]


def run_leg_test(
    config: RobotConfig | Path | None,
    opts: LegTestOptions,
    out: Path,
    *,
    fake: bool = False,
    on_status: Callable[[str], object] | None = None,
    on_phase: Callable[[str, Hardware], None] | None = None,
) -> LegTestReport:
    """Run the leg test on the robot (or on the fake leg with `fake`) and write its log to `out`.

    `on_status(text)` hears what the operator should do and what happened; `on_phase(phase, hw)` is called in
    the read loop as each phase begins ("press", "hold", "free": the tests inject faults there). Raises
    `ParameterError` for a bad option (before any pin moves), `OutputFileError` when `out` cannot be written
    (checked first), `RunFailure` when the sensor cannot be opened; every other outcome is in the report.
    """
    say = on_status or (lambda _text: None)
    report = LegTestReport(opts.leg, Path(out), fake)
    _check_out(Path(out))
    state: dict[str, Any] = {}

    def release_now() -> None:
        hw = state.get("hw")
        if hw is not None:
            hw.outputs_off()

    try:
        with stop_on_signals(release_now):
            cfg = config if isinstance(config, RobotConfig) else load_config(config)
            i_sensor = check_options(cfg, opts)
            hw = _open(cfg, opts, i_sensor, fake, state)
            try:
                lines = _run(hw, cfg, opts, i_sensor, report, say, on_phase)
            finally:
                hw.close()
            if fake and hw.pin_factory is not None:
                report.fake_pins = pin_histories(hw.pin_factory, [cfg.clutch.pins[opts.leg]])
            _write(Path(out), lines)
            report.written = True
    except Interrupted as sig:
        opened = state.get("hw")
        if opened is not None:
            opened.close()  # idempotent
            if fake and opened.pin_factory is not None:
                report.fake_pins = pin_histories(opened.pin_factory, opened.clutches.pins)
        report.interrupted, report.exit_code = sig.name, sig.exit_code
    return report


def _check_out(out: Path) -> None:
    """Refuse an output that cannot be written before any pin moves (the file itself is written at the end, and
    an earlier log at that path stays until then)."""
    if out.is_dir():
        raise OutputFileError(f"--out {out}: is a folder, expected a file name")
    check_output_folder(out.parent if str(out.parent) else Path("."), option="--out")


def _open(cfg: RobotConfig, opts: LegTestOptions, i_sensor: int, fake: bool, state: dict[str, Any]) -> Hardware:
    """The hardware (or the fakes, the leg's sensor watching a `FakeLeg`), the sensor set for the test."""
    try:
        if fake:
            factory = mock_pin_factory()
            pin = cfg.clutch.pins[opts.leg]
            on_level = cfg.clutch.active_high

            mock: list[Any] = []  # the clutch's mock pin, looked up once (a lookup costs more than a read)

            def engaged() -> bool:
                if not mock:
                    mock.append(factory.pin(pin))
                return bool(mock[0].state) == on_level

            clock = VirtualClock()  # every read at its deadline: a loaded machine cannot thin out the reads

            def changed_s() -> float | None:  # the clutch output's last edge (s, as `seconds(clock)`), once pins exist
                hw_now = state.get("hw")
                t_ns = hw_now.clutches.changed_ns(opts.leg) if hw_now is not None else None
                return None if t_ns is None else (t_ns - clock.start_ns) * 1e-9

            leg = FakeLeg(opts.fake_leg, engaged, clutch_changed_s=changed_s, clock=seconds(clock))
            trajectories = [leg if i == i_sensor else still for i in range(len(cfg.sensors))]
            hw = build_fake(
                cfg,
                trajectories=trajectories,
                pin_factory=factory,
                noise_counts=opts.noise_counts,
                seed=opts.seed,
                clock=clock,
            )
            state["fake_leg"] = leg
        else:
            hw = build_real(cfg)
        state["hw"] = hw
        sensor = hw.sensors[i_sensor]
        try:
            sensor.set_resolution(LEG_TEST_CPI)
            sensor.set_frame_rate(opts.frame_rate_hz)
            sensor.mark_configured()  # read back in the loop from now on: a reset or a wrong ID faults
            sensor.clear_motion()
        except BaseException:
            hw.close()
            raise
    except SensorError as err:
        raise RunFailure(f"leg test: sensor {i_sensor} failed: {err}") from None
    return hw


def _run(
    hw: Hardware,
    cfg: RobotConfig,
    opts: LegTestOptions,
    i_sensor: int,
    report: LegTestReport,
    say: Callable[[str], object],
    on_phase: Callable[[str, Hardware], None] | None,
) -> list[dict[str, Any]]:
    """The test itself; returns the log's lines (header, samples, events, end)."""

    def enter(name: str) -> None:
        if on_phase is not None:
            on_phase(name, hw)

    s = cfg.sensors[i_sensor]
    sensor = hw.sensors[i_sensor]
    cpm = s.counts_per_m * LEG_TEST_CPI / s.resolution_cpi  # counts per metre at 1600 cpi
    report.counts_per_m = cpm
    report.frame_rate_hz = frame = sensor.frame_rate_hz()
    detector = LegDetector(HAND_DETECTOR, [opts.leg])
    health = HealthMonitor(s.health())
    clutches, leg = hw.clutches, opts.leg
    clock: Clock = hw.clock if hw.clock is not None else MonotonicClock()
    faults: list[tuple[str, str]] = []

    stalls: list[str] = []

    def trip(name: str, detail: str) -> None:  # in the watchdog thread
        if clutches.engaged():  # the loop stalled with the leg held: release it, and the test is void
            hw.outputs_off()
            faults.append((Fault.SENSOR_STALLED.value, detail))
        else:  # nothing engaged (the press): the heartbeat stops until the loop runs again, nothing to release
            stalls.append(detail)

    def hold_check() -> None:  # in the watchdog thread
        held = clutches.longest_hold_s(clock.now_ns())
        if held > cfg.clutch.max_hold_s:
            hw.outputs_off()
            faults.append(
                (Fault.CLUTCH_TIMEOUT.value, f"clutch held {held:.3f} s > max_hold_s {cfg.clutch.max_hold_s:g} s")
            )

    def read_back(check: Callable[[], None]) -> tuple[str, str] | None:  # classified as `robot run` does
        try:
            check()
        except SensorReset as err:
            return Fault.SENSOR_RESET.value, str(err)
        except SensorNotFound as err:
            return Fault.ID_MISMATCH.value, str(err)
        except SensorError as err:
            return Fault.SPI_ERROR.value, str(err)
        return None

    wd = Watchdog(trip, self_timeout_s=cfg.sampling.loop_stall_s)
    wd.add(WATCHDOG_FEED, cfg.sampling.stall_timeout_s)
    wd.checks.append(hold_check)
    header = {
        "format": FORMAT,
        "leg": leg,
        "sensor": i_sensor,
        "counts_per_m": cpm,
        "resolution_cpi": LEG_TEST_CPI,
        "frame_rate_hz": frame,
        "frame_rate_requested_hz": opts.frame_rate_hz,
        "rate_hz": opts.rate_hz,
        "hold_s": opts.hold_s,
        "record_s": opts.record_s,
        "axis": s.axis,
        "sign": s.sign,
        "fake": hw.fakes != [],
        "t_s": "start of each read (s from the test's start, monotonic clock)"
        if hw.clock is None
        else "start of each read (s from the test's start, the fake's virtual clock)",
        "started_epoch_s": time.time(),
    }
    if hw.fakes:
        header["fake_leg"] = opts.fake_leg.to_json()
        header["fake_noise_counts"] = opts.noise_counts
    pre: deque[dict[str, Any]] = deque(maxlen=max(16, int(PRE_LOCK_KEEP_S * opts.rate_hz)))
    post: list[dict[str, Any]] = []
    events: list[dict[str, Any]] = []
    period_ns = round(1e9 / opts.rate_hz)
    det_period_ns = round(1e9 / DETECTOR_RATE_HZ)
    t0 = clock.now_ns()
    counts = 0
    det_counts = 0
    det_next = t0
    readback_period_ns = round(READBACK_PERIOD_S * 1e9)
    readback_next = t0
    phase = "press"
    engaged_ns = released_ns = None
    lock_counts = 0
    deadline = t0
    n = 0
    say(f"compress leg {leg} by hand (about 2 mm) and hold it: the clutch engages at maximum compression")
    wd.start()
    try:
        enter(phase)
        while True:
            deadline += period_ns
            now = clock.now_ns()
            if now < deadline:
                clock.sleep_until(deadline)  # on the robot: sleep, then spin the last 0.3 ms
            else:
                deadline = now  # late: read at once, never in a burst to catch up
            try:
                r0 = clock.now_ns()
                m = sensor.read_motion()
                read_ns = clock.now_ns() - r0
            except SensorError as err:
                hw.outputs_off()
                faults.append((Fault.SPI_ERROR.value, str(err)))
                break
            wd.feed(WATCHDOG_FEED)
            if not wd.thread_alive():  # the watchdog thread is blocked: no heartbeat, clutch off, the test void
                hw.outputs_off()
                faults.append(
                    (
                        Fault.WATCHDOG_STALLED.value,
                        f"the watchdog thread completed no round for {wd.self_timeout_ns * 1e-9:g} s: "
                        "heartbeat stopped",
                    )
                )
                break
            if wd.healthy and hw.heartbeat is not None:
                hw.heartbeat.toggle()
            n += 1
            counts += m.counts
            t_s = (r0 - t0) * 1e-9  # the read's start: the chip freezes the motion at the burst's first byte
            row: dict[str, Any] = {
                "t_s": round(t_s, 7),
                "counts": counts,
                "squal": m.squal,
                "shutter": m.shutter,
                "read_us": round(read_ns * 1e-3, 1),
            }
            if m.overflow or m.saturated:
                row["saturated"] = True
            (pre if phase == "press" else post).append(row)
            bad = health.check(m.t_ns, m.squal, m.saturated or m.overflow, m.stuck)
            if bad is None and m.resolution_reset:
                bad = (Fault.SENSOR_RESET, "the sensor reports 400 cpi: it reset itself")
            if bad is not None:
                hw.outputs_off()
                faults.append((bad[0].value, bad[1]))
                break
            if m.t_ns >= readback_next:  # the sensor's identity and configuration, one register in turn
                readback_next = m.t_ns + readback_period_ns
                wrong = read_back(sensor.check_next)
                if wrong is not None:
                    hw.outputs_off()
                    faults.append(wrong)
                    break
            if faults:
                break
            if phase == "press":
                det_counts += m.counts
                if m.t_ns >= det_next:
                    det_next = m.t_ns + det_period_ns
                    d = detector.update(m.t_ns, det_counts / cpm, trusted=True)
                    det_counts = 0
                    wrong = read_back(sensor.check_all) if d.engage is not None else None
                    if wrong is not None:  # every register read back right before the engage
                        hw.outputs_off()
                        faults.append(wrong)
                        break
                    if d.engage is not None:
                        clutches.engage(leg)
                        engaged_ns, lock_counts = clock.now_ns(), counts
                        events.append(
                            {"t_s": round((engaged_ns - t0) * 1e-9, 7), "event": "engage", "leg": leg, "counts": counts}
                        )
                        phase = "hold"
                        enter(phase)
                        say(
                            f"clutch {leg} engaged at {1e3 * counts / cpm:.2f} mm of "
                            f"compression: let go of the leg; release in {opts.hold_s:g} s"
                        )
                if phase == "press" and (now - t0) * 1e-9 > opts.timeout_s:
                    faults.append(
                        (
                            "no_compression",
                            f"no maximum compression detected within {opts.timeout_s:g} s: "
                            "compress the leg by hand by at least 0.5 mm, at a steady pace, and hold it",
                        )
                    )
                    break
            elif phase == "hold":
                if engaged_ns is not None and now - engaged_ns >= opts.hold_s * 1e9:
                    clutches.release(leg)
                    released_ns = clock.now_ns()
                    events.append(
                        {"t_s": round((released_ns - t0) * 1e-9, 7), "event": "release", "leg": leg, "counts": counts}
                    )
                    phase = "free"
                    enter(phase)
            elif released_ns is not None and now - released_ns >= opts.record_s * 1e9:
                break
    finally:
        wd.stop()
        hw.outputs_off()
    t_end = clock.now_ns()
    report.samples = n
    report.achieved_rate_hz = n / max((t_end - t0) * 1e-9, 1e-9)
    if engaged_ns is not None:
        report.held_s = ((released_ns or t_end) - engaged_ns) * 1e-9
        report.lock_compression_mm = 1e3 * lock_counts / cpm  # from where the leg rested at the start
    free = [r for r in post if released_ns is not None and r["t_s"] >= (released_ns - t0) * 1e-9]
    report.free_samples = len(free)
    report.peak_speed_m_s, report.peak_accel_m_s2 = _peaks(free, cpm)
    if math.isfinite(report.peak_speed_m_s) and report.peak_speed_m_s > SENSOR_SPEED_RATING_M_S:
        report.warnings.append(
            f"peak speed {report.peak_speed_m_s:.2f} m/s is above the sensor's rating (1.0 m/s): compress the leg less"
        )
    if math.isfinite(report.peak_accel_m_s2) and report.peak_accel_m_s2 > SENSOR_ACCEL_RATING_M_S2:
        report.warnings.append(
            f"peak acceleration {report.peak_accel_m_s2 / 9.81:.1f} g is above the sensor's "
            "rating (15 g): compress the leg less"
        )
    if stalls:
        report.warnings.append(f"the read loop stalled {len(stalls)} time(s) while no clutch was engaged ({stalls[0]})")
    if report.achieved_rate_hz < 0.8 * opts.rate_hz:
        report.warnings.append(
            f"read {report.achieved_rate_hz:.0f} times a second, below --rate-hz "
            f"{opts.rate_hz:g} (the bus or Python is the limit here)"
        )
    if faults:
        report.fault, report.detail = faults[0]
        report.exit_code = 1
        events.append(
            {"t_s": round((t_end - t0) * 1e-9, 7), "event": "fault", "fault": faults[0][0], "detail": faults[0][1]}
        )
    end = {
        "event": "end",
        "t_s": round((t_end - t0) * 1e-9, 7),
        "samples": n,
        "achieved_rate_hz": round(report.achieved_rate_hz, 1),
        "outcome": report.fault or "ok",
    }
    rows = list(pre) + post
    return [header, *_merge(rows, events), end]


def _merge(rows: list[dict[str, Any]], events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Samples and events in time order (an event after the samples of its instant)."""
    out: list[dict[str, Any]] = []
    ev = sorted(events, key=lambda e: e["t_s"])
    j = 0
    for r in rows:
        while j < len(ev) and ev[j]["t_s"] < r["t_s"]:
            out.append(ev[j])
            j += 1
        out.append(r)
    out.extend(ev[j:])
    return out


def _peaks(free: list[dict[str, Any]], cpm: float) -> tuple[float, float]:
    """Peak speed (m/s) and acceleration (m/s^2) of the free motion, from positions 1 ms apart (finer steps
    would measure the count's quantisation), slow reads left out."""
    pts: list[tuple[float, float]] = []
    for r in free:
        if r["read_us"] > SLOW_READ_US:
            continue  # descheduled in the read: its instant is uncertain
        if not pts or r["t_s"] - pts[-1][0] >= 1e-3:
            pts.append((r["t_s"], r["counts"] / cpm))
    if len(pts) < 3:
        return math.nan, math.nan
    v = [((b[1] - a[1]) / (b[0] - a[0]), 0.5 * (a[0] + b[0])) for a, b in zip(pts, pts[1:])]
    acc = [abs((q[0] - p[0]) / (q[1] - p[1])) for p, q in zip(v, v[1:])]
    return max(abs(x[0]) for x in v), max(acc)


def _write(out: Path, lines: list[dict[str, Any]]) -> None:
    with atomic_file(out, option="--out") as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            for line in lines:
                f.write(json.dumps(line, separators=(",", ":")) + "\n")


__all__ = [
    "FORMAT",
    "LEG_TEST_FRAME_RATE_HZ",
    "HAND_DETECTOR",
    "LegTestOptions",
    "LegTestReport",
    "check_options",
    "run_leg_test",
]
