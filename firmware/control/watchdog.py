"""The dead-man's chain in software: a thread with its own deadlines, apart from the event loop and from the
control thread.

Each part of the firmware that must stay alive `feed`s its named deadline (the control thread at every sample,
the event loop every 10 ms). The watchdog thread wakes every `period_s`; a feed older than its timeout trips
it: `on_trip(name, detail)` runs in the watchdog thread (the app releases every clutch there and disarms),
once per stall, and `healthy` is False until every feed is fresh again. Extra `checks` (link loss) run in
the same thread, so they fire while the event loop is blocked. While healthy, `notify("WATCHDOG=1")` is sent
every `notify_every_s` (systemd's `WatchdogSec=`: a stalled firmware is restarted, and the unit's
`ExecStopPost=` releases the pins).

Release bound on a stall: the feeder's timeout + `period_s` + one switch interval of the GIL.

The watchdog thread is watched in turn: it counts its completed rounds (`rounds`), and the control thread asks
`thread_alive()` before every heartbeat toggle. No new round for `self_timeout_s` (on the watchdog's clock)
means the watchdog thread itself is blocked: the control thread then stops toggling the heartbeat (the hardware
monostable drops the clutches), releases every clutch and reports `watchdog_stalled`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class Watchdog:
    """Deadlines fed from other threads, checked by a thread of its own (`rimless-watchdog`)."""

    def __init__(
        self,
        on_trip: Callable[[str, str], None],
        *,
        period_s: float = 0.01,
        notify: Callable[[str], object] | None = None,
        notify_every_s: float = 0.0,
        clock_ns: Callable[[], int] = time.monotonic_ns,
        self_timeout_s: float = 0.25,
    ) -> None:
        self.on_trip = on_trip
        self.clock_ns = clock_ns
        self.period_s = period_s
        self.notify = notify
        self.notify_every_s = notify_every_s
        self.checks: list[Callable[[], None]] = []
        self.while_stalled: Callable[[], None] | None = None  # every round while a feed is late (outputs off)
        self.healthy = True
        self.trips = 0
        self._timeouts_ns: dict[str, int] = {}
        self._fed_ns: dict[str, int] = {}
        self._tripped: set[str] = set()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.rounds = 0  # completed rounds of checks: the evidence that the watchdog thread itself runs
        self.self_timeout_ns = int(self_timeout_s * 1e9)
        self._seen_rounds = -1  # the count `thread_alive` last saw, and when it saw it change
        self._seen_ns = 0

    def add(self, name: str, timeout_s: float) -> None:
        """A deadline `name`: fed at least every `timeout_s`, starting now."""
        self._timeouts_ns[name] = int(timeout_s * 1e9)
        self._fed_ns[name] = self.clock_ns()

    def feed(self, name: str) -> None:
        """`name` is alive now (a plain store: safe from any thread)."""
        self._fed_ns[name] = self.clock_ns()

    def start(self) -> None:
        """Start the thread."""
        self._thread = threading.Thread(target=self._run, name="rimless-watchdog", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread (and wait for it, briefly)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)

    def thread_alive(self) -> bool:
        """Has a round of checks completed within `self_timeout_s`? Asked by one thread only (the control
        thread, before each heartbeat toggle); the first call starts the count."""
        now = self.clock_ns()
        rounds = self.rounds
        if rounds != self._seen_rounds:
            self._seen_rounds, self._seen_ns = rounds, now
            return True
        return now - self._seen_ns <= self.self_timeout_ns

    def check_now(self) -> None:
        """One round of checks (the thread runs this every `period_s`); counted in `rounds` when it returns
        (or raises: a bad check is not a blocked thread)."""
        try:
            self._check_round()
        finally:
            self.rounds += 1

    def _check_round(self) -> None:
        now = self.clock_ns()
        stalled = []
        for name, timeout in self._timeouts_ns.items():
            age = now - self._fed_ns.get(name, now)
            if age > timeout:
                stalled.append(name)
                if name not in self._tripped:
                    self._tripped.add(name)
                    self.trips += 1
                    self.healthy = False
                    self.on_trip(name, f"{name} not fed for {age * 1e-9:.3f} s (deadline {timeout * 1e-9:.3f} s)")
            else:
                self._tripped.discard(name)
        self.healthy = not stalled
        if stalled and self.while_stalled is not None:
            self.while_stalled()
        for check in self.checks:
            check()

    def _run(self) -> None:
        next_notify = 0.0
        while not self._stop.wait(self.period_s):
            try:
                self.check_now()
                if self.notify is not None and self.notify_every_s > 0 and self.healthy:
                    now = time.monotonic()
                    if now >= next_notify:
                        next_notify = now + self.notify_every_s
                        self.notify("WATCHDOG=1")
            except Exception:  # noqa: BLE001 - the watchdog must outlive a bad check
                pass
