"""The sampler thread: steady-rate sampling on absolute deadlines, commands through an inbox.

asyncio's timers round up to whole milliseconds (selectors.EpollSelector), so a steady 300 Hz to
2 kHz cannot come from `asyncio.sleep`. The control path runs in this dedicated thread instead, waiting
for each absolute deadline on its `Clock` (on the robot `MonotonicClock`: `time.sleep` until `spin_s`
before the deadline, releasing the GIL, then a short busy-wait; on the fakes a `VirtualClock`, whose
time moves only to the next deadline); every read is timestamped. A late sample never shifts later deadlines; when more than
one period late, the missed deadlines are counted and skipped (no catch-up bursts).

Commands from the asyncio side are callables put in `inbox`; the thread runs them between
samples and completes their `concurrent.futures.Future`. It never blocks on anything else.
"""

from __future__ import annotations

import concurrent.futures
import queue
import threading
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rimless.firmware.clock import Clock, MonotonicClock
from rimless.firmware.control.controller import Controller
from rimless.firmware.control.faults import Fault


@dataclass
class SamplerStats:
    """Timing statistics of one run (times in ns, on the sampler's clock)."""

    samples: int = 0
    missed_deadlines: int = 0
    started_ns: int = 0
    stopped_ns: int = 0
    cpu_s: float = 0.0


class Sampler:
    """Runs `controller.step()` at `rate_hz` in its own thread.

    :param spin_s: busy-wait this long before each deadline (s), on the default clock.
    :param max_samples: stop by itself after this many periods (None = until stopped).
    :param record_timing: keep per-sample timestamps and latencies for the bench (bounded).
    :param on_sample: called after every control step, in the thread (watchdog feed, heartbeat pin).
    :param realtime: (priority, cpu): the thread makes itself SCHED_FIFO on one CPU (`realtime.apply_realtime`).
    :param clock: the deadlines' clock (None: `MonotonicClock(spin_s)`; the fakes' `VirtualClock`).
    """

    def __init__(
        self,
        controller: Controller,
        *,
        rate_hz: float,
        spin_s: float = 0.0003,
        max_samples: int | None = None,
        record_timing: bool = False,
        timing_capacity: int = 200_000,
        on_sample: Callable[[], None] | None = None,
        realtime: tuple[int, int | None] | None = None,
        clock: Clock | None = None,
    ) -> None:
        if not 1.0 <= rate_hz <= 5000.0:
            raise ValueError(f"rate_hz must be in 1..5000, got {rate_hz}")
        self.controller = controller
        self.rate_hz = rate_hz
        self.on_sample = on_sample  # after every control step, in this thread (watchdog feed, heartbeat pin)
        self.realtime = realtime  # (SCHED_FIFO priority, CPU or -1 for the last or None), applied by the thread
        self.realtime_report: Any = None
        self.period_ns = round(1e9 / rate_hz)
        self.spin_ns = int(spin_s * 1e9)
        self.clock: Clock = clock if clock is not None else MonotonicClock(spin_s)
        self.max_samples = max_samples
        self.inbox: queue.SimpleQueue[tuple[Callable[[Controller], Any], concurrent.futures.Future[Any]]] = (
            queue.SimpleQueue()
        )
        self.stats = SamplerStats()
        self.last_sample_ns = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.done: concurrent.futures.Future[SamplerStats] = concurrent.futures.Future()
        self.record_timing = record_timing
        self._cap = timing_capacity
        self.sample_times_ns = array("q")
        self.latencies_ns = array("q")
        self.command_latencies_ns = array("q")
        self.wake_late_ns = array("q")  # sample time minus its deadline

    # --- control from other threads -------------------------------------------------------------
    def start(self) -> None:
        """Start the thread (named `rimless-sampler`)."""
        self._thread = threading.Thread(target=self._run, name="rimless-sampler", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ask the thread to stop after the current sample."""
        self._stop.set()

    def join(self, timeout_s: float | None = None) -> None:
        """Wait for the thread to end."""
        if self._thread is not None:
            self._thread.join(timeout_s)

    @property
    def running(self) -> bool:
        """True while the thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def submit(self, fn: Callable[[Controller], Any]) -> concurrent.futures.Future[Any]:
        """Run `fn(controller)` in the sampler thread between samples; returns its future."""
        fut: concurrent.futures.Future[Any] = concurrent.futures.Future()
        if not self.running:
            fut.set_exception(RuntimeError("the sampler is not running"))
            return fut
        self.inbox.put((fn, fut))
        return fut

    # --- the thread -----------------------------------------------------------------------------
    def _drain_inbox(self) -> None:
        while True:
            try:
                fn, fut = self.inbox.get_nowait()
            except queue.Empty:
                return
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                fut.set_result(fn(self.controller))
            except Exception as err:  # a refused command: the reply carries it  # noqa: BLE001
                fut.set_exception(err)

    def _run(self) -> None:
        ctl = self.controller
        stats = self.stats
        period = self.period_ns
        now_ns = self.clock.now_ns
        sleep_until = self.clock.sleep_until
        if self.realtime is not None:
            from rimless.firmware.control.realtime import apply_realtime

            self.realtime_report = apply_realtime(*self.realtime)
        cpu0 = time.thread_time()
        stats.started_ns = deadline = now_ns()
        try:
            while not self._stop.is_set():
                self._drain_inbox()
                sleep_until(deadline)  # the absolute deadline (on the robot: sleep, then spin the last bit)
                t = now_ns()
                ctl.step()
                self.last_sample_ns = t
                if self.on_sample is not None:
                    self.on_sample()
                stats.samples += 1
                if self.record_timing and len(self.sample_times_ns) < self._cap:
                    self.sample_times_ns.append(t)
                    self.wake_late_ns.append(t - deadline)
                    self.latencies_ns.append(ctl.last_latency_ns)
                    if ctl.last_had_command:
                        self.command_latencies_ns.append(ctl.last_latency_ns)
                deadline += period
                late = now_ns() - deadline
                if late > period // 2:  # the next deadline cannot be met within half a period: skip it
                    skipped = 1 + (late - period // 2) // period
                    stats.missed_deadlines += skipped
                    deadline += skipped * period
                if self.max_samples is not None and stats.samples >= self.max_samples:
                    break
        except BaseException as err:  # noqa: BLE001
            # A bug in the control path: clutches off first, then let the app see the error.
            try:
                ctl.fault(Fault.EXCEPTION, f"{type(err).__name__}: {err}")
            finally:
                self._finish(cpu0)
                if not self.done.done():
                    self.done.set_exception(err)
            return
        self._drain_inbox()
        self._finish(cpu0)
        if not self.done.done():
            self.done.set_result(stats)

    def _finish(self, cpu0: float) -> None:
        if self.realtime_report is not None:
            from rimless.firmware.control.realtime import restore_others

            restore_others(self.realtime_report)
        self.stats.stopped_ns = self.clock.now_ns()
        self.stats.cpu_s = time.thread_time() - cpu0
        # Anything still waiting in the inbox gets an answer.
        while True:
            try:
                _fn, fut = self.inbox.get_nowait()
            except queue.Empty:
                break
            if fut.set_running_or_notify_cancel():
                fut.set_exception(RuntimeError("the sampler stopped"))
