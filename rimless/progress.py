"""A progress bar on stderr for work longer than about two seconds.

Drawn when stderr is a terminal, `--json` or not: the bar is on stderr and never takes stdout over (with `--json`
rich does not redirect stdout into its display), so stdout stays the result (pure JSON). Where stderr is not a
terminal (pipes, CI, tests, logs) no bar is drawn: a command that prints `--json` (told by `json_out`, or seen on
the command line) says how far it got in one plain line on stderr every `PLAIN_EVERY_S` seconds
(``rimless: DESCRIPTION [done/total] (N s)``; $RIMLESS_PROGRESS_EVERY_S sets the period, 0 a line at every
update), the first after that long, so short work stays silent; without `--json` it stays quiet (a `spinner`
may print one plain line there instead). `spinner(...)` is for library work that cannot count its progress and
does not know the command's options (compiling the simulator on first use): it infers `--json` from the command
line and, inside a command's bar, shows its text in that bar instead of opening a second display.

`stage(name)` is the tests' hook: with `RIMLESS_TEST_STAGE_FILE=PATH` set, a command appends the name of each
stage it reaches to PATH (every bar or spinner it opens and every text it shows beside a bar is a stage, plus a few
named in the library, such as "calibration started"), so that a test can send its Ctrl-C when the command is
inside its work instead of after a fixed delay. Unset (always, outside the tests), it costs one lookup in
os.environ.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
from collections.abc import Iterator
from typing import Any

#: test-only: the file (or FIFO) `stage` appends the names of the stages reached to (docs/cli.md, Environment)
STAGE_FILE_ENV = "RIMLESS_TEST_STAGE_FILE"
#: the period of the plain progress lines of a `--json` command whose stderr is not a terminal, s
PLAIN_EVERY_S = 30.0
#: overrides `PLAIN_EVERY_S` (seconds; 0: a line at every update) (docs/cli.md, Environment)
PLAIN_EVERY_ENV = "RIMLESS_PROGRESS_EVERY_S"
_clock = time.monotonic  # the plain lines' clock, s (a test replaces it with a virtual one)


def stage(name: str) -> None:
    """Record that the command reached the stage `name` (one line in $RIMLESS_TEST_STAGE_FILE; nothing when that
    variable is unset). Never fails the command: a file that cannot be written, or a FIFO that no test reads
    any more (opened without blocking), is ignored."""
    path = os.environ.get(STAGE_FILE_ENV)
    if not path:
        return
    line = (" ".join(str(name).split()) + "\n").encode("utf-8", "replace")
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NONBLOCK, 0o644)
        try:
            os.write(fd, line)
        finally:
            os.close(fd)


def plain_every_s() -> float:
    """The plain lines' period, s: $RIMLESS_PROGRESS_EVERY_S when it is a number >= 0, else `PLAIN_EVERY_S`."""
    raw = os.environ.get(PLAIN_EVERY_ENV)
    try:
        every = float(raw) if raw is not None else PLAIN_EVERY_S
    except ValueError:
        return PLAIN_EVERY_S
    return every if math.isfinite(every) and every >= 0 else PLAIN_EVERY_S


class PlainLines:
    """The progress of a `--json` command whose stderr is not a terminal, as one plain line on stderr at most
    every ``every_s`` seconds of `_clock` (the first ``every_s`` after the start)."""

    def __init__(self, description: str, total: float | None, every_s: float) -> None:
        self.description, self.total, self.completed = description, total, 0.0
        self.every_s = every_s
        self._start = self._last = _clock()

    def note(self, completed: float | None, total: float | None, description: str | None, advance: float) -> None:
        """Take an update, then print the line if the period has passed since the last."""
        if description is not None:
            self.description = description
        if total is not None:
            self.total = total
        self.completed = (completed if completed is not None else self.completed) + advance
        now = _clock()
        if now - self._last < self.every_s:
            return
        self._last = now
        count = f"{self.completed:g}/{self.total:g}" if self.total is not None else ""
        count = f" [{count}]" if count and count not in self.description else ""  # "series 3/20" says it already
        print(f"rimless: {self.description}{count} ({now - self._start:.0f} s)", file=sys.stderr, flush=True)


class ProgressBar:
    """One task on a rich progress display (or `PlainLines`); every method is a no-op when the bar is quiet."""

    def __init__(self, progress: Any, task: Any, plain: PlainLines | None = None) -> None:
        self._progress = progress
        self._task = task
        self._plain = plain

    def update(
        self, completed: float | None = None, total: float | None = None, description: str | None = None
    ) -> None:
        """Set how much is done (in the bar's own units), the total, or the text beside the bar (a `stage`)."""
        if description is not None:
            stage(description)
        if self._plain is not None:
            self._plain.note(completed, total, description, 0.0)
        if self._progress is None:
            return
        kwargs: dict[str, Any] = {}
        if completed is not None:
            kwargs["completed"] = completed
        if total is not None:
            kwargs["total"] = total
        if description is not None:
            kwargs["description"] = description
        self._progress.update(self._task, **kwargs)

    def advance(self, amount: float = 1.0) -> None:
        """Count `amount` more units done."""
        if self._plain is not None:
            self._plain.note(None, None, None, amount)
        if self._progress is not None:
            self._progress.advance(self._task, amount)


_ACTIVE: list[ProgressBar] = []  # the bar open in this process, if any (rich allows one live display)


def json_requested() -> bool:
    """Whether the running command was given `--json` (for library code that does not see the options)."""
    return "--json" in sys.argv[1:]


def progress_is_shown(json_out: bool = False) -> bool:
    """Whether a progress bar would be drawn: stderr is a terminal (with `--json` too: the bar is on stderr,
    stdout stays the JSON's; `json_out` is kept for the callers and changes nothing)."""
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty())


@contextlib.contextmanager
def progress_bar(description: str, total: float | None = None, *, json_out: bool = False) -> Iterator[ProgressBar]:
    """A transient progress bar on stderr for the block; `total=None` shows a spinner and elapsed time. Where
    stderr is not a terminal, a `--json` command (``json_out``, or `--json` on the command line) gets
    `PlainLines` instead, others nothing. Opening it is a `stage` named `description`."""
    stage(description)
    as_json = json_out or json_requested()
    if not progress_is_shown():
        yield ProgressBar(None, None, PlainLines(description, total, plain_every_s()) if as_json else None)
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    columns = [
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
    ]
    if total is None:  # nothing to count: the spinner and the elapsed time say that work goes on
        columns = [SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn()]
    # with --json, stdout is not routed into the display (rich would print it on the display's stderr console)
    display = Progress(*columns, console=Console(stderr=True), transient=True, redirect_stdout=not as_json)
    with display as progress:
        bar = ProgressBar(progress, progress.add_task(description, total=total))
        _ACTIVE.append(bar)
        try:
            yield bar
        finally:
            _ACTIVE.remove(bar)


# room for a spinner's text on an 80-column line: the spinner, two spaces and the elapsed time (0:00:00) beside it
SPINNER_TEXT_WIDTH = 80 - 12


def _fit(text: str, width: int = SPINNER_TEXT_WIDTH) -> str:
    """`text` cut to `width` characters (an ellipsis last), so that the columns after it stay on the line."""
    return text if len(text) <= width else text[: width - 1] + "…"


@contextlib.contextmanager
def spinner(description: str, done: str | None = None, *, plain: str | None = None) -> Iterator[bool]:
    """A spinner with the elapsed time on stderr while the block runs, then `done` (if given, with the seconds
    appended) as one line; inside an open progress bar the description is shown in that bar. The description
    is cut to fit 80 columns with the elapsed time (SPINNER_TEXT_WIDTH). Where no spinner is drawn (stderr not
    a terminal), `plain` (if given) is printed as one line on stderr instead, before the work: a pipe, a log or
    a notebook still learns why the command is silent. Yields whether the spinner is shown. Entering it is a
    `stage` named `description`."""
    stage(description)
    if not progress_is_shown():
        if plain:
            print(plain, file=sys.stderr, flush=True)
        yield False
        return
    description = _fit(description)
    t0 = time.perf_counter()
    if _ACTIVE:
        outer = _ACTIVE[-1]
        task = outer._progress.tasks[-1] if outer._progress.tasks else None
        before = task.description if task is not None else ""
        outer.update(description=description)
        try:
            yield True
        finally:
            outer.update(description=before)
        return
    with progress_bar(description) as _bar:
        yield True
    if done:
        print(f"{done} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
