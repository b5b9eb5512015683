"""Logging that never blocks the caller: records go through a bounded queue to a writer thread.

A stalled stderr (a full pipe nobody reads, a frozen terminal, a hung journald) stalls only the
writer thread; the event loop, the command server and the watchdogs keep running, and records
that do not fit in the queue are dropped and counted.
"""

from __future__ import annotations

import logging
import os
import queue
import sys
import threading
from typing import TextIO

QUEUE_LEN = 1000
_STOP = object()


class DroppingQueueHandler(logging.Handler):
    """Puts formatted records in a bounded queue without ever waiting; counts what it drops."""

    def __init__(self, q: queue.Queue[object]) -> None:
        super().__init__()
        self.queue = q
        self.dropped = 0

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.queue.put_nowait(self.format(record))
        except queue.Full:
            self.dropped += 1
        except Exception:  # noqa: BLE001 - a logging problem must never reach the control path
            self.dropped += 1


class NonBlockingLog:
    """Route the root logger to `stream` through a writer thread. Use as a context manager."""

    def __init__(
        self,
        stream: TextIO | None = None,
        *,
        level: int = logging.INFO,
        queue_len: int = QUEUE_LEN,
        fmt: str = "%(asctime)s %(levelname)s %(name)s: %(message)s",
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        # The process's stderr is written with os.write on its descriptor: a writer stuck on a full pipe then
        # holds no lock of sys.stderr, so the interpreter can still flush and exit.
        self._fd: int | None = None
        if stream is None:
            try:
                self._fd = sys.stderr.fileno()
            except (AttributeError, OSError, ValueError):
                self._fd = None
        self.queue: queue.Queue[object] = queue.Queue(queue_len)
        self.handler = DroppingQueueHandler(self.queue)
        self.handler.setFormatter(logging.Formatter(fmt))
        self.level = level
        self._thread = threading.Thread(target=self._write, name="rimless-log", daemon=True)
        self._old: tuple[list[logging.Handler], int] | None = None

    @property
    def dropped(self) -> int:
        """Records dropped because the queue was full."""
        return self.handler.dropped

    def _write(self) -> None:
        while True:
            item = self.queue.get()
            if item is _STOP:
                return
            try:
                if self._fd is not None:
                    os.write(self._fd, f"{item}\n".encode(errors="replace"))
                else:
                    self.stream.write(f"{item}\n")
                    self.stream.flush()
            except Exception:  # noqa: BLE001 - a closed stderr must not kill the writer
                self.handler.dropped += 1

    def start(self) -> NonBlockingLog:
        """Install the handler on the root logger (replacing its handlers) and start the writer."""
        root = logging.getLogger()
        self._old = (list(root.handlers), root.level)
        for h in list(root.handlers):
            root.removeHandler(h)
        root.addHandler(self.handler)
        root.setLevel(self.level)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 1.0) -> None:
        """Flush what the writer can within `timeout_s`, then restore the previous handlers."""
        root = logging.getLogger()
        root.removeHandler(self.handler)
        if self._old is not None:
            for h in self._old[0]:
                root.addHandler(h)
            root.setLevel(self._old[1])
            self._old = None
        try:
            self.queue.put(_STOP, timeout=timeout_s)
        except queue.Full:
            return
        self._thread.join(timeout_s)

    def __enter__(self) -> NonBlockingLog:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.stop()
