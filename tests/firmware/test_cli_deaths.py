"""Every catchable terminating signal leaves every pin low, read from `--pin-log` outside the process.
Fails on today's main: SIGUSR1/2, SIGALRM, SIGPWR, SIGVTALRM, SIGPROF, SIGIO, ... were not handled (the
process died with its pins as they were), and there was no --pin-log."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rimless.firmware.service.safety import STOP_SIGNALS

RIMLESS = [str(Path(sys.executable).with_name("rimless"))]
CLUTCH_PINS = {17, 27, 22, 23, 24, 16, 20, 21}
HEARTBEAT = 18
OLD = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT}
# the watchdogs at 5 s (the robot's 0.1 s and 0.25 s): a test machine at load 14 pauses a process for tenths of a
# second, and a `sensor_stalled` fault disarms it for good (these tests are about signals, not stalls)
SAMPLING = "[sampling]\nstall_timeout_s = 5.0\nloop_stall_s = 5.0\n"
#: how long a test waits for a process that should end by itself (a hang guard, not a bound: only a hung process
#: takes this long, whatever the machine's load)
HANG_GUARD_S = 300.0


def read_log(path: Path) -> list[dict]:
    try:
        text = path.read_text()
    except FileNotFoundError:
        return []
    return [json.loads(line) for line in text.splitlines() if line.endswith("}")]


def start(tmp_path: Path, name: str) -> tuple[subprocess.Popen, Path]:
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text(f'[commands]\nenabled = false\n[log]\ndir = "{tmp_path}"\n{SAMPLING}')
    log = tmp_path / f"{name}.jsonl"
    proc = subprocess.Popen(
        [
            *RIMLESS,
            "robot",
            "run",
            "--fake",
            "--arm",
            "--stance-leg",
            "0",
            "--config",
            str(cfg),
            "--duration-s",
            "90",
            "--pin-log",
            str(log),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return proc, log


def wait_for(proc: subprocess.Popen, log: Path, pins: set[int], timeout_s: float = HANG_GUARD_S) -> None:
    """Until one of `pins` went high (the timeout is a hang guard: several processes start at once)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if any(r["pin"] in pins and r["level"] == 1 for r in read_log(log)):
            return
        time.sleep(0.02)
    raise AssertionError(f"no pin of {sorted(pins)} went high in {timeout_s} s")


def finish(proc: subprocess.Popen, log: Path, sig: signal.Signals) -> None:
    try:
        _, err = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    expected = 0 if sig == signal.SIGTERM else 128 + sig
    assert proc.returncode == expected, (sig.name, proc.returncode, err)
    assert "Traceback" not in err, err
    last: dict[int, int] = {}
    for rec in read_log(log):
        last[rec["pin"]] = rec["level"]
    assert all(level == 0 for level in last.values()), (sig.name, last)


@pytest.mark.slow
@pytest.mark.parametrize("batch", [0, 1, 2])
def test_every_catchable_terminating_signal_leaves_every_pin_low(tmp_path, batch) -> None:
    """The new signals, a batch at a time (bounded: at most 6 processes at once). The first of each batch waits
    for a clutch engaged, the others for the firmware running (the heartbeat toggling)."""
    new = [s for s in STOP_SIGNALS if s not in OLD]
    assert {"SIGUSR1", "SIGUSR2", "SIGALRM", "SIGPWR", "SIGVTALRM", "SIGPROF", "SIGIO"} <= {s.name for s in new}
    sigs = new[batch::3]
    procs = [(sig, *start(tmp_path, sig.name)) for sig in sigs]
    try:
        for i, (sig, proc, log) in enumerate(procs):
            wait_for(proc, log, CLUTCH_PINS if i == 0 else {HEARTBEAT})
            proc.send_signal(sig)
        for sig, proc, log in procs:
            finish(proc, log, sig)
    finally:
        for _sig, proc, _log in procs:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    engaged_first = read_log(procs[0][2])
    assert any(r["pin"] in CLUTCH_PINS and r["level"] == 1 for r in engaged_first)


@pytest.mark.slow
def test_a_blocked_stderr_holds_up_neither_start_nor_exit(tmp_path) -> None:
    """stderr is a pipe already full that nobody reads (a hung terminal or journal). Fails on today's main: the
    first status line blocked start-up, and the exit waited on stderr (the unit then SIGKILLs it). On events,
    not times: nobody reads the pipe before the process has exited, so a start-up or an exit that waited on
    stderr would wait for ever (the hang guard then kills it and the test fails); the time is printed only."""
    r, w = os.pipe()
    os.set_blocking(w, False)
    try:
        while True:
            os.write(w, b"x" * 4096)
    except BlockingIOError:
        pass
    os.set_blocking(w, True)
    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nenabled = false\n[log]\ndir = "{tmp_path}"\n{SAMPLING}')
    log = tmp_path / "pins.jsonl"
    t0 = time.monotonic()
    proc = subprocess.Popen(
        [
            *RIMLESS,
            "robot",
            "run",
            "--fake",
            "--arm",
            "--stance-leg",
            "0",
            "--config",
            str(cfg),
            "--duration-s",
            "3",
            "--pin-log",
            str(log),
        ],
        stdout=subprocess.DEVNULL,
        stderr=w,
    )
    os.close(w)
    try:
        code = proc.wait(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(r)  # the first time anything is done with the pipe's reading end
    print(f"exit after {time.monotonic() - t0:.1f} s with stderr blocked")  # a figure, not a bound
    assert code == 0  # it ended by itself, on its --duration-s, its stderr still full
    recs = read_log(log)
    assert any(rec["pin"] in CLUTCH_PINS and rec["level"] == 1 for rec in recs)  # it ran: a clutch engaged
    assert all(level == 0 for level in {rec["pin"]: rec["level"] for rec in recs}.values())
