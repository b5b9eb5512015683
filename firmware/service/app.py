"""The asyncio application: named tasks around the sampler thread, with an orderly, safe shutdown.

Tasks: `sampler` (awaits the control thread: sensor reads, detector, clutch commands), `controller`
(routes records, watchdogs: stalled sampler and link loss), `telemetry` (UDP), `trial_log` (disk,
through `asyncio.to_thread`) and `commands` (TCP). The control path lives in the sampler thread and
never waits on the network or the disk; it hands records over through a bounded deque.

Shutdown, on SIGINT/SIGTERM/SIGHUP/SIGQUIT, `duration_s`, a fatal error or the sampler ending:
clutches off first, then the sampler thread is stopped, the last records are flushed, the tasks are
cancelled, and the hardware is closed (clutches driven off again, then released). Every step of the
shutdown runs whatever the previous one raised; the hardware is closed last, in a `finally`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import secrets
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rimless.firmware.control.controller import Controller, EventRecord, Record
from rimless.firmware.control.faults import Fault
from rimless.firmware.control.sampler import Sampler
from rimless.firmware.control.watchdog import Watchdog
from rimless.firmware.link.commands import CommandServer
from rimless.firmware.link.protocol import Command, check_token, new_boot_nonce
from rimless.firmware.link.telemetry import TelemetrySender
from rimless.firmware.service import sdnotify
from rimless.firmware.service.config import RobotConfig
from rimless.firmware.service.hardware import Hardware
from rimless.firmware.service.safety import STOP_SIGNALS, install_faulthandler
from rimless.firmware.service.triallog import TrialLog

log = logging.getLogger("rimless.robot")

COMMAND_TIMEOUT_S = 1.0
ROUTE_PERIOD_S = 0.01
WATCHDOG_PERIOD_S = 0.01  # the watchdog thread's check period
CONTROL_LOOP, EVENT_LOOP = "control loop", "event loop"  # the watchdog's deadlines
SWITCH_INTERVAL_S = 0.0005  # let the sampler thread get the GIL back quickly after its sleep


@dataclass
class RunSummary:
    """What happened in one run."""

    stop_reason: str = ""
    samples: int = 0
    missed_deadlines: int = 0
    achieved_rate_hz: float = 0.0
    clutch_commands: int = 0
    faults: list[str] = field(default_factory=list)
    trials: list[str] = field(default_factory=list)
    telemetry_sent: int = 0
    telemetry_dropped: int = 0
    error: str | None = None
    command_port: int | None = None
    log_dropped_lines: int = 0  # trial-log lines lost to failed writes (a full disk)
    log_errors: int = 0  # failed trial-log writes or fsyncs
    log_last_error: str = ""
    stderr_dropped: int = 0  # log records dropped because stderr did not keep up (set by the runner)
    realtime: dict[str, Any] | None = None  # what the control thread's real-time settings achieved


class RobotApp:
    """The firmware around one `Hardware`.

    :param command_port: overrides the config's port (0 = any free port, see `command_port`).
    :param on_ready: called (in the loop) once every task runs, with the app.
    """

    def __init__(
        self,
        cfg: RobotConfig,
        hw: Hardware,
        *,
        token: str | None = None,
        command_port: int | None = None,
        record_timing: bool = False,
        event_sink: list[EventRecord] | None = None,
        on_ready: Callable[[RobotApp], None] | None = None,
    ) -> None:
        self.cfg = cfg
        self.hw = hw
        configured, setting = (token, "the token given") if token else cfg.token_and_setting()
        self.token = configured or secrets.token_urlsafe(24)
        self.token_generated = not configured
        self.token_path: Any = None  # where a generated token was written (mode 0600), by the runner
        if cfg.commands.enabled and not self.token_generated:
            check_token(self.token, setting=setting)  # WeakToken (a ParameterError) names the setting and why
        self.controller = Controller(
            hw.channels,
            hw.clutches,
            max_hold_s=cfg.clutch.max_hold_s,
            id_check_interval_s=cfg.sampling.id_check_interval_s,
            readback_every_samples=cfg.sampling.readback_every_samples,
            clock_ns=time.monotonic_ns if hw.clock is None else hw.clock.now_ns,
        )
        self.armed_remotely = False
        self.signal_received: str | None = None
        self.sampler: Sampler | None = None
        self.record_timing = record_timing
        self.event_sink = event_sink
        self.on_ready = on_ready
        self._command_port = cfg.commands.port if command_port is None else command_port
        self.command_port: int | None = None
        self.summary = RunSummary()
        self.trial: TrialLog | None = None
        self.telemetry: TelemetrySender | None = None
        self.server: CommandServer | None = None
        self.boot = new_boot_nonce()  # this start's nonce: the reserved UDP path's challenges, the telemetry's key
        self._tel_pending: list[Record] = []
        self._log_pending: list[Record] = []
        self._stop: asyncio.Event | None = None
        # the link-loss timer's clock (s, monotonic): the robot's; a test's virtual clock moves it by hand
        self.link_clock: Callable[[], float] = time.monotonic
        self._last_command_s = self.link_clock()
        self._trial_lock: asyncio.Lock | None = None
        self.watchdog: Watchdog | None = None
        self.trial_log_write: Callable[[int, Any], int] = os.write  # the trial log's write (a fake fills the disk)
        self._log_closed = (0, 0)  # dropped lines and errors of the trials already closed
        self._log_reported = 0  # errors already reported as a log_degraded event
        self._event_seq = 0

    # --- stop -----------------------------------------------------------------------------------
    def request_stop(self, reason: str) -> None:
        """Ask the app to stop (safe from the loop thread)."""
        if not self.summary.stop_reason:
            self.summary.stop_reason = reason
        if self._stop is not None:
            self._stop.set()

    def _signal_handler(self, loop: asyncio.AbstractEventLoop) -> Callable[[int, Any], None]:
        """The handler of every stop signal: clutches off and no new engage right here, in the main thread
        between two bytecodes (so also while the event loop is blocked), then the orderly stop in the loop."""

        def handler(signum: int, _frame: Any) -> None:
            self.controller.armed = False
            with contextlib.suppress(Exception):
                self.hw.outputs_off()
            with contextlib.suppress(Exception):
                loop.call_soon_threadsafe(self._on_signal, signal.Signals(signum).name)

        return handler

    def _on_signal(self, name: str) -> None:
        # Clutches off at once (a second signal may not wait), then the orderly shutdown.
        with contextlib.suppress(Exception):
            self.hw.clutches.all_off()
        if self.signal_received is None:
            self.signal_received = name
        self.controller.outbox.append(EventRecord(self.controller.clock_ns(), "signal", {"signal": name}))
        self.request_stop(name)

    # --- main -----------------------------------------------------------------------------------
    async def run(
        self,
        *,
        duration_s: float | None = None,
        max_samples: int | None = None,
        arm: bool = False,
        handle_signals: bool = True,
        stance_leg: int | None = None,
    ) -> RunSummary:
        """Run until stopped; always ends with every clutch off and the hardware closed. `arm`: armed at start,
        naming `stance_leg` (a clutch index) as the leg on the ground, as `arm` over the link does."""
        loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._trial_lock = asyncio.Lock()
        old_switch = sys.getswitchinterval()
        signals: list[tuple[signal.Signals, Any]] = []
        tasks: list[asyncio.Task[Any]] = []
        server: CommandServer | None = None
        try:
            if handle_signals:
                install_faulthandler()
                handler = self._signal_handler(loop)
                for sig in STOP_SIGNALS:
                    signals.append((sig, signal.signal(sig, handler)))
            sys.setswitchinterval(SWITCH_INTERVAL_S)
            tcfg = self.cfg.telemetry
            if tcfg.destinations_list():
                self.telemetry = TelemetrySender(
                    tcfg.destinations_list(),
                    max_datagram_bytes=tcfg.max_datagram_bytes,
                    batch=tcfg.batch,
                    decimate=tcfg.decimate,
                    token=self.token,  # signed with this start's key: `robot listen` knows the robot by it
                    boot=self.boot,
                )
            if self.cfg.commands.enabled:
                c = self.cfg.commands
                server = CommandServer(
                    self._execute,
                    self.token,
                    host=c.bind,
                    port=self._command_port,
                    max_message_bytes=c.max_message_bytes,
                    max_connections=c.max_connections,
                    auth_timeout_s=c.auth_timeout_s,
                    idle_timeout_s=c.idle_timeout_s,
                    on_valid=self._command_seen,
                    on_disarm=self._reserved_disarm,
                    on_status=self._reserved_status,
                    boot=self.boot,
                )
                self.server = server
                self.command_port = self.summary.command_port = await server.start()
            self.sampler = Sampler(
                self.controller,
                rate_hz=self.cfg.sampling.rate_hz,
                spin_s=self.cfg.sampling.spin_s,
                max_samples=max_samples,
                record_timing=self.record_timing,
                on_sample=self._on_sample,
                realtime=(self.cfg.sampling.realtime_priority, self.cfg.sampling.realtime_cpu)
                if self.cfg.sampling.realtime
                else None,
                clock=self.hw.clock,
            )
            wd = self.watchdog = Watchdog(
                self._watchdog_trip,
                period_s=WATCHDOG_PERIOD_S,
                notify=sdnotify.notify,
                notify_every_s=sdnotify.watchdog_interval_s(),
                self_timeout_s=self.cfg.sampling.loop_stall_s,
            )
            wd.add(CONTROL_LOOP, self.cfg.sampling.stall_timeout_s)
            wd.add(EVENT_LOOP, self.cfg.sampling.loop_stall_s)
            wd.checks.append(self._check_link)
            wd.while_stalled = self._outputs_off
            if arm:
                self.controller.arm(stance_leg=stance_leg)
            self.sampler.start()
            wd.start()
            tasks = [
                asyncio.create_task(self._sampler_task(), name="sampler"),
                asyncio.create_task(self._controller_task(), name="controller"),
                asyncio.create_task(self._telemetry_task(), name="telemetry"),
                asyncio.create_task(self._trial_log_task(), name="trial_log"),
            ]
            if server is not None:
                tasks.append(asyncio.create_task(self._commands_task(), name="commands"))
            if self.on_ready is not None:
                self.on_ready(self)
            sdnotify.notify("READY=1")
            stop_wait = asyncio.create_task(self._stop.wait(), name="stop")
            done, _ = await asyncio.wait([stop_wait, *tasks], timeout=duration_s, return_when=asyncio.FIRST_COMPLETED)
            if not done:
                self.request_stop("duration")
            for t in done:
                if t is not stop_wait and not t.cancelled() and t.exception() is not None:
                    exc = t.exception()
                    self.summary.error = f"{t.get_name()}: {type(exc).__name__}: {exc}"
                    self.request_stop("error")
            stop_wait.cancel()
            self.request_stop("sampler finished")
        except BaseException as err:
            self.summary.error = self.summary.error or f"{type(err).__name__}: {err}"
            self.request_stop("error")
            raise
        finally:
            try:
                await self._shutdown(tasks, server)
            finally:
                for sig, previous in signals:
                    with contextlib.suppress(Exception):
                        signal.signal(sig, previous)
                sys.setswitchinterval(old_switch)
        return self.summary

    def _shutdown_error(self, step: str, err: BaseException) -> None:
        detail = f"shutdown ({step}): {type(err).__name__}: {err}"
        log.error("%s", detail)
        if not self.summary.error:
            self.summary.error = detail

    async def _shutdown(self, tasks: list[asyncio.Task[Any]], server: CommandServer | None) -> None:
        ctl = self.controller
        try:
            # 1. Outputs safe, whatever state the sampler is in; the watchdog has nothing left to guard.
            sdnotify.notify("STOPPING=1")
            if self.watchdog is not None:
                self.watchdog.stop()
            with contextlib.suppress(Exception):
                self.hw.outputs_off()
            # 2. Stop the control thread.
            if self.sampler is not None:
                self.sampler.stop()
                await asyncio.to_thread(self.sampler.join, 2.0)
                st = self.sampler.stats
                self.summary.samples = st.samples
                self.summary.missed_deadlines = st.missed_deadlines
                span = (st.stopped_ns - st.started_ns) * 1e-9
                self.summary.achieved_rate_hz = st.samples / span if span > 0 else 0.0
                if self.sampler.realtime_report is not None:
                    self.summary.realtime = self.sampler.realtime_report.to_json()
            with contextlib.suppress(Exception):
                ctl.safe_stop(self.summary.stop_reason or "stop")
            if self.summary.error:
                ctl.fault(Fault.EXCEPTION, self.summary.error)
            self.summary.clutch_commands = ctl.clutch_commands
            # 3. Cancel the tasks, then flush what is left; each step runs whatever the others raised.
            for t in tasks:
                t.cancel()
            for t in tasks:
                with contextlib.suppress(BaseException):
                    await t
            if server is not None:
                try:
                    await server.close()
                except Exception as err:  # noqa: BLE001
                    self._shutdown_error("commands", err)
            try:
                self._route()
            except Exception as err:  # noqa: BLE001
                self._shutdown_error("routing", err)
            if self.telemetry is not None:
                try:
                    self.telemetry.send(self._tel_pending)
                except Exception as err:  # noqa: BLE001
                    self._shutdown_error("telemetry", err)
                finally:
                    self._tel_pending = []
                    self.summary.telemetry_sent = self.telemetry.sent_datagrams
                    self.summary.telemetry_dropped = self.telemetry.dropped_datagrams
                    with contextlib.suppress(Exception):
                        self.telemetry.close()
            if self.trial is not None:
                try:
                    self.trial.append(self._log_pending)
                    self.trial.append([EventRecord(self.controller.clock_ns(), "trial_stop", {"reason": "shutdown"})])
                    self.trial.close()
                    self._account_log(closed=True)
                except Exception as err:  # noqa: BLE001
                    self._shutdown_error("trial log", err)
                finally:
                    self._log_pending = []
                    self.trial = None
        finally:
            # 4. Hardware: clutches off again and released, then buses. Always.
            self.hw.close()

    # --- tasks ----------------------------------------------------------------------------------
    async def _sampler_task(self) -> None:
        assert self.sampler is not None
        done = self.sampler.done
        # Poll rather than wrap_future: cancelling a wrapper would cancel the thread's future.
        while not done.done():
            await asyncio.sleep(ROUTE_PERIOD_S)
        done.result()

    def _route(self) -> None:
        """Move records from the control thread's deque to the telemetry and trial-log buffers."""
        out = self.controller.outbox
        while out:
            try:
                rec = out.popleft()
            except IndexError:
                break
            if isinstance(rec, EventRecord):
                self._event_seq += 1
                rec.fields["event_seq"] = self._event_seq  # a lost event (a fault) shows as a gap
            if self.telemetry is not None:
                self._tel_pending.append(rec)
            if self.trial is not None:
                self._log_pending.append(rec)
            if isinstance(rec, EventRecord) and self.event_sink is not None:
                self.event_sink.append(rec)
            if isinstance(rec, EventRecord) and rec.name == "fault":
                self.summary.faults.append(rec.fields["fault"])
                log.warning("fault %s: %s", rec.fields["fault"], rec.fields.get("detail"))

    async def _controller_task(self) -> None:
        assert self.sampler is not None and self.watchdog is not None
        wd = self.watchdog
        while True:
            await asyncio.sleep(ROUTE_PERIOD_S)
            wd.feed(EVENT_LOOP)
            self._route()

    # --- the dead-man's chain (watchdog thread and control thread) ----------------------------------
    def _on_sample(self) -> None:
        """After every control step, in the control thread: feed the watchdog; toggle the heartbeat pin while
        the watchdog sees every part alive (a stall stops the toggling, and the hardware monostable drops) and
        the watchdog thread itself is seen alive (its rounds advance: else every clutch off, `watchdog_stalled`)."""
        wd = self.watchdog
        if wd is not None:
            wd.feed(CONTROL_LOOP)
            if not wd.thread_alive():
                self.armed_remotely = False
                self.controller.fault(  # in the control thread: all clutches off, disarmed, reported once
                    Fault.WATCHDOG_STALLED,
                    f"the watchdog thread completed no round for {wd.self_timeout_ns * 1e-9:g} s: heartbeat stopped",
                )
                return
            if wd.healthy and self.hw.heartbeat is not None:
                self.hw.heartbeat.toggle()

    def _outputs_off(self) -> None:
        self.controller.armed = False
        with contextlib.suppress(Exception):
            if self.hw.clutches.engaged():
                self.hw.clutches.all_off()

    def _watchdog_trip(self, name: str, detail: str) -> None:
        """A stalled event loop or control thread (in the watchdog thread): every clutch off and disarmed here,
        the fault reported once."""
        self.controller.armed = False
        with contextlib.suppress(Exception):
            self.hw.clutches.all_off()
        self.armed_remotely = False
        fault = Fault.SENSOR_STALLED if name == CONTROL_LOOP else Fault.LOOP_STALLED
        self.controller.fault(fault, detail)

    def _check_link(self) -> None:
        """Link loss, checked in the watchdog thread so that it fires while the event loop is blocked."""
        link_s = self.cfg.commands.link_timeout_s
        ctl = self.controller
        if link_s > 0 and ctl.armed and self.armed_remotely and self.link_clock() - self._last_command_s > link_s:
            ctl.armed = False
            self.armed_remotely = False
            with contextlib.suppress(Exception):
                self.hw.clutches.all_off()
            ctl.fault(Fault.LINK_LOST, f"no command or heartbeat for {link_s} s")

    async def _telemetry_task(self) -> None:
        period = self.cfg.telemetry.period_s
        while True:
            await asyncio.sleep(period)
            if self.telemetry is not None and self._tel_pending:
                pending, self._tel_pending = self._tel_pending, []
                try:
                    self.telemetry.send(pending)
                except Exception as err:  # noqa: BLE001 - telemetry must never stop the robot
                    self.telemetry.dropped_datagrams += 1
                    log.error("telemetry: %s: %s", type(err).__name__, err)

    async def _trial_log_task(self) -> None:
        period = self.cfg.log.flush_interval_s
        assert self._trial_lock is not None
        while True:
            await asyncio.sleep(period)
            async with self._trial_lock:
                if self.trial is not None and self._log_pending:
                    pending, self._log_pending = self._log_pending, []
                    self.trial.append(pending)
                    await asyncio.to_thread(self.trial.sync)
                    self._account_log()

    def _account_log(self, *, closed: bool = False) -> None:
        """Trial-log failures into the summary; the first failure of a run of them becomes a `log_degraded`
        event (telemetry, and the log itself when it can write again). Logging degrades, control goes on."""
        trial = self.trial
        if trial is None:
            return
        dropped, errors = self._log_closed
        self.summary.log_dropped_lines = dropped + trial.dropped_lines
        self.summary.log_errors = errors + trial.errors
        if trial.last_error:
            self.summary.log_last_error = trial.last_error
        if self.summary.log_errors > self._log_reported:
            if self._log_reported == 0 or closed:
                log.warning("trial log: %s (%d lines dropped)", trial.last_error, self.summary.log_dropped_lines)
            if self._log_reported == 0:
                self.controller.outbox.append(
                    EventRecord(
                        self.controller.clock_ns(),
                        "log_degraded",
                        {"error": trial.last_error, "dropped_lines": self.summary.log_dropped_lines},
                    )
                )
            self._log_reported = self.summary.log_errors
        if closed:
            self._log_closed = (self.summary.log_dropped_lines, self.summary.log_errors)

    async def _commands_task(self) -> None:
        await asyncio.Event().wait()  # the server runs on its own; this task marks its lifetime

    # --- commands -------------------------------------------------------------------------------
    def _reserved_disarm(self) -> None:
        """A disarm over the reserved UDP path: clutches off at once, then the control thread."""
        self.armed_remotely = False
        self.controller.armed = False  # no new engage from here on (a bool store is atomic)
        with contextlib.suppress(Exception):
            self.hw.clutches.all_off()
        if self.sampler is not None and self.sampler.running:
            self.sampler.submit(lambda c: c.disarm("reserved path"))  # the event, and off once more

    def _reserved_status(self) -> dict[str, Any]:
        """A small status for the reserved UDP path (read from its thread: copies only)."""
        ctl = self.controller
        return {
            "armed": ctl.armed,
            "faults": sorted(f.value for f in list(ctl.active_faults)),
            "engaged": self.hw.clutches.engaged(),
            "samples": ctl.samples,
        }

    def _command_seen(self) -> None:
        self._last_command_s = self.link_clock()

    async def _in_sampler(self, fn: Callable[[Controller], Any]) -> Any:
        assert self.sampler is not None
        try:
            return await asyncio.wait_for(asyncio.wrap_future(self.sampler.submit(fn)), COMMAND_TIMEOUT_S)
        except TimeoutError:
            raise RuntimeError("the control loop did not answer in time") from None

    async def _execute(self, cmd: Command) -> dict[str, Any]:
        if cmd.cmd == "ping":
            return {"pong": True}
        if cmd.cmd == "status":
            status = await self._in_sampler(lambda c: c.status())
            assert self.sampler is not None
            status.update(
                rate_hz=self.cfg.sampling.rate_hz,
                missed_deadlines=self.sampler.stats.missed_deadlines,
                trial=None if self.trial is None else str(self.trial.path),
                log={
                    "dropped_lines": self.summary.log_dropped_lines,
                    "errors": self.summary.log_errors,
                    "last_error": self.summary.log_last_error,
                },
                params={k: getattr(self.controller.params(), k) for k in self.controller.params().__slots__},
                link={
                    "timeout_s": self.cfg.commands.link_timeout_s,
                    "armed_remotely": self.armed_remotely,
                    "connections": 0 if self.server is None else self.server.connections,
                },
            )
            return status
        if cmd.cmd == "arm":
            leg = cmd.args.get("stance_leg")
            if leg is not None and (isinstance(leg, bool) or not isinstance(leg, int)):
                raise ValueError(f"stance_leg must be a clutch index (integer), got {leg!r}")
            result = await self._in_sampler(lambda c: c.arm(stance_leg=leg))
            self.armed_remotely = True
            self._last_command_s = self.link_clock()
            result["link_timeout_s"] = self.cfg.commands.link_timeout_s
            return result
        if cmd.cmd == "disarm":
            self.armed_remotely = False
            self.hw.clutches.all_off()  # at once, even if the control loop is not answering
            return await self._in_sampler(lambda c: c.disarm())
        if cmd.cmd == "set":
            name, value = cmd.args["name"], cmd.args["value"]
            if not isinstance(name, str):
                raise ValueError("set: name must be a string")
            return await self._in_sampler(lambda c: c.set_param(name, value))
        if cmd.cmd == "trial_start":
            return await self.start_trial(cmd.args.get("name", "trial"))
        if cmd.cmd == "trial_stop":
            return await self.stop_trial()
        raise ValueError(f"unhandled command {cmd.cmd}")  # pragma: no cover - parse_command forbids it

    async def start_trial(self, name: Any) -> dict[str, Any]:
        """Start a trial log named `name` (the `trial_start` command); returns its path. Needs the loop running."""
        assert self._trial_lock is not None
        if not isinstance(name, str):
            raise ValueError("trial name must be a string")
        async with self._trial_lock:
            if self.trial is not None:
                raise ValueError(f"a trial is already running ({self.trial.path.name})")
            header = {
                "rate_hz": self.cfg.sampling.rate_hz,
                "detector": _params_dict(self.controller),
                "legs": [list(s.legs) for s in self.cfg.sensors],
                "clutch_pins": list(self.cfg.clutch.pins),
            }
            trial = await asyncio.to_thread(TrialLog, self.cfg.log.dir, name, header, write=self.trial_log_write)
            self._route()  # records from before the start do not belong to the trial
            self.trial = trial
            self._log_pending = [EventRecord(self.controller.clock_ns(), "trial_start", {"trial": name})]
            self.summary.trials.append(str(trial.path))
            return {"path": str(trial.path)}

    async def stop_trial(self) -> dict[str, Any]:
        """Stop the running trial log (the `trial_stop` command); returns its path and line count."""
        assert self._trial_lock is not None
        async with self._trial_lock:
            if self.trial is None:
                raise ValueError("no trial is running")
            self._route()
            trial, self.trial = self.trial, None
            trial.append(self._log_pending)
            trial.append([EventRecord(self.controller.clock_ns(), "trial_stop", {})])
            self._log_pending = []
            await asyncio.to_thread(trial.close)
            self.trial = trial
            self._account_log(closed=True)
            self.trial = None
            return {"path": str(trial.path), "lines": trial.lines, "dropped_lines": trial.dropped_lines}


def _params_dict(ctl: Controller) -> dict[str, Any]:
    p = ctl.params()
    return {k: getattr(p, k) for k in p.__slots__}
