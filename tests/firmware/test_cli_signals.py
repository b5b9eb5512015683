"""Every signal a process can catch, and every way to start without hardware, ends with the clutches
released: `robot run --fake` under SIGHUP/SIGQUIT, `robot check --fake` under SIGTERM, `robot release`,
and `run`/`check` on a machine with no GPIO. Each outcome is checked on the mock pins' histories."""

from __future__ import annotations

import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rimless.firmware.errors import RobotUnreachable
from rimless.firmware.link.remote import send_command
from tests.support.firmware_app import free_port, signed_datagram

RIMLESS = [str(Path(sys.executable).with_name("rimless"))]
TOKEN = secrets.token_urlsafe(18)  # generated: a token published in the tests is refused
PINS = ("17", "27", "22", "23", "24", "16", "20", "21")
#: the watchdogs at 5 s (the robot's 0.1 s and 0.25 s): a loaded test machine pauses a process for tenths of a
#: second, and a `sensor_stalled` fault disarms the fake robot for good, so that no clutch ever engages (a run at
#: load 14 waited 300 s for one); these tests are about signals, not stalls
SAMPLING = "[sampling]\nstall_timeout_s = 5.0\nloop_stall_s = 5.0\n"
#: how long a test waits for an event or an exit (a hang guard, not a bound: only a hung process takes this long)
HANG_GUARD_S = 300.0


def pin_levels(line: str) -> dict[str, str]:
    """'... GPIO17=010 GPIO27=0 ...' -> {'17': '010', ...}"""
    items = [w for w in line.replace(")", " ").split() if w.startswith("GPIO") and "=" in w]
    return {k[4:]: v for k, v in (w.split("=") for w in items)}


def start_run(tmp_path: Path, *args: str) -> tuple[subprocess.Popen, int]:
    port = free_port()
    cfg = tmp_path / "robot.toml"
    cfg.write_text(
        f'[commands]\nbind = "127.0.0.1"\nport = {port}\nlink_timeout_s = 0.0\n[log]\ndir = "{tmp_path}"\n{SAMPLING}'
    )
    env = {**os.environ, "RIMLESS_TOKEN": TOKEN}
    proc = subprocess.Popen(
        [*RIMLESS, "robot", "run", "--fake", "--config", str(cfg), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        text=True,
    )
    return proc, port


def wait_engaged(proc: subprocess.Popen, port: int) -> None:
    deadline = time.monotonic() + HANG_GUARD_S
    status = None
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            status = send_command("127.0.0.1", "status", token=TOKEN, port=port, timeout_s=1)
            if status["engaged"]:
                return
        except RobotUnreachable:
            pass
        time.sleep(0.02)
    raise AssertionError(f"no clutch engaged in {HANG_GUARD_S:g} s; last status: {status}")


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGHUP, 129), (signal.SIGQUIT, 131), (signal.SIGINT, 130)])
def test_run_fake_releases_every_clutch_on_a_signal(tmp_path, sig, code) -> None:
    proc, port = start_run(tmp_path, "--arm", "--stance-leg", "0")
    try:
        wait_engaged(proc, port)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, err
    assert f"stopped ({sig.name})" in err and "every clutch released" in err
    assert "Traceback" not in err and "CancelledError" not in err
    line = next(ln for ln in err.splitlines() if ln.startswith("fake clutch pin levels"))
    levels = pin_levels(line)
    assert sorted(levels) == sorted(PINS)
    assert all(h.endswith("0") for h in levels.values()), levels  # every pin ends off...
    assert any("1" in h for h in levels.values()), levels  # ...including one that was on when the signal came


def test_sigterm_during_check_fake_releases_the_clicked_clutch(tmp_path) -> None:
    """Load-independent: the line "clicking clutch 0" comes once it is engaged, and it stays engaged for 10 s,
    so the signal finds it on however late it is delivered."""
    proc = subprocess.Popen(
        [*RIMLESS, "robot", "check", "--fake", "--click-s", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    err_lines = []
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # wait until clutch 0 is engaged
            err_lines.append(line)
            if line.startswith("clicking clutch 0"):
                break
        proc.send_signal(signal.SIGTERM)
        out, rest = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    err = "".join(err_lines) + rest
    assert proc.returncode == 128 + signal.SIGTERM, err
    final = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(final) == 1 and "interrupted by SIGTERM" in final[0] and "every clutch released" in final[0]
    assert "Traceback" not in err
    levels = pin_levels(final[0])
    assert sorted(levels) == sorted(PINS)
    assert all(h.endswith("0") for h in levels.values()), levels
    assert levels["17"] == "010", levels  # clutch 0 was on when the signal came, and is off now
    assert all(levels[p] == "0" for p in PINS[1:]) and out == ""  # no click after the signal, no report


def test_release_drives_every_clutch_pin_low(tmp_path) -> None:
    r = subprocess.run([*RIMLESS, "robot", "release", "--fake", "--json"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    import json

    rep = json.loads(r.stdout)
    assert rep["released_pins"] == [int(p) for p in PINS] and rep["level"] == "low"
    assert all(v == "0" for v in rep["fake_levels"].values()) and len(rep["fake_levels"]) == 8
    unit = (Path(__file__).parents[2] / "firmware" / "service" / "rimless-robot.service").read_text()
    assert "ExecStopPost=" in unit and "robot release" in unit


@pytest.mark.skipif(Path("/dev/gpiochip0").exists(), reason="this machine has GPIO")
@pytest.mark.parametrize("command", ["run", "check"])
def test_no_gpio_is_one_line_and_exit_2(command) -> None:
    env = {k: v for k, v in os.environ.items() if k != "GPIOZERO_PIN_FACTORY"}
    env["RIMLESS_TOKEN"] = TOKEN
    r = subprocess.run([*RIMLESS, "robot", command], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: no GPIO on this machine") and "--fake" in lines[0], r.stderr


def test_weak_token_is_refused_at_start(tmp_path) -> None:
    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nbind = "127.0.0.1"\nport = {free_port()}\n')
    for weak in ("change-me", "short"):
        r = subprocess.run(
            [*RIMLESS, "robot", "run", "--fake", "--config", str(cfg), "--duration-s", "1"],
            capture_output=True,
            text=True,
            env={**os.environ, "RIMLESS_TOKEN": weak},
            timeout=60,
        )
        assert r.returncode == 2, r.stderr
        err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
        assert len(err) == 1 and "token" in err[0], r.stderr
    unit = (Path(__file__).parents[2] / "firmware" / "service" / "rimless-robot.service").read_text()
    assert "RIMLESS_TOKEN=" not in unit and "LoadCredential=" in unit


def test_ctrl_c_in_bench_exits_130_without_cancelled_error(tmp_path) -> None:
    """The Ctrl-C lands inside the bench's event loop, on an event: the bench's trial log appears (in its
    temporary folder, under $TMPDIR) once the app's loop runs (`on_ready`), and the bench runs 10 s more."""
    proc = subprocess.Popen(
        [*RIMLESS, "robot", "bench", "--fake", "--rate-hz", "300", "--duration-s", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "TMPDIR": str(tmp_path)},
    )
    try:
        assert proc.stderr is not None
        first = proc.stderr.readline()
        assert first.startswith("bench:"), first
        deadline = time.monotonic() + HANG_GUARD_S  # a file appearing is announced by nothing: looked for
        while not list(tmp_path.glob("rimless-bench-*/*bench.jsonl")):
            assert proc.poll() is None and time.monotonic() < deadline, "the bench's loop never started its trial"
            time.sleep(0.01)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=HANG_GUARD_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "CancelledError" not in err and "Traceback" not in err
    assert [ln for ln in err.splitlines() if ln.strip()] == ["interrupted"]
    assert out == "" and not list(tmp_path.iterdir())  # no figures, and its temporary folder removed


def test_ctrl_c_in_listen_completes_the_recording_and_exits_130(tmp_path) -> None:
    out = tmp_path / "tel.jsonl"
    port = free_port()
    proc = subprocess.Popen(
        [
            *RIMLESS,
            "robot",
            "listen",
            "--bind",
            "127.0.0.1",
            "--port",
            str(port),
            "--out",
            str(out),
            "--no-live",
            "--summary-every-s",
            "0.2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        first = proc.stderr.readline()  # the first summary line: it is listening
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for k in range(5):
            s.sendto(signed_datagram(b'[{"timestamp": %d, "leg": {"stance": 1}}]' % k), ("127.0.0.1", port))
        s.close()
        seen = [first]
        while not seen[-1].startswith("5 samples"):  # a summary line every 0.2 s: all five received
            line = proc.stderr.readline()
            assert line, "".join(seen)  # listen ends by itself after --timeout-s (10 s) of silence
            seen.append(line)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=HANG_GUARD_S)
        err = "".join(seen) + err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert err.rstrip().splitlines()[-1] == "interrupted"
    assert f"wrote {out}" in err and len(out.read_text().splitlines()) == 5
    assert not list(tmp_path.glob("*.part")) and "Traceback" not in err


def test_a_guessable_token_is_refused_naming_its_setting(tmp_path) -> None:
    """Fails on today's main: a keyboard walk from a private token file started the robot."""
    tok = tmp_path / "token"
    tok.write_text("1q2w3e4r5t6y7u8i9o0p\n")
    tok.chmod(0o600)
    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nbind = "127.0.0.1"\nport = {free_port()}\ntoken_file = "{tok}"\n')
    env = {k: v for k, v in os.environ.items() if k not in ("RIMLESS_TOKEN", "RIMLESS_TOKEN_FILE")}
    r = subprocess.run(
        [*RIMLESS, "robot", "run", "--fake", "--config", str(cfg), "--duration-s", "1"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert r.returncode == 2, r.stderr
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "[commands] token_file" in err[0] and "guessable" in err[0], r.stderr


def _pins_at_the_end(pin_log: Path) -> dict[int, int]:
    import json

    last: dict[int, int] = {}
    for line in pin_log.read_text().splitlines():
        if line.endswith("}"):
            rec = json.loads(line)
            last[rec["pin"]] = rec["level"]
    return last


@pytest.mark.parametrize(
    "line",
    [
        # printed from the firmware's loop once it runs and handles the signals itself
        "rimless robot: running (fake)",
        # printed before the loop starts: the Ctrl-C lands before the loop or just after it started (either way)
        "command token (generated) in ",
    ],
)
def test_ctrl_c_on_a_start_up_line_of_run_exits_130_with_interrupted(tmp_path, line) -> None:
    """Fails before: a Ctrl-C right after the "running" line (printed before the loop started) ended with
    "stopped (SIGINT) before the firmware ran" and no `interrupted` line. The signal is sent on the line."""
    from tests.support.interrupt import Watched

    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nbind = "127.0.0.1"\nport = {free_port()}\n[log]\ndir = "{tmp_path}"\n{SAMPLING}')
    env = {k: v for k, v in os.environ.items() if not k.startswith("RIMLESS_TOKEN")}
    env["XDG_RUNTIME_DIR"] = str(tmp_path)  # the generated token's file
    pin_log = tmp_path / "pins.jsonl"
    argv = [
        *RIMLESS,
        "robot",
        "run",
        "--fake",
        "--arm",
        "--stance-leg",
        "0",
        "--config",
        str(cfg),
        "--pin-log",
        str(pin_log),
    ]
    with Watched(argv, cwd=tmp_path, env=env) as cmd:
        cmd.wait_for(stderr=line, timeout_s=HANG_GUARD_S)
        cmd.interrupt()
        res = cmd.finish(timeout_s=HANG_GUARD_S)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 130, res.stderr
    assert lines[-1] == "interrupted", res.stderr
    assert any(ln.startswith("stopped (SIGINT)") and ln.endswith("every clutch released") for ln in lines), lines
    assert "Traceback" not in res.stderr and "CancelledError" not in res.stderr
    assert set(_pins_at_the_end(pin_log).values()) <= {0}  # every pin that ever changed ends low
    if line.startswith("rimless robot: running"):  # the loop ran: its summary, not "before the firmware ran"
        assert any(ln.startswith("stopped (SIGINT): ") for ln in lines), lines
