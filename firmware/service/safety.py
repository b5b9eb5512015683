"""Release the clutches on every signal a process can catch, for the synchronous commands.

`robot run` handles SIGINT/SIGTERM/SIGHUP/SIGQUIT in its event loop (`app.py`); the commands that
drive pins without an event loop (`robot check`, `robot release`, and `run` before its loop starts)
wrap their work in `stop_on_signals`: the first signal calls `on_signal` (clutches off) at once, then
raises `Interrupted` so that the `finally` blocks close the hardware. SIGKILL, a crash or a power
cut cannot be caught: `rimless robot release` in the systemd unit's `ExecStopPost=` and a pull-down
at each MOSFET module input cover those.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from typing import Any

from rimless.firmware.errors import Interrupted

__all__ = ["STOP_SIGNALS", "Interrupted", "stop_on_signals"]

STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT") if hasattr(signal, n))


@contextlib.contextmanager
def stop_on_signals(on_signal: Callable[[], None] | None = None) -> Iterator[list[int]]:
    """Within the block, a stop signal runs `on_signal` and raises `Interrupted` once; later signals
    only run `on_signal` again (the cleanup in progress is not interrupted). Yields the list of
    signals received."""
    received: list[int] = []
    previous: dict[int, Any] = {}
    if threading.current_thread() is not threading.main_thread():
        yield received  # only the main thread receives signals (and may set handlers)
        return

    def handler(signum: int, _frame: Any) -> None:
        if on_signal is not None:
            with contextlib.suppress(Exception):
                on_signal()
        received.append(signum)
        if len(received) == 1:
            raise Interrupted(signum)

    for sig in STOP_SIGNALS:
        previous[sig] = signal.signal(sig, handler)
    try:
        yield received
    finally:
        for sig, old in previous.items():
            with contextlib.suppress(Exception):
                signal.signal(sig, old)
