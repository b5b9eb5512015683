"""Every signal a process can catch, and every way to start without hardware, ends with the clutches
released: `robot run --fake` under SIGHUP/SIGQUIT, `robot check --fake` under SIGTERM, `robot release`,
and `run`/`check` on a machine with no GPIO. Each outcome is checked on the mock pins' histories."""

from __future__ import annotations

import os
import secrets
import signal
import socket
import subprocess
from pathlib import Path
from typing import Any

import pytest

from rimless.firmware.errors import RobotUnreachable
from rimless.firmware.link.remote import send_command
from tests.support.firmware_app import free_port, signed_datagram
from tests.support.robot_process import (
    ARMED,
    CLUTCH_PINS,
    HANG_GUARD_S,
    RIMLESS,
    last_levels,
    pin_levels,
    read_pin_log,
    read_stderr_until,
    run_fake,
    started,
    stop_with,
    wait_until,
    write_config,
)

TOKEN = secrets.token_urlsafe(18)  # generated: a token published in the tests is refused
PINS = tuple(str(p) for p in CLUTCH_PINS)


def start_run(tmp_path: Path, *args: str) -> tuple[list[str], dict[str, str], int]:
    """The argv, environment and command port of `robot run --fake ARGS...` with its commands on the loopback."""
    port = free_port()
    cfg = write_config(
        tmp_path / "robot.toml", log_dir=tmp_path, commands=f'bind = "127.0.0.1"\nport = {port}\nlink_timeout_s = 0.0'
    )
    return run_fake(cfg, *args), {**os.environ, "RIMLESS_TOKEN": TOKEN}, port


def wait_engaged(proc: subprocess.Popen, port: int) -> None:
    """Until the robot's status says a clutch is engaged (asked every 20 ms)."""
    last: dict[str, Any] = {}

    def engaged() -> bool:
        try:
            last["status"] = status = send_command("127.0.0.1", "status", token=TOKEN, port=port, timeout_s=1)
        except RobotUnreachable:
            return False
        return bool(status["engaged"])

    wait_until(proc, engaged, lambda: f"clutch engaged (last status: {last.get('status')})")


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGHUP, 129), (signal.SIGQUIT, 131), (signal.SIGINT, 130)])
def test_run_fake_releases_every_clutch_on_a_signal(tmp_path, sig, code) -> None:
    argv, env, port = start_run(tmp_path, *ARMED)
    with started(argv, env=env) as proc:
        wait_engaged(proc, port)
        _, err = stop_with(proc, sig)
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
    with started([*RIMLESS, "robot", "check", "--fake", "--click-s", "10"]) as proc:
        err_lines = read_stderr_until(proc, lambda line: line.startswith("clicking clutch 0"))  # clutch 0 engaged
        out, rest = stop_with(proc, signal.SIGTERM)
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
    cfg = write_config(tmp_path / "robot.toml", log_dir=tmp_path, commands=f'bind = "127.0.0.1"\nport = {free_port()}')
    for weak in ("change-me", "short"):
        r = subprocess.run(
            run_fake(cfg, "--duration-s", "1"),
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
    argv = [*RIMLESS, "robot", "bench", "--fake", "--rate-hz", "300", "--duration-s", "10"]
    with started(argv, env={**os.environ, "TMPDIR": str(tmp_path)}) as proc:
        first = read_stderr_until(proc, lambda line: True)[0]
        assert first.startswith("bench:"), first
        # a file appearing is announced by nothing: looked for
        wait_until(proc, lambda: bool(list(tmp_path.glob("rimless-bench-*/*bench.jsonl"))), "trial of the bench's loop")
        out, err = stop_with(proc, signal.SIGINT)
    assert proc.returncode == 130, err
    assert "CancelledError" not in err and "Traceback" not in err
    assert [ln for ln in err.splitlines() if ln.strip()] == ["interrupted"]
    assert out == "" and not list(tmp_path.iterdir())  # no figures, and its temporary folder removed


def test_ctrl_c_in_listen_completes_the_recording_and_exits_130(tmp_path) -> None:
    out = tmp_path / "tel.jsonl"
    port = free_port()
    argv = [*RIMLESS, "robot", "listen", "--bind", "127.0.0.1", "--port", str(port), "--out", str(out), "--no-live"]
    with started([*argv, "--summary-every-s", "0.2"]) as proc:
        seen = read_stderr_until(proc, lambda line: True)  # the first summary line: it is listening
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for k in range(5):
            s.sendto(signed_datagram(b'[{"timestamp": %d, "leg": {"stance": 1}}]' % k), ("127.0.0.1", port))
        s.close()
        # a summary line every 0.2 s: all five received (listen ends by itself after 10 s of silence: stderr ends)
        seen += read_stderr_until(proc, lambda line: line.startswith("5 samples"))
        _, err = stop_with(proc, signal.SIGINT)
        err = "".join(seen) + err
    assert proc.returncode == 130, err
    assert err.rstrip().splitlines()[-1] == "interrupted"
    assert f"wrote {out}" in err and len(out.read_text().splitlines()) == 5
    assert not list(tmp_path.glob("*.part")) and "Traceback" not in err


def test_a_guessable_token_is_refused_naming_its_setting(tmp_path) -> None:
    """Fails on today's main: a keyboard walk from a private token file started the robot."""
    tok = tmp_path / "token"
    tok.write_text("1q2w3e4r5t6y7u8i9o0p\n")
    tok.chmod(0o600)
    cfg = write_config(
        tmp_path / "robot.toml",
        log_dir=tmp_path,
        commands=f'bind = "127.0.0.1"\nport = {free_port()}\ntoken_file = "{tok}"',
    )
    env = {k: v for k, v in os.environ.items() if k not in ("RIMLESS_TOKEN", "RIMLESS_TOKEN_FILE")}
    r = subprocess.run(run_fake(cfg, "--duration-s", "1"), capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 2, r.stderr
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "[commands] token_file" in err[0] and "guessable" in err[0], r.stderr


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

    cfg = write_config(tmp_path / "robot.toml", log_dir=tmp_path, commands=f'bind = "127.0.0.1"\nport = {free_port()}')
    env = {k: v for k, v in os.environ.items() if not k.startswith("RIMLESS_TOKEN")}
    env["XDG_RUNTIME_DIR"] = str(tmp_path)  # the generated token's file
    pin_log = tmp_path / "pins.jsonl"
    argv = run_fake(cfg, *ARMED, "--pin-log", str(pin_log))
    with Watched(argv, cwd=tmp_path, env=env) as cmd:
        cmd.wait_for(stderr=line, timeout_s=HANG_GUARD_S)
        cmd.interrupt()
        res = cmd.finish(timeout_s=HANG_GUARD_S)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 130, res.stderr
    assert lines[-1] == "interrupted", res.stderr
    assert any(ln.startswith("stopped (SIGINT)") and ln.endswith("every clutch released") for ln in lines), lines
    # the whole stderr in the message: a traceback seen once (2026-11-27, in a loop's __del__ -> close() on a full
    # run at load ~2) was cut by pytest's comparison output, so its cause could not be read
    assert "Traceback" not in res.stderr and "CancelledError" not in res.stderr, "\n" + res.stderr
    assert pin_log.exists() and set(last_levels(read_pin_log(pin_log)).values()) <= {0}  # every pin changed ends low
    if line.startswith("rimless robot: running"):  # the loop ran: its summary, not "before the firmware ran"
        assert any(ln.startswith("stopped (SIGINT): ") for ln in lines), lines
