"""Release the clutches on every signal a process can catch, for the synchronous commands.

`STOP_SIGNALS` is every signal whose default action ends the process and that Python can catch when another
process sends it: SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1/2, SIGALRM, SIGPWR, SIGVTALRM, SIGPROF, SIGIO,
SIGXCPU, SIGXFSZ, SIGSTKFLT, SIGSYS, SIGTRAP and SIGABRT (SIGPIPE is ignored by Python). SIGSEGV, SIGBUS,
SIGFPE and SIGILL are left to `faulthandler` (a Python handler would return to the faulting instruction and
spin): it prints every thread's traceback and the process dies; the heartbeat-gated enable (hardware.md,
firmware README) then drops the clutches. `robot run` releases the clutches in its own handler (`app.py`)
and stops through its event loop; the commands that
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

__all__ = ["STOP_SIGNALS", "Interrupted", "signals_held", "stop_on_signals"]

#: the state of each `stop_on_signals` block now active (the innermost last): how deep `signals_held` is, and the
#: signal it held back
_ACTIVE: list[dict[str, Any]] = []

STOP_SIGNAL_NAMES = (
    "SIGINT",
    "SIGTERM",
    "SIGHUP",
    "SIGQUIT",
    "SIGUSR1",
    "SIGUSR2",
    "SIGALRM",
    "SIGPWR",
    "SIGVTALRM",
    "SIGPROF",
    "SIGIO",
    "SIGXCPU",
    "SIGXFSZ",
    "SIGSTKFLT",
    "SIGSYS",
    "SIGTRAP",
    "SIGABRT",
)
STOP_SIGNALS = tuple(getattr(signal, n) for n in STOP_SIGNAL_NAMES if hasattr(signal, n))


def install_faulthandler() -> None:
    """Dump every thread's traceback to stderr on SIGSEGV/SIGBUS/SIGFPE/SIGILL (and SIGABRT until a stop
    handler takes it over); idempotent."""
    import faulthandler
    import sys

    if not faulthandler.is_enabled():
        with contextlib.suppress(Exception):  # stderr without a file descriptor (a test runner)
            # no sys.__stderr__ (pythonw): sys.stderr, which is what faulthandler takes for None
            faulthandler.enable(file=sys.__stderr__ or sys.stderr, all_threads=True)


@contextlib.contextmanager
def stop_on_signals(on_signal: Callable[[], None] | None = None) -> Iterator[list[int]]:
    """Within the block, a stop signal runs `on_signal` and raises `Interrupted` once; later signals
    only run `on_signal` again (the cleanup in progress is not interrupted). Inside `signals_held` the
    first signal still runs `on_signal` at once but its `Interrupted` waits for the end of that block.
    Yields the list of signals received."""
    received: list[int] = []
    previous: dict[int, Any] = {}
    if threading.current_thread() is not threading.main_thread():
        yield received  # only the main thread receives signals (and may set handlers)
        return
    state: dict[str, Any] = {"held": 0, "pending": None}

    def handler(signum: int, _frame: Any) -> None:
        if on_signal is not None:
            with contextlib.suppress(Exception):
                on_signal()
        received.append(signum)
        if len(received) == 1:
            if state["held"]:
                state["pending"] = signum
                return
            raise Interrupted(signum)

    for sig in STOP_SIGNALS:
        previous[sig] = signal.signal(sig, handler)
    _ACTIVE.append(state)
    try:
        yield received
    finally:
        _ACTIVE.remove(state)
        for sig, old in previous.items():
            with contextlib.suppress(Exception):
                signal.signal(sig, old)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Within the block, the enclosing `stop_on_signals` still releases the clutches on a stop signal at once,
    but raises its `Interrupted` only when the block ends (then, also in place of an exception the block
    raised): for a few steps that must not be cut in two, such as creating an event loop and taking hold of
    it, so that whatever they made can be closed. Outside `stop_on_signals` (or off the main thread) it
    does nothing."""
    if not _ACTIVE or threading.current_thread() is not threading.main_thread():
        yield
        return
    state = _ACTIVE[-1]
    state["held"] += 1
    try:
        yield
    finally:
        state["held"] -= 1
        pending = state["pending"]
        if not state["held"] and pending is not None:
            state["pending"] = None
            raise Interrupted(pending)
