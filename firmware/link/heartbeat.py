"""PC side: keep the command link alive while the robot is armed remotely.

The robot disarms itself (fault `link_lost`) when it hears no command for `link_timeout_s` after an
`arm` from the network. `Heartbeat` pings on one authenticated connection every `period_s`,
reconnects when the connection drops, and reports changes of the robot's state.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from rimless.firmware.errors import CommandError, RobotUnreachable
from rimless.firmware.link.remote import RobotLink


class Heartbeat:
    """Ping the robot every `period_s` (s); `status_every` pings, also ask for its status."""

    def __init__(
        self,
        host: str,
        *,
        token: str,
        port: int = 9871,
        period_s: float = 0.5,
        echo: Callable[[str], None] = print,
        status_every: int = 4,
    ) -> None:
        self.host, self.port, self.token = host, port, token
        self.period_s = period_s
        self.echo = echo
        self.status_every = status_every
        self.pings = 0
        self.failures = 0
        self.last_status: dict[str, Any] | None = None
        self._stop = threading.Event()
        self._link: RobotLink | None = None
        self._state = ""
        self._last_error = ""

    def stop(self) -> None:
        """Ask `run` to return."""
        self._stop.set()

    def _beat(self) -> None:
        if self._link is None:
            self._link = RobotLink(self.host, token=self.token, port=self.port, timeout_s=max(1.0, 2 * self.period_s))
            self.echo(f"heartbeat: connected to {self.host}:{self.port}")
            self._last_error = ""
        if self.pings % self.status_every == 0:
            st = self._link.call("status")
            self.last_status = st
            faults = ",".join(sorted(st.get("faults", {}))) or "none"
            state = f"armed={st.get('armed')} faults={faults}"
            if state != self._state:
                self.echo(f"heartbeat: robot {state}")
                self._state = state
        else:
            self._link.call("ping")
        self.pings += 1

    def run(self, duration_s: float | None = None) -> None:
        """Beat until `stop()`, `duration_s`, or Ctrl-C. The first connection must succeed (else
        `RobotUnreachable`); later losses are reported and retried."""
        start = time.monotonic()
        next_t = start
        first = True
        try:
            while not self._stop.is_set() and (duration_s is None or time.monotonic() - start < duration_s):
                try:
                    self._beat()
                except (RobotUnreachable, CommandError) as err:
                    if first:
                        raise
                    self.failures += 1
                    if str(err) != self._last_error:  # say it once, not every period
                        self.echo(f"heartbeat: {err}; retrying every {self.period_s:g} s")
                        self._last_error = str(err)
                    if self._link is not None:
                        self._link.close()
                        self._link = None
                first = False
                next_t += self.period_s
                self._stop.wait(max(0.0, next_t - time.monotonic()))
        finally:
            if self._link is not None:
                self._link.close()
                self._link = None
