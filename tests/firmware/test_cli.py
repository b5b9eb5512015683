"""CLI: user errors are one line with exit 2; `run --fake` under SIGTERM ends with every clutch off."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rimless.cli import app

RIMLESS = [str(Path(sys.executable).with_name("rimless"))]
runner = CliRunner()
STRONG = "cli-test-token-5e8d1f0a9b"


def invoke(*args: str, env: dict | None = None):
    return runner.invoke(app, ["robot", *args], env=env)


def free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_bad_config_file_names_file_and_field(tmp_path) -> None:
    cfg = tmp_path / "robot.toml"
    cfg.write_text("[detector]\ntouch_velocity_m_s = -1\n")
    r = invoke("check", "--fake", "--no-click", "--config", str(cfg))
    assert r.exit_code == 2
    assert r.output.count("\n") == 1 and r.output.startswith("error: ")
    assert "robot.toml" in r.output and "touch_velocity_m_s" in r.output
    cfg.write_text("[clutch]\npins = [17, 17]\n")
    r = invoke("run", "--fake", "--config", str(cfg))
    assert r.exit_code == 2 and "clutch" in r.output and "pins" in r.output
    cfg.write_text("[sampling\n")
    r = invoke("run", "--fake", "--config", str(cfg))
    assert r.exit_code == 2 and "robot.toml" in r.output and "line 1" in r.output
    r = invoke("run", "--fake", "--config", str(tmp_path / "missing.toml"))
    assert r.exit_code == 2 and "missing.toml: no such file" in r.output


def test_bad_host_and_no_robot(tmp_path) -> None:
    r = invoke("status", "--host", "no-such-host.invalid", "--token", "x")
    assert r.exit_code == 2 and r.output.startswith("error: ") and "no-such-host.invalid" in r.output
    r = invoke("arm", "--host", "127.0.0.1", "--port", str(free_port()), "--token", "x")
    assert r.exit_code == 2 and "cannot reach the robot" in r.output
    r = invoke("status", "--host", "127.0.0.1", env={"RIMLESS_TOKEN": ""})
    assert r.exit_code == 2 and "token" in r.output


def test_bench_json_contract() -> None:
    r = invoke("bench", "--fake", "--rate-hz", "300", "--duration-s", "0.5", "--json")
    assert r.exit_code == 0, r.output
    rows = json.loads(r.stdout)
    assert len(rows) == 1
    keys = {"rate_hz", "achieved_rate_hz", "period_jitter_p99_ms", "latency_p50_ms", "latency_p99_ms",
            "latency_max_ms", "missed_deadlines"}
    assert keys <= set(rows[0]) and rows[0]["rate_hz"] == 300.0
    assert rows[0]["latency_p50_ms"] <= rows[0]["latency_p99_ms"] <= rows[0]["latency_max_ms"]
    r = invoke("bench", "--rate-hz", "300")
    assert r.exit_code == 2 and "--fake" in r.output
    r = invoke("bench", "--fake", "--rate-hz", "3x")
    assert r.exit_code == 2 and "--rate-hz" in r.output


def test_check_fake_reports_id_squal_and_clicks() -> None:
    r = invoke("check", "--fake", "--json")
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["sensors"][0]["product_id_ok"] and rep["sensors"][0]["squal"] == 60
    assert rep["sensors"][0]["frame_rate_hz"] == 2000.0
    assert [c["pin"] for c in rep["clutches"]] == [17, 27, 22, 23, 24, 16, 20, 21]


def test_listen_records_datagrams(tmp_path) -> None:
    port = free_port()
    out = tmp_path / "tel.jsonl"

    def send() -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        time.sleep(0.3)  # let the listener bind first
        for k in range(20):
            time.sleep(0.02)
            batch = [{"timestamp": 1.0 + k, "leg": {"stance": 1, "velocity_m_s": 0.1}},
                     {"timestamp": 1.0 + k, "event": {"name": "lock", "code": 2}}]
            s.sendto(json.dumps(batch).encode(), ("127.0.0.1", port))
        s.sendto(b"garbage", ("127.0.0.1", port))
        s.close()

    t = threading.Thread(target=send)
    t.start()
    r = invoke("listen", "--bind", "127.0.0.1", "--port", str(port), "--out", str(out), "--duration-s", "1.2",
               "--summary-every-s", "0.3")
    t.join()
    assert r.exit_code == 0, r.output
    lines = out.read_text().splitlines()
    assert len(lines) == 40
    assert "20 samples" in r.output and "20 events" in r.output and "1 garbled" in r.output


def test_sigterm_to_run_fake_turns_every_clutch_off(tmp_path) -> None:
    port = free_port()
    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nbind = "127.0.0.1"\nport = {port}\n[log]\ndir = "{tmp_path}"\n')
    env = {**os.environ, "RIMLESS_TOKEN": STRONG}
    proc = subprocess.Popen([*RIMLESS, "robot", "run", "--fake", "--arm", "--config", str(cfg)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    try:
        from rimless.firmware.commands import send_command
        from rimless.firmware.errors import RobotUnreachable

        engaged = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not engaged:
            try:
                engaged = send_command("127.0.0.1", "status", token=STRONG, port=port, timeout_s=1)["engaged"]
            except RobotUnreachable:
                pass
            time.sleep(0.02)
        assert engaged, "no clutch engaged in 20 s"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "stopped (SIGTERM)" in err
    line = next(ln for ln in err.splitlines() if ln.startswith("fake clutch pin levels"))
    levels = dict(item.split("=") for item in line.split(": ", 1)[1].split())
    assert len(levels) == 8
    assert all(h.endswith("0") for h in levels.values()), levels  # every pin ends off...
    assert any(h == "010" or h.endswith("10") for h in levels.values())  # ...including one that was on
