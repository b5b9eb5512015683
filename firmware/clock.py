"""The clock seam of the control loops: `Clock` (now, sleep until a deadline), the robot's `MonotonicClock` and
the fakes' `VirtualClock`.

The sampler thread, the leg test's read loop, the fake sensor, the fake leg and the fault scenarios take a
`Clock`; on the robot it is `MonotonicClock` (sleep, then spin the last `spin_s` before the deadline). The fake
hardware of the tests and of `--fake` runs takes a `VirtualClock`: its time moves only when the loop asks for its
next deadline, so every sample is taken at its deadline exactly, whatever the machine's load (a loaded machine
makes the run slower, never different). It is paced to the wall clock (it never runs ahead of it by more than
`slack_s`, and catches up with it after a hiccup), so a `--fake` run still lasts as long on the wall clock and
its timestamps stay on the monotonic clock's scale. The watchdogs (and a bench) stay on the wall clock.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol


class Clock(Protocol):
    """Time for a control loop (ns, monotonic) and the wait for its next deadline."""

    def now_ns(self) -> int:
        """The time now (ns)."""
        ...

    def sleep_until(self, deadline_ns: int) -> None:
        """Return at `deadline_ns` (at once when it has passed)."""
        ...


class MonotonicClock:
    """The robot's clock: `time.monotonic_ns`; waits sleep (GIL released) and then spin the last `spin_s`."""

    def __init__(self, spin_s: float = 0.0003) -> None:
        self.spin_ns = int(spin_s * 1e9)

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        remaining = deadline_ns - time.monotonic_ns()
        if remaining > self.spin_ns:
            time.sleep((remaining - self.spin_ns) * 1e-9)
        while time.monotonic_ns() < deadline_ns:
            pass


class VirtualClock:
    """Time that moves only in `sleep_until` (to the deadline, exactly), starting at `start_ns` (default: the
    monotonic clock now). With `paced`, a wait sleeps on the wall clock while the virtual time is more than
    `slack_s` ahead of it (measured from the clock's creation); a loop late on the wall clock runs its samples
    back to back, each at its own virtual deadline, until it has caught up. Without `paced` it never sleeps."""

    def __init__(self, start_ns: int | None = None, *, paced: bool = True, slack_s: float = 0.002) -> None:
        self._wall0 = time.monotonic_ns()
        self._t0 = self.start_ns = self._wall0 if start_ns is None else start_ns
        self._t = self._t0
        self.paced = paced
        self.slack_ns = int(slack_s * 1e9)

    def now_ns(self) -> int:
        return self._t

    def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns <= self._t:
            return
        if self.paced:
            ahead = (deadline_ns - self._t0) - (time.monotonic_ns() - self._wall0)
            if ahead > self.slack_ns:
                time.sleep(ahead * 1e-9)
        self._t = deadline_ns


def seconds(clock: Clock) -> Callable[[], float]:
    """`clock`'s time in seconds as a callable (the time of the fakes, their trajectories and the pin log): from the
    clock's `start_ns` when it has one (a `VirtualClock`), else on its own scale. Small numbers keep the fakes'
    float arithmetic the same from run to run (seconds near 1e4 round differently with each start)."""
    start = getattr(clock, "start_ns", 0)
    return lambda: (clock.now_ns() - start) * 1e-9


def sleeper(clock: Clock) -> Callable[[float], None]:
    """A `time.sleep` on `clock` (the driver's waits)."""
    return lambda s: clock.sleep_until(clock.now_ns() + round(s * 1e9))
