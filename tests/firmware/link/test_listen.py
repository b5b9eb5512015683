"""The live view of `robot listen`."""

from __future__ import annotations


def test_live_view_draws_velocity_compression_and_one_strip_per_clutch() -> None:
    from rimless.firmware.link.listen import Summary, sparkline

    assert sparkline([0.0, 0.5, 1.0], 10) == "▁▅█"
    assert sparkline([2.0, 2.0], 10) == "▁▁"
    s = Summary()
    for k in range(40):
        s.add([{"timestamp": k, "leg": {"velocity_m_s": (k % 10) * 0.01, "compression_m": k * 1e-4,
                                        "clutch_mask": 1 << (k // 10)}}], now_s=k * 0.01)
    lines = s.view(now_s=0.4, span_s=1.0, width=40)
    assert lines[1].startswith("velocity") and "m/s" in lines[1]
    assert lines[2].startswith("compression") and "0.0..3.9 mm" in lines[2]
    strips = lines[3:]
    assert len(strips) == 8
    assert strips[0].endswith("█" * 10 + "·" * 30) and strips[3].endswith("·" * 30 + "█" * 10)
    assert all(len(line) <= 80 for line in lines)


def test_listen_with_no_robot_says_so_and_exits_1_after_its_timeout(tmp_path) -> None:
    """Fails on today's main: `robot listen` with nobody sending printed "0 samples" lines forever."""
    import subprocess
    import sys
    from pathlib import Path

    from tests.support.firmware_app import free_port

    out = tmp_path / "tel.jsonl"
    proc = subprocess.run([str(Path(sys.executable).with_name("rimless")), "robot", "listen", "--bind", "127.0.0.1",
                           "--port", str(free_port()), "--no-live", "--summary-every-s", "0.2", "--timeout-s", "1",
                           "--out", str(out)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines[-1].startswith("error: no robot is sending telemetry") and "--timeout-s 1" in lines[-1]
    assert any(line.startswith("waiting for telemetry on 127.0.0.1:") for line in lines)
    assert "Traceback" not in proc.stderr and out.exists() and not list(tmp_path.glob("*.part"))
