"""`rimless robot run` as a library call: build the hardware, run the app until a stop, and say how it ended.

`run_robot` owns the fail-safes around the event loop: a stop signal before the loop runs (or after it)
releases every clutch at once and closes the hardware; inside the loop `RobotApp` handles the signals
itself. The exit code follows the shell's conventions (`RunOutcome.exit_code`); the command prints.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import signal
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from rimless.errors import ParameterError
from rimless.firmware.clock import VirtualClock, seconds
from rimless.firmware.drivers.fake_walk import airborne_locks
from rimless.firmware.drivers.gpio import PinLog, pin_histories
from rimless.firmware.errors import CommandError, Interrupted, SensorError
from rimless.firmware.service.app import RobotApp, RunSummary
from rimless.firmware.service.config import RobotConfig, decide_realtime, load_config, with_realtime
from rimless.firmware.service.hardware import Hardware, build_fake, build_real
from rimless.firmware.service.logsetup import NonBlockingLog
from rimless.firmware.service.safety import signals_held, stop_on_signals
from rimless.firmware.service.scenarios import Scenario, inject, on_ready, scenario

EXIT_OK = 0
EXIT_FIRMWARE_FAULT = 1  # an error in the firmware itself (the summary says which)


@dataclass
class RunOutcome:
    """How a run ended.

    `summary` is None when a stop signal (`signal`) came before the event loop ran (`before_start`);
    `fake_pins` holds the mock clutch pins' level histories with `fake` ("GPIO17=010 ...").
    """

    fake: bool
    summary: RunSummary | None
    signal: str | None = None
    before_start: bool = False
    fake_pins: str = ""
    fake_fault: str | None = None
    engages: int | None = None  # clutch engages seen on the mock pins (fake)
    airborne_leg_locks: int | None = None  # of those, on a leg the fake walk's truth has in the air

    def to_json(self) -> dict:
        """The summary `rimless robot run --json` prints."""
        s = self.summary
        out: dict = {"fake": self.fake, "signal": self.signal, "exit_code": self.exit_code}
        if s is not None:
            out.update(dataclasses.asdict(s))
        if self.fake:
            out.update(fake_fault=self.fake_fault, engages=self.engages, airborne_leg_locks=self.airborne_leg_locks)
        return out

    @property
    def exit_code(self) -> int:
        """0 after the duration or SIGTERM (a service stop), 1 after a fault in the firmware itself,
        128 + n after another signal n (130 for Ctrl-C)."""
        if self.before_start:
            return EXIT_OK if self.signal in (None, "SIGTERM") else 128 + int(getattr(signal, str(self.signal)))
        if self.summary is not None and self.summary.error:
            return EXIT_FIRMWARE_FAULT
        if self.signal is not None and self.signal != "SIGTERM":
            return 128 + int(getattr(signal, self.signal))
        return EXIT_OK


def write_private_token(token: str) -> Path:
    """Write a generated token to a new private file (mode 0600) in $XDG_RUNTIME_DIR or the temporary directory,
    so that it is never printed; returns its path."""
    import os
    import tempfile

    base = os.environ.get("XDG_RUNTIME_DIR") or None
    fd, name = tempfile.mkstemp(prefix="rimless-token-", dir=base)
    try:
        os.write(fd, (token + "\n").encode())
    finally:
        os.close(fd)
    return Path(name)


def with_telemetry(cfg: RobotConfig, destinations: Sequence[str]) -> RobotConfig:
    """`cfg` sending telemetry also to each "host:port" of `destinations` (already checked)."""
    if not destinations:
        return cfg
    return dataclasses.replace(
        cfg, telemetry=dataclasses.replace(cfg.telemetry, destinations=cfg.telemetry.destinations + tuple(destinations))
    )


def run_robot(
    config: RobotConfig | Path | None = None,
    *,
    telemetry: Sequence[str] = (),
    fake: bool = False,
    duration_s: float | None = None,
    arm: bool = False,
    on_start: Callable[[RobotApp], None] | None = None,
    on_running: Callable[[RobotApp], None] | None = None,
    log_level: int = logging.INFO,
    fake_fault: str | None = None,
    pin_log: Path | None = None,
    realtime: bool = False,
    stance_leg: int | None = None,
) -> RunOutcome:
    """Run the firmware until a stop signal or `duration_s`.

    `config` is a `RobotConfig` or the robot.toml to load (None: the defaults); `telemetry` adds "host:port"
    destinations (already checked); `fake` runs on the fake sensors and mock pins. `on_start(app)` is called
    once the app exists, before its loop starts (to show the token); `on_running(app)` in the loop once every
    task runs and the app handles the stop signals itself (a Ctrl-C from then on stops the firmware's loop,
    with its summary). Every clutch is off and the hardware closed on every path. Real time: `realtime`
    (--realtime), else `[sampling] realtime`, else on when systemd started this process
    (`config.decide_realtime`; the reason in `cfg.sampling.realtime_why`). With `fake`, `fake_fault` names a
    scenario of `scenarios.FAKE_FAULTS` and `pin_log` a JSON Lines file receiving every mock pin change. Raises
    `ConfigError` for a bad robot.toml, `CommandError` when a sensor cannot be opened or a socket cannot be
    bound, `ParameterError` when a telemetry host cannot be resolved. `arm` arms at start naming `stance_leg`
    (the clutch index of the leg on the ground; `check_arm_at_start`: a `ParameterError` when a sensor counting
    legs needs it and it is missing, or it is given without `arm`).
    """
    if not fake and (fake_fault is not None or pin_log is not None):
        raise ParameterError("--fake-fault and --pin-log need --fake")
    try:
        # the fakes run on a virtual clock paced to the wall clock: every deadline sampled whatever the load
        sc = scenario(fake_fault, clock=VirtualClock()) if fake else None
    except ValueError as err:
        raise ParameterError(f"--fake-fault: {err}") from None
    state: dict[str, Hardware | RunSummary] = {}

    def release_now() -> None:
        hw = state.get("hw")
        if isinstance(hw, Hardware):
            hw.clutches.all_off()

    try:
        with stop_on_signals(release_now):
            cfg = config if isinstance(config, RobotConfig) else load_config(config)
            source = str(config) if config is not None and not isinstance(config, RobotConfig) else "the configuration"
            cfg = with_realtime(cfg, decide_realtime(cfg.sampling, flag=realtime, source=source))
            return _run(
                with_telemetry(cfg, telemetry),
                state,
                sc,
                duration_s,
                arm,
                (on_start, on_running),
                log_level,
                pin_log,
                stance_leg,
            )
    except Interrupted as sig:  # before or after the event loop ran: the hardware is closed by now
        hw = state.get("hw")
        if isinstance(hw, Hardware):
            hw.close()
        ran = state.get("summary")
        if isinstance(ran, RunSummary):  # after the loop: its summary stands, the signal ends the command
            return RunOutcome(fake, ran, sig.name)
        return RunOutcome(fake, None, sig.name, before_start=True)


def _run(
    cfg: RobotConfig,
    state: dict[str, Hardware | RunSummary],
    sc: Scenario | None,
    duration_s: float | None,
    arm: bool,
    callbacks: tuple[Callable[[RobotApp], None] | None, Callable[[RobotApp], None] | None],
    log_level: int,
    pin_log_path: Path | None,
    stance_leg: int | None = None,
) -> RunOutcome:
    check_arm_at_start(cfg, arm, stance_leg)
    fake = sc is not None
    pins_log: PinLog | None = None
    try:
        if sc is not None:
            clock = sc.timeline.clock
            try:
                pins_log = PinLog(pin_log_path, clock=seconds(clock))  # the engages on the walk's clock
            except OSError as err:
                raise ParameterError(f"--pin-log {pin_log_path}: {err.strerror or err}") from None
            hw = build_fake(cfg, trajectory=sc.motion, pin_log=pins_log, clock=clock)
            # the virtual time moves no more until the sampler's first deadline: the walk starts there
            sc.timeline.start()
            inject(sc, hw.sensors, hw.fakes)
        else:
            hw = build_real(cfg)
    except SensorError as err:
        raise CommandError(f"sensor: {err}") from None
    state["hw"] = hw
    on_start, on_running = callbacks

    def ready(app: RobotApp) -> None:
        if sc is not None:
            on_ready(sc, app)
        if on_running is not None:
            on_running(app)

    try:
        robot = RobotApp(cfg, hw, on_ready=ready)
        if robot.token_generated and cfg.commands.enabled:
            robot.token_path = write_private_token(robot.token)
        if on_start is not None:
            on_start(robot)
    except BaseException:
        hw.close()
        raise
    try:
        with NonBlockingLog(level=log_level) as logs:
            summary = _run_loop(robot, duration_s, arm, stance_leg)
            state["summary"] = summary
            summary.stderr_dropped = logs.dropped
    except OSError as err:
        raise CommandError(f"cannot start: {err}") from None
    except ValueError as err:  # a telemetry host that cannot be resolved
        raise ParameterError(f"cannot start: {err}") from None
    finally:
        if robot.token_path is not None:
            robot.token_path.unlink(missing_ok=True)
    pins = pin_histories(hw.pin_factory, cfg.clutch.pins) if fake and hw.pin_factory is not None else ""
    outcome = RunOutcome(fake, summary, robot.signal_received, fake_pins=pins)
    if sc is not None and pins_log is not None:
        pins_log.close()
        on = 1 if cfg.clutch.active_high else 0
        engages = sorted(
            (t, leg)
            for leg, pin in enumerate(cfg.clutch.pins)
            for t, p, level in pins_log.transitions
            if p == pin and level == on
        )
        outcome.fake_fault, outcome.engages = None if sc.name == "none" else sc.name, len(engages)
        # the walk's truth (one sensor counting its legs); an app that never ran never walked
        walk = sc.walk or dataclasses.replace(sc.template, start_s=math.inf)
        if len(cfg.sensors) == 1:
            outcome.airborne_leg_locks = len(
                airborne_locks(walk, engages, cfg.sensors[0].legs, cfg.clutch.start_leg_index + sc.start_leg_offset)
            )
    return outcome


def _run_loop(robot: RobotApp, duration_s: float | None, arm: bool, stance_leg: int | None) -> RunSummary:
    """``robot.run`` in an event loop of its own that is closed here on every path, as `asyncio.run` does
    (the remaining tasks cancelled, async generators and the default executor shut down), also when a stop
    signal's `Interrupted` lands while the loop is being made or set up: `asyncio.run` then leaves its new
    loop unclosed, and its ``__del__`` closes it later, wherever the garbage collector or the interpreter's
    shutdown happens to run (a traceback on stderr after the "stopped" line was seen once, 2026-11-27). The
    loop is made with the signal held (`signals_held`: the clutches are still released at once)."""
    loop = None
    try:
        with signals_held():  # a stop signal now raises once `loop` is ours to close
            loop = asyncio.new_event_loop()
        coro = robot.run(duration_s=duration_s, arm=arm, stance_leg=stance_leg)
        try:
            with asyncio.Runner(loop_factory=lambda: loop) as runner:
                return runner.run(coro)
        finally:
            coro.close()  # never awaited when the signal came before the loop ran it (no warning then)
    finally:
        if loop is not None and not loop.is_closed():
            loop.close()


def check_arm_at_start(cfg: RobotConfig, arm: bool, stance_leg: int | None) -> None:
    """Refuse (`ParameterError`, naming --stance-leg) arming at start without naming the leg on the ground when
    a sensor counts legs and `named_stance_required` is on (it would arm and never lock: refused, so that the
    operator does not take a robot that cannot lock for one that is walking), a `stance_leg` without `arm`, and
    a `stance_leg` no sensor watches."""
    if stance_leg is not None and not arm:
        raise ParameterError(
            "--stance-leg names the leg on the ground at arm: add --arm (or name it later: "
            "rimless robot arm --stance-leg K)"
        )
    if not arm:
        return
    if stance_leg is None:
        counted = [s.legs for s in cfg.sensors if len(s.legs) > 1]
        if counted and cfg.detector.named_stance_required:
            raise ParameterError(
                f"--arm needs --stance-leg K, the clutch index of the leg on the ground now: one sensor counting "
                f"legs {', '.join(map(str, counted[0]))} cannot tell which one stands "
                "([detector] named_stance_required = 1)"
            )
    elif not any(stance_leg in s.legs for s in cfg.sensors):
        watched = sorted({leg for s in cfg.sensors for leg in s.legs})
        raise ParameterError(
            f"--stance-leg {stance_leg}: not a leg any [[sensor]] watches (legs {', '.join(map(str, watched))})"
        )
