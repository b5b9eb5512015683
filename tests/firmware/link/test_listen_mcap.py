"""`robot listen --mcap`: a fake walk's telemetry, encoded as the robot sends it and with datagrams lost on the
way, recorded to MCAP and read back with the `mcap` library's own reader: Foxglove's encodings (JSON messages
with JSON Schema), one topic per series and per leg, the robot's timestamps as log times, the telemetry
numbers as sequence numbers (so the gaps are the lost objects), every received object once. The robot side
never imports `mcap`, and without it `--mcap` is a one-line error."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from rimless.firmware.control.controller import EventRecord, SampleRecord
from rimless.firmware.drivers.fake_walk import FakeWalk
from rimless.firmware.link.listen import Recorder
from rimless.firmware.link.telemetry import WallClock, pack_datagrams, parse_datagram, record_to_json
from rimless.firmware.service.config import ROBOT_DETECTOR
from tests.support.firmware_walk import walk_controller

RIMLESS = str(Path(sys.executable).with_name("rimless"))


def fake_run_datagrams() -> tuple[list[bytes], list[dict]]:
    """The datagrams of a 2 s fake walk, numbered as `TelemetrySender` and the app number them."""
    records: list = []
    walk_controller(FakeWalk(start_s=0.3), ROBOT_DETECTOR, duration_s=2.0, records=records)
    clock = WallClock()
    objs, event_seq = [], 0
    for tseq, rec in enumerate(records, 1):
        if isinstance(rec, EventRecord):
            event_seq += 1
            rec.fields["event_seq"] = event_seq
        obj = record_to_json(rec, clock)
        obj["tseq"] = tseq
        objs.append(obj)
    assert any(isinstance(r, SampleRecord) for r in records) and event_seq > 3
    return list(pack_datagrams(objs, 1200)), objs


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> tuple[Path, list[dict], list[dict]]:
    pytest.importorskip("mcap")
    datagrams, sent = fake_run_datagrams()
    received = [parse_datagram(d) for i, d in enumerate(datagrams) if i % 7 != 3]  # every 7th lost on the way
    path = tmp_path_factory.mktemp("mcap") / "walk.mcap"
    rec = Recorder(None, None, path, {"robot": "fake"})
    for objs in received:
        rec.write(objs)
    assert rec.close() == [path]
    got = [o for objs in received for o in objs]
    assert len(got) < len(sent)
    return path, got, sent


def read_back(path: Path) -> tuple[list[tuple[str, str, str, int, int, int, dict]], object]:
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        reader = make_reader(fh)
        out = [
            (ch.topic, ch.message_encoding, schema.encoding, m.log_time, m.publish_time, m.sequence, json.loads(m.data))
            for schema, ch, m in reader.iter_messages(log_time_order=False)
        ]
        summary = reader.get_summary()
    return out, summary


def test_every_received_object_is_one_message_per_series_with_the_robots_time_and_number(recording) -> None:
    path, got, sent = recording
    msgs, summary = read_back(path)
    assert summary.statistics.message_count == len(msgs)
    assert {(enc, schema_enc) for _t, enc, schema_enc, *_ in msgs} == {("json", "jsonschema")}
    by_tseq = {o["tseq"]: o for o in got}
    samples = [o for o in got if "event" not in o]
    events = [o for o in got if "event" in o]
    topics = {t for t, *_ in msgs}
    stance_legs = {o["leg"]["stance"] for o in samples}
    assert len(stance_legs) >= 3  # the walk went round several legs
    assert topics == {"/leg", "/sensor", "/loop", "/events"} | {f"/leg{k}" for k in stance_legs}
    count = {t: sum(1 for m in msgs if m[0] == t) for t in topics}
    assert count["/leg"] == count["/sensor"] == count["/loop"] == len(samples)
    assert count["/events"] == len(events)
    assert sum(count[f"/leg{k}"] for k in stance_legs) == len(samples)
    for topic, _e, _s, log_ns, pub_ns, seq, body in msgs:
        obj = by_tseq[seq]  # the sequence number is the telemetry number: every one was received
        assert log_ns == pub_ns and abs(log_ns - obj["timestamp"] * 1e9) < 1e3  # the robot's clock, to 1 us
        if topic.startswith("/leg") and topic != "/leg":
            assert body["leg"] == obj["leg"]["stance"] == int(topic[4:])
            assert body["velocity_m_s"] == obj["leg"]["velocity_m_s"]
        elif topic == "/leg":
            assert body["compression_m"] == obj["leg"]["compression_m"] and body["seq"] == obj["seq"]
        elif topic == "/events":
            assert body == obj["event"]
    # the gaps in the sequence numbers are exactly the objects lost on the way, events among them
    lost = [o for o in sent if o["tseq"] not in by_tseq]
    assert {m[5] for m in msgs} == {o["tseq"] for o in sent} - {o["tseq"] for o in lost}
    lost_events = {o["event"]["event_seq"] for o in lost if "event" in o}
    all_events = {o["event"]["event_seq"] for o in sent if "event" in o}
    assert {m[6]["event_seq"] for m in msgs if m[0] == "/events"} == all_events - lost_events


def test_foxglove_finds_a_schema_per_topic_and_the_metadata(recording) -> None:
    from mcap.reader import make_reader

    path, _got, _sent = recording
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta == {"rimless": {"robot": "fake"}}
    for ch in summary.channels.values():
        schema = summary.schemas[ch.schema_id]
        doc = json.loads(schema.data)
        assert doc["type"] == "object" and doc["properties"]
    t0, t1 = summary.statistics.message_start_time, summary.statistics.message_end_time
    assert 1.5e9 < t1 - t0 < 2.1e9  # the 2 s walk on the robot's clock


def test_listen_records_mcap_from_the_loopback(tmp_path) -> None:
    """`listen(mcap_out=...)` end to end: a few datagrams from a sender on the loopback."""
    pytest.importorskip("mcap")
    import socket
    import threading

    from rimless.firmware.link.listen import listen
    from rimless.firmware.link.telemetry import sign_datagram, telemetry_key
    from tests.support.firmware_app import TOKEN, free_port, wait_udp_bound

    port = free_port()
    datagrams, _n = fake_run_datagrams()
    key = telemetry_key(TOKEN, "d" * 32)

    def send() -> None:
        wait_udp_bound(port)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for d in datagrams[:20]:
                tx.sendto(sign_datagram(d, key, "d" * 32), ("127.0.0.1", port))

    t = threading.Thread(target=send)
    t.start()
    out = tmp_path / "t.mcap"
    lines: list[str] = []
    listen(
        bind="127.0.0.1",
        port=port,
        out=None,
        duration_s=120.0,  # a hang guard: it ends on the 20th datagram
        echo=lines.append,
        timeout_s=0,
        mcap_out=out,
        token=TOKEN,
        max_datagrams=20,
    )
    t.join()
    assert f"wrote {out}" in lines
    msgs, _summary = read_back(out)
    received = sum(len(parse_datagram(d)) for d in datagrams[:20])
    assert 0 < sum(1 for m in msgs if m[0] in ("/leg", "/events")) <= received


def test_the_robot_side_never_imports_mcap() -> None:
    code = (
        "import sys; import rimless.firmware.service.app, rimless.firmware.link.listen, rimless.firmware.cli; "
        "assert 'mcap' not in sys.modules, 'mcap imported'"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


def test_without_the_mcap_package_mcap_is_a_one_line_error_and_leaves_no_file(tmp_path) -> None:
    from tests.support.firmware_app import free_port

    shadow = tmp_path / "shadow" / "mcap"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError('No module named mcap')\n")
    env = {**os.environ, "PYTHONPATH": str(shadow.parent)}
    out = tmp_path / "t.mcap"
    proc = subprocess.run(
        [
            RIMLESS,
            "robot",
            "listen",
            "--bind",
            "127.0.0.1",
            "--port",
            str(free_port()),
            "--no-live",
            "--mcap",
            str(out),
            "--out",
            str(tmp_path / "t.jsonl"),
            "--timeout-s",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "mcap" in proc.stderr and "pip install" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.glob("t.*")) == []
