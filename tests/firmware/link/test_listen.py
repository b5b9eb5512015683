"""The live view of `robot listen`."""

from __future__ import annotations


def test_live_view_draws_velocity_compression_and_one_strip_per_clutch() -> None:
    from rimless.firmware.link.listen import Summary, sparkline

    assert sparkline([0.0, 0.5, 1.0], 10) == "▁▅█"
    assert sparkline([2.0, 2.0], 10) == "▁▁"
    s = Summary()
    for k in range(40):
        s.add(
            [
                {
                    "timestamp": k,
                    "leg": {"velocity_m_s": (k % 10) * 0.01, "compression_m": k * 1e-4, "clutch_mask": 1 << (k // 10)},
                }
            ],
            now_s=k * 0.01,
        )
    lines = s.view(now_s=0.4, span_s=1.0, width=40)
    assert lines[1].startswith("velocity") and "m/s" in lines[1]
    assert lines[2].startswith("compression") and "0.0..3.9 mm" in lines[2]
    strips = lines[3:]
    assert len(strips) == 8
    assert strips[0].endswith("█" * 10 + "·" * 30) and strips[3].endswith("·" * 30 + "█" * 10)
    assert all(len(line) <= 80 for line in lines)


def test_listen_with_no_robot_says_so_and_exits_1_after_its_timeout(tmp_path) -> None:
    """Fails on today's main: `robot listen` with nobody sending printed "0 samples" lines forever (and then,
    once it gave up, left empty recordings behind)."""
    import subprocess
    import sys
    from pathlib import Path

    from tests.support.firmware_app import free_port

    out = tmp_path / "tel.jsonl"
    proc = subprocess.run(
        [
            str(Path(sys.executable).with_name("rimless")),
            "robot",
            "listen",
            "--bind",
            "127.0.0.1",
            "--port",
            str(free_port()),
            "--no-live",
            "--summary-every-s",
            "0.2",
            "--timeout-s",
            "1",
            "--out",
            str(out),
            "--csv",
            str(tmp_path / "tel.csv"),
            "--mcap",
            str(tmp_path / "tel.mcap"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines[-1].startswith("error: no robot is sending telemetry") and "--timeout-s 1" in lines[-1]
    assert "nothing recorded" in lines[-1]
    assert any(line.startswith("waiting for telemetry on 127.0.0.1:") for line in lines)
    assert not any(line.startswith("wrote ") for line in lines), lines
    # exit 1, nothing heard: no recording is left behind, not even an empty one (nor a .part)
    assert "Traceback" not in proc.stderr and not list(tmp_path.iterdir()), list(tmp_path.iterdir())


def test_listen_counts_gaps_and_ignores_other_senders() -> None:
    """Fails on today's main: listen recorded forged datagrams from any sender and said nothing about lost
    objects or events (which carried no sequence number). The robot's datagrams are signed (protocol 3)."""
    import socket
    import threading

    from rimless.firmware.link.listen import listen
    from rimless.firmware.link.telemetry import sign_datagram, telemetry_key
    from tests.support.firmware_app import TOKEN, free_port, wait_udp_bound

    key = telemetry_key(TOKEN, "b" * 32)

    port = free_port()
    lines: list[str] = []

    def send():
        import json

        wait_udp_bound(port)  # datagrams sent before the listener binds are lost
        robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        robot.bind(("127.0.0.1", 0))
        forger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        forger.bind(("127.0.0.2", 0))
        sent = [1, 2, 3, 6, 7, 10]  # 4, 5, 8, 9 lost on the way; 8 was an event
        for t in sent:
            obj = {"timestamp": t, "tseq": t, "leg": {"stance": 1}}
            if t == 7:
                obj = {"timestamp": t, "tseq": t, "event": {"name": "arm", "event_seq": 1}}
            if t == 10:
                obj = {"timestamp": t, "tseq": t, "event": {"name": "fault", "fault": "x", "event_seq": 3}}
            forger.sendto(  # before the robot's: the listener stops at the robot's 6th, the last datagram sent
                json.dumps([{"timestamp": 0, "event": {"name": "fault", "fault": "forged"}}]).encode(),
                ("127.0.0.1", port),
            )
            robot.sendto(sign_datagram(json.dumps([obj]).encode(), key, "b" * 32), ("127.0.0.1", port))
        robot.close()
        forger.close()

    t = threading.Thread(target=send)
    t.start()
    summary = listen(
        bind="127.0.0.1",
        port=port,
        out=None,
        duration_s=120.0,  # a hang guard: it ends on the robot's 6th datagram
        summary_every_s=0.5,
        echo=lines.append,
        stale_s=5.0,
        timeout_s=0,
        token=TOKEN,
        max_datagrams=6,
    )
    t.join()
    assert summary.samples == 4 and summary.events == 2 and summary.faults == ["x"]
    assert summary.foreign == 6
    assert summary.lost_objects == 4 and summary.lost_events == 1
    assert any(line.startswith("receiving from 127.0.0.1") for line in lines)
    assert any("lost 4 telemetry objects" in line and "1 of them events" in line for line in lines)


def test_telemetry_numbers_every_object_and_names_a_series_per_leg() -> None:
    from rimless.firmware.control.controller import EventRecord, SampleRecord
    from rimless.firmware.link.telemetry import TelemetrySender, parse_datagram

    rx = __import__("socket").socket(2, 2)
    rx.bind(("127.0.0.1", 0))
    tx = TelemetrySender([("127.0.0.1", rx.getsockname()[1])])
    s = SampleRecord(10**9, 1, 0, 0.001, 0.1, 0.002, 60, 133, 42, 2, 3, 8, True, 30_000)
    tx.send([s, EventRecord(10**9, "lock", {"leg": 3, "event_seq": 1}), s])
    objs = parse_datagram(rx.recv(65536))
    rx.close()
    tx.close()
    assert [o["tseq"] for o in objs] == [1, 2, 3]
    assert objs[0]["leg3"]["velocity_m_s"] == 0.1 and objs[1]["event"]["event_seq"] == 1


def test_listen_whose_robot_stops_keeps_the_recording_up_to_then_and_says_so(tmp_path) -> None:
    """Exit 1 after data stopped: the recording is the useful part of the run; it is completed and named."""
    import json
    import socket
    import threading

    import pytest

    from rimless.errors import RunFailure
    from rimless.firmware.link.listen import listen
    from rimless.firmware.link.telemetry import sign_datagram, telemetry_key
    from tests.support.firmware_app import TOKEN, free_port, wait_udp_bound

    port = free_port()
    out = tmp_path / "tel.jsonl"
    key = telemetry_key(TOKEN, "c" * 32)

    def send():
        wait_udp_bound(port)
        robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for t in range(3):
            data = json.dumps([{"timestamp": t, "tseq": t, "leg": {"stance": 1}}]).encode()
            robot.sendto(sign_datagram(data, key, "c" * 32), ("127.0.0.1", port))
        robot.close()

    t = threading.Thread(target=send)
    t.start()
    lines: list[str] = []
    with pytest.raises(RunFailure, match="the robot stopped sending") as err:
        listen(
            bind="127.0.0.1",
            port=port,
            out=out,
            duration_s=None,
            echo=lines.append,
            stale_s=0.2,
            timeout_s=0.5,
            token=TOKEN,
        )
    t.join()
    assert f"the recording up to then is kept ({out})" in str(err.value)
    assert len(out.read_text().splitlines()) == 3 and f"wrote {out}" in lines
    assert not list(tmp_path.glob("*.part"))
