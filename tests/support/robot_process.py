"""`rimless robot ...` in a subprocess, for the tests of signals and deaths (tests/firmware/test_cli_signals.py,
test_cli_deaths.py): started on the fake robot, awaited on an event (a line it prints, a pin of its `--pin-log`
gone high, a clutch engaged in its status), stopped by a signal, and what it left read back (its exit and output,
the last level of every pin). No fixed sleeps: a wait ends on its event, on the command's end, or after
HANG_GUARD_S (a hang guard, not a bound: only a hung command takes that long, whatever the machine's load)."""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

RIMLESS = [str(Path(sys.executable).with_name("rimless"))]
#: the default config's clutch and heartbeat pins (BCM numbers, firmware/service/config.py)
CLUTCH_PINS = (17, 27, 22, 23, 24, 16, 20, 21)
HEARTBEAT_PIN = 18
#: arm at start, on leg 0 (the fake gait starts on it)
ARMED = ("--arm", "--stance-leg", "0")
#: the watchdogs at 5 s (the robot's 0.1 s and 0.25 s): a loaded test machine pauses a process for tenths of a
#: second, and a `sensor_stalled` fault disarms the fake robot for good, so that no clutch ever engages (a run at
#: load 14 waited 300 s for one); these tests are about signals, not stalls
SAMPLING = "[sampling]\nstall_timeout_s = 5.0\nloop_stall_s = 5.0\n"
#: how long a test waits for an event or an exit (a hang guard, not a bound)
HANG_GUARD_S = 300.0


def write_config(path: Path, *, log_dir: Path, commands: str = "enabled = false") -> Path:
    """A robot.toml at `path`: `commands` as the [commands] table's lines, the trial logs in `log_dir`, the relaxed
    watchdogs of SAMPLING."""
    path.write_text(f'[commands]\n{commands}\n[log]\ndir = "{log_dir}"\n{SAMPLING}')
    return path


def run_fake(config: Path, *args: str) -> list[str]:
    """The argv of `rimless robot run --fake --config CONFIG ARGS...`."""
    return [*RIMLESS, "robot", "run", "--fake", "--config", str(config), *args]


@contextlib.contextmanager
def started(argv: Sequence[str], **popen: Any) -> Iterator[subprocess.Popen[str]]:
    """The command started now (stdout and stderr piped, as text, unless `popen` says otherwise), killed on leaving
    the block if it still runs."""
    proc = subprocess.Popen(list(argv), **{"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True, **popen})
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def stop_with(proc: subprocess.Popen[str], sig: signal.Signals | None) -> tuple[str, str]:
    """Send `sig` (None: none, the command ends by itself) and wait for the end; what is left of stdout and stderr."""
    if sig is not None:
        proc.send_signal(sig)
    return proc.communicate(timeout=HANG_GUARD_S)


def wait_until(proc: subprocess.Popen[str], event: Callable[[], bool], what: str | Callable[[], str]) -> None:
    """Until `event()` holds, looked at every 20 ms (an event announced by nothing the test can block on: a file
    written, a status asked); fails at once if the command ends first, or after HANG_GUARD_S, naming `what` (or
    what `what()` says then)."""
    deadline = time.monotonic() + HANG_GUARD_S
    while not event():
        name = what if isinstance(what, str) else what()
        assert proc.poll() is None, (f"the command ended before {name}", proc.communicate())
        assert time.monotonic() < deadline, f"no {name} in {HANG_GUARD_S:g} s"
        time.sleep(0.02)


def read_stderr_until(proc: subprocess.Popen[str], done: Callable[[str], bool]) -> list[str]:
    """stderr's lines as they come, up to the first for which `done(line)` holds (blocking: the line is the
    event); fails if stderr ends first."""
    assert proc.stderr is not None
    seen: list[str] = []
    for line in proc.stderr:
        seen.append(line)
        if done(line):
            return seen
    raise AssertionError("stderr ended before the awaited line:\n" + "".join(seen))


def read_pin_log(path: Path) -> list[dict[str, Any]]:
    """The `--pin-log` records written so far (t_s, pin, level), a line still being written left out."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return []
    return [json.loads(line) for line in text.splitlines() if line.endswith("}")]


def went_high(records: list[dict[str, Any]], pins: Sequence[int] | set[int]) -> bool:
    """Whether one of `pins` went high in the pin log's `records`."""
    return any(r["pin"] in pins and r["level"] == 1 for r in records)


def last_levels(records: list[dict[str, Any]]) -> dict[int, int]:
    """The last level of every pin that ever changed, from the pin log's `records`."""
    return {r["pin"]: r["level"] for r in records}


def pin_levels(line: str) -> dict[str, str]:
    """The fake's pin histories printed at the end: '... GPIO17=010 GPIO27=0 ...' -> {'17': '010', ...}"""
    items = [w for w in line.replace(")", " ").split() if w.startswith("GPIO") and "=" in w]
    return {k[4:]: v for k, v in (w.split("=") for w in items)}
