"""Telemetry records packed into datagrams under the size limit, and read back."""

from __future__ import annotations

import json

import pytest

from rimless.firmware.control.controller import EventRecord, SampleRecord
from rimless.firmware.link.telemetry import WallClock, pack_datagrams, parse_datagram, record_to_json


def _sample(seq: int) -> SampleRecord:
    return SampleRecord(10**9 * seq, seq, 0, 0.001 * seq, 0.1, 0.002, 60, 133, 42, 2, 3, 8, True, 30_000)


def test_datagrams_stay_under_the_limit_and_keep_every_object() -> None:
    clock = WallClock()
    objs = [record_to_json(_sample(k), clock) for k in range(100)]
    objs.append(record_to_json(EventRecord(5, "fault", {"fault": "squal_low", "code": 6, "detail": "x"}), clock))
    grams = list(pack_datagrams(objs, 600))
    assert all(len(g) <= 600 for g in grams)
    back = [o for g in grams for o in parse_datagram(g)]
    assert back == json.loads(json.dumps(objs))
    assert back[-1]["event"]["name"] == "fault" and isinstance(back[-1]["event"]["fault_code"], int)
    single = list(pack_datagrams(objs[:3], 600, batch=False))
    assert [json.loads(g) for g in single] == json.loads(json.dumps(objs[:3]))
    with pytest.raises(ValueError):
        parse_datagram(b'[{"no_timestamp": 1}]')
