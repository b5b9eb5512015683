"""One function run in a second process while the caller goes on with other work (on a machine with two or
more cores the two run at the same time).

`Background(fn, *args)` starts a fresh interpreter (multiprocessing's "spawn": nothing of the caller's threads,
progress bar or locks is copied) that runs ``fn(*args)``; `result()` waits for it and returns its value or
raises its exception (both pickled). The child ignores SIGINT from its start and writes nothing to the terminal: a Ctrl-C
reaches the caller, whose `close()` (or leaving the ``with`` block) terminates the child, so an interrupted
command still prints one line. A child that dies without an answer (killed, out of memory) raises
`BackgroundFailed` instead of leaving the caller waiting. With one core, or ``RIMLESS_NO_BACKGROUND=1`` in the
environment, ``fn`` runs in the caller's process when `result()` is asked for (the same value: the same code on
the same, pickled, inputs).

May import: the standard library, rimless.second_process.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator
from typing import Any

from rimless.second_process import second_process_allowed

POLL_S = 0.1  # how often result() checks that the child is still alive while it waits


class BackgroundFailed(RuntimeError):
    """The child process ended without sending a result (killed, crashed, out of memory)."""


def background_allowed() -> bool:
    """A second process pays only with a second core; ``RIMLESS_NO_BACKGROUND=1`` turns it off."""
    return second_process_allowed()


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT held back in this thread (delivered when the block ends) where the platform allows it."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _child(conn: Any, fn: Callable[..., Any], prepare: Callable[[], Any] | None) -> None:
    """The child's body: quiet, deaf to Ctrl-C; ``prepare()``, then the arguments from the pipe, then one
    message back (("ok", value) or ("err", exception))."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    devnull = open(os.devnull, "w")
    sys.stdout = sys.stderr = devnull
    try:
        if prepare is not None:
            prepare()
        args = conn.recv()
        msg = ("ok", fn(*args))
    except EOFError:  # the caller closed the pipe without arguments: nothing to do
        return
    except BaseException as err:  # noqa: BLE001 (sent to the caller, raised there)
        msg = ("err", err)
    try:
        conn.send(msg)
    except Exception as err:  # noqa: BLE001 (an unpicklable result or exception: say what it was)
        conn.send(("err", BackgroundFailed(f"{type(err).__name__}: {err}")))
    conn.close()


class Background:
    """``fn(*args)`` in a second process from now on; `result()` for its value (see the module doc).

    `Background.started(fn, prepare)` starts the process before the arguments exist: it imports what ``fn``
    needs and runs ``prepare()`` (e.g. loading compiled code) while the caller works; `submit(*args)` then
    hands over the arguments."""

    def __init__(
        self, fn: Callable[..., Any], *args: Any, _submit: bool = True, _prepare: Callable[[], Any] | None = None
    ) -> None:
        self._fn, self._args = fn, args
        self._proc: Any = None
        self._conn: Any = None
        self._submitted = False
        if background_allowed():
            ctx = multiprocessing.get_context("spawn")
            self._conn, child_conn = ctx.Pipe(duplex=True)
            self._proc = ctx.Process(
                target=_child,
                args=(child_conn, fn, _prepare),
                daemon=True,
                name=f"rimless-{getattr(fn, '__name__', 'background')}",
            )
            with _sigint_blocked():  # the child is deaf to Ctrl-C from its first instruction (a blocked
                self._proc.start()  # signal mask survives fork and exec); one pending here is raised after
            child_conn.close()
        if _submit:
            self.submit(*args)

    @classmethod
    def started(cls, fn: Callable[..., Any], prepare: Callable[[], Any] | None = None) -> Background:
        """The second process started now, waiting (after ``prepare()``) for `submit`."""
        return cls(fn, _submit=False, _prepare=prepare)

    def submit(self, *args: Any) -> None:
        """Hand ``args`` to ``fn`` (once)."""
        if self._submitted:
            raise RuntimeError("Background.submit: the arguments were given already")
        self._submitted, self._args = True, args
        if self._proc is not None:
            try:
                self._conn.send(args)
            except OSError:  # the child has ended already (its prepare failed): result() says why
                pass

    @property
    def in_background(self) -> bool:
        """Whether a second process runs ``fn`` (False: it runs in this process at `result()`)."""
        return self._proc is not None

    @property
    def pid(self) -> int | None:
        """The child's process id while it runs (None in this process or once closed)."""
        return self._proc.pid if self._proc is not None else None

    def result(self) -> Any:
        """Wait for ``fn(*args)``; its value, or its exception raised here."""
        if not self._submitted:
            raise RuntimeError("Background.result: no arguments submitted")
        if self._proc is None:
            return self._fn(*self._args)
        try:
            while not self._conn.poll(POLL_S):
                if not self._proc.is_alive() and not self._conn.poll(0):
                    raise BackgroundFailed(
                        f"the background process ({self._proc.name}) ended with exit code "
                        f"{self._proc.exitcode} and no result"
                    )
            kind, value = self._conn.recv()
        except EOFError:  # the child's end of the pipe closed: it has ended
            self._proc.join(timeout=5)
            raise BackgroundFailed(
                f"the background process ({self._proc.name}) ended with exit code {self._proc.exitcode} and no result"
            ) from None
        finally:
            self.close()
        if kind == "err":
            raise value
        return value

    def close(self) -> None:
        """Stop the child if it still runs (idempotent)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.is_alive():
            proc.terminate()
        proc.join(timeout=5)
        if proc.is_alive():
            proc.kill()
            proc.join()
        self._conn.close()
        self._fn, self._args = (lambda: None), ()  # result() after close() must not rerun fn here

    def __enter__(self) -> Background:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
