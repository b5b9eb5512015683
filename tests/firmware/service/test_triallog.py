"""The trial log: durable JSON Lines that survive a torn last line, names that stay in their directory."""

from __future__ import annotations

import pytest

from rimless.firmware.control.controller import EventRecord, SampleRecord
from rimless.firmware.service.triallog import TrialLog, TrialLogError, read_trial_log


def _sample(seq: int) -> SampleRecord:
    return SampleRecord(10**9 * seq, seq, 0, 0.001 * seq, 0.1, 0.002, 60, 133, 42, 2, 3, 8, True, 30_000)


def test_trial_log_survives_a_torn_last_line_but_not_corruption(tmp_path) -> None:
    log = TrialLog(tmp_path, "t1", {"rate_hz": 300.0})
    log.append([_sample(k) for k in range(1, 51)])
    log.append([EventRecord(7, "lock", {"leg": 2})])
    log.sync()
    log.append([_sample(51)])
    log.close()
    good = read_trial_log(log.path)
    assert len(good.samples) == 51 and good.events[0]["event"]["name"] == "lock" and not good.torn_tail
    data = log.path.read_bytes()
    # Power cut in the middle of the last write: everything before it is intact.
    log.path.write_bytes(data[:-20])
    torn = read_trial_log(log.path)
    assert torn.torn_tail and len(torn.samples) == 50
    assert [s["seq"] for s in torn.samples] == list(range(1, 51))
    # A damaged line in the middle is corruption, and is reported with its line number.
    lines = data.split(b"\n")
    lines[10] = b'{"timestamp": 1, "seq'
    log.path.write_bytes(b"\n".join(lines))
    with pytest.raises(TrialLogError, match="line 11"):
        read_trial_log(log.path)


def test_trial_names_cannot_escape_the_directory(tmp_path) -> None:
    for bad in ("../x", "a/b", "", "."):
        with pytest.raises(ValueError):
            TrialLog(tmp_path, bad)


def test_a_full_disk_degrades_the_log_never_raises_and_never_leaves_a_torn_line(tmp_path) -> None:
    """Fails on today's main: the write's OSError reached the firmware (which stopped) after a short write
    had left a torn line."""
    import errno
    import os

    state = {"full": False, "short": False}

    def write(fd, data):
        if not state["full"]:
            return os.write(fd, data)
        if not state["short"]:
            state["short"] = True
            return os.write(fd, bytes(data[: len(data) // 2]))
        raise OSError(errno.ENOSPC, "No space left on device")

    log = TrialLog(tmp_path, "full", {"rate_hz": 300.0}, write=write)
    log.append([_sample(k) for k in range(1, 11)])
    assert log.sync() > 0
    state["full"] = True
    log.append([_sample(k) for k in range(11, 21)])
    assert log.sync() == 0  # cut short, then ENOSPC: cut back to the last whole line
    log.append([_sample(21)])
    assert log.sync() == 0
    assert log.dropped_lines == 11 and log.errors == 2 and "No space left" in log.last_error
    state["full"] = False  # space again: logging resumes
    log.append([_sample(22)])
    log.close()
    back = read_trial_log(log.path)
    assert not back.torn_tail
    assert [s["seq"] for s in back.samples] == [*range(1, 11), 22]
