"""A command under test, watched as it runs, so that a test sends its Ctrl-C on an event and never after a delay.

`Watched` starts the command (SIGINT's default disposition in the child, as in a terminal: a test run started as
a background job has SIGINT ignored, which exec passes on), reads its stdout and stderr line by line as they come,
and reads the stages the command reaches through a FIFO named by RIMLESS_TEST_STAGE_FILE
(`rimless.progress.stage`). `wait_for(...)` blocks until a stage or a line matches (or the command ends, or a
generous timeout passes): no polling, no sleep. Then `interrupt()` and `finish()`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from rimless.progress import STAGE_FILE_ENV

#: how long a test waits for a stage by default: the first simulator command compiles for minutes on a busy
#: machine; a command that ends, or dies, before its stage stops the wait at once
STAGE_TIMEOUT_S = 900.0


@dataclass(frozen=True)
class Finished:
    """What the command left: exit code, everything it wrote on stdout and stderr, the stages it reached."""

    returncode: int
    stdout: str
    stderr: str
    stages: list[str]


class NotReached(AssertionError):
    """The command ended (or the timeout passed) before the awaited stage or line."""


class Watched:
    """A command started now with its output and its stages read as they come (see the module doc)."""

    def __init__(
        self, argv: list[str], *, cwd: Path, env: dict[str, str] | None = None, new_session: bool = False
    ) -> None:
        self._folder = Path(tempfile.mkdtemp(prefix="rimless-stages-"))  # outside `cwd`: no leftover there
        fifo = self._folder / "stages"
        os.mkfifo(fifo)
        # our reader first (so the command's non-blocking open for writing succeeds), then a writer of ours, so
        # that the reader sees no end of file between the command's stages; blocking reads in the thread
        self._rfd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
        self._wfd: int | None = os.open(fifo, os.O_WRONLY)
        os.set_blocking(self._rfd, True)
        self._cond = threading.Condition()
        self.lines: dict[str, list[str]] = {"stdout": [], "stderr": [], "stage": []}
        self._ended = {"stdout": False, "stderr": False}
        self.new_session = new_session
        self.proc = subprocess.Popen(
            argv,
            cwd=cwd,
            env={**(os.environ if env is None else env), STAGE_FILE_ENV: str(fifo)},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            start_new_session=new_session,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        assert self.proc.stdout is not None and self.proc.stderr is not None
        self._threads = [
            threading.Thread(target=self._read_stream, args=("stdout", self.proc.stdout), daemon=True),
            threading.Thread(target=self._read_stream, args=("stderr", self.proc.stderr), daemon=True),
            threading.Thread(target=self._read_stages, daemon=True),
        ]
        for t in self._threads:
            t.start()

    # ------------------------------------------------------------------ readers

    def _read_stream(self, name: str, stream: IO[str]) -> None:
        for line in stream:
            with self._cond:
                self.lines[name].append(line)
                self._cond.notify_all()
        with self._cond:
            self._ended[name] = True
            self._cond.notify_all()

    def _read_stages(self) -> None:
        buf = b""
        while True:
            try:
                chunk = os.read(self._rfd, 65536)
            except OSError:
                return
            if not chunk:  # every writer closed: ours too, in finish()
                return
            buf += chunk
            *whole, buf = buf.split(b"\n")
            with self._cond:
                self.lines["stage"].extend(w.decode("utf-8", "replace") for w in whole)
                self._cond.notify_all()

    # ------------------------------------------------------------------ events

    def _match(self, stage: str | None, stdout: str | None, stderr: str | None) -> str | None:
        if stage is not None:
            for s in self.lines["stage"]:
                if stage in s:
                    return s
        for name, text in (("stdout", stdout), ("stderr", stderr)):
            if text is not None:
                for line in self.lines[name]:
                    if text in line:
                        return line.rstrip("\n")
        return None

    def wait_for(
        self,
        *,
        stage: str | None = None,
        stdout: str | None = None,
        stderr: str | None = None,
        timeout_s: float = STAGE_TIMEOUT_S,
    ) -> str:
        """Block until the command reaches a stage whose name contains `stage`, or prints a line containing `stdout`
        (`stderr`) there; return that stage or line. `NotReached` when the command's output ended first (it
        finished or died) or after `timeout_s`."""
        found: list[str] = []

        def done() -> bool:
            hit = self._match(stage, stdout, stderr)
            if hit is not None:
                found.append(hit)
                return True
            return all(self._ended.values())

        with self._cond:
            self._cond.wait_for(done, timeout=timeout_s)
            if found:
                return found[0]
            what = " or ".join(
                f"{k} {v!r}" for k, v in (("stage", stage), ("stdout", stdout), ("stderr", stderr)) if v is not None
            )
            ended = all(self._ended.values())
            raise NotReached(
                f"{'the command ended' if ended else f'{timeout_s:g} s passed'} before {what}; stages reached: "
                f"{self.lines['stage'][-10:]}\nstderr:\n{''.join(self.lines['stderr'])[-2000:]}"
            )

    def interrupt(self) -> None:
        """A Ctrl-C: SIGINT to the command, or to its whole process group when it was started in its own."""
        if self.new_session:
            os.killpg(self.proc.pid, signal.SIGINT)
        else:
            self.proc.send_signal(signal.SIGINT)

    def finish(self, timeout_s: float = 60.0) -> Finished:
        """Wait for the command to end (`subprocess.TimeoutExpired` after `timeout_s`, the command killed)."""
        try:
            self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.kill()
            raise
        for t in self._threads[:2]:
            t.join(timeout=timeout_s)
        self.close()
        with self._cond:
            return Finished(
                self.proc.returncode,
                "".join(self.lines["stdout"]),
                "".join(self.lines["stderr"]),
                list(self.lines["stage"]),
            )

    def kill(self) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                if self.new_session:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                else:
                    self.proc.kill()
            self.proc.wait()

    def close(self) -> None:
        """Kill the command if it still runs and let go of the FIFO (its reader ends once every writer closed)."""
        self.kill()
        if self._wfd is not None:
            os.close(self._wfd)
            self._wfd = None
            self._threads[2].join(timeout=10)
            with contextlib.suppress(OSError):
                os.close(self._rfd)
            shutil.rmtree(self._folder, ignore_errors=True)

    def __enter__(self) -> Watched:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
