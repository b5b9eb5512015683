"""Config validation, telemetry packing, trial-log durability, and the lean-import rule."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from rimless.errors import ParameterError, UserError
from rimless.firmware.service.config import config_from_dict, example_config_path, load_config
from rimless.firmware.control.controller import EventRecord, SampleRecord
from rimless.firmware.errors import ConfigError, ConfigFileError
from rimless.firmware.link.telemetry import WallClock, pack_datagrams, parse_datagram, record_to_json
from rimless.firmware.service.triallog import TrialLog, TrialLogError, read_trial_log


def test_example_config_loads_and_documents_every_section() -> None:
    cfg = load_config(example_config_path())
    assert cfg.sampling.rate_hz == 300.0 and cfg.sensors[0].legs == tuple(range(8))
    text = example_config_path().read_text()
    for section in ("[[sensor]]", "[clutch]", "[sampling]", "[detector]", "[telemetry]", "[commands]", "[log]"):
        assert section in text


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"sampling": {"rate_hz": 0}}, r"\[sampling\]\.rate_hz must be in"),
        ({"sampling": {"rate": 300}}, r"unknown field 'rate'"),
        ({"bogus": {}}, r"unknown section \[bogus\]"),
        ({"clutch": {"pins": [17, 17]}}, r"pins has duplicates"),
        ({"clutch": {"active_high": 1}}, r"active_high must be true or false"),
        ({"sensor": [{"legs": [0, 9]}]}, r"leg 9 has no clutch pin"),
        ({"sensor": [{"legs": [0]}, {"legs": [0], "spi_device": 1}]}, r"watched by two sensors"),
        ({"sensor": [{"resolution_cpi": 800}]}, r"resolution_cpi must be 400 or 1600"),
        ({"detector": {"touch_debounce_samples": 0}}, r"touch_debounce_samples"),
        ({"telemetry": {"port": "x"}}, r"telemetry\]\.port must be an integer"),
    ],
)
def test_config_errors_name_the_field(data, match) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        config_from_dict(data, "robot.toml")
    assert str(info.value).startswith("robot.toml")
    assert isinstance(info.value, ParameterError) and isinstance(info.value, UserError)


def test_config_file_syntax_error(tmp_path) -> None:
    p = tmp_path / "robot.toml"
    p.write_text("[sampling]\nrate_hz = = 3\n")
    with pytest.raises(ConfigFileError, match="line 2"):
        load_config(p)


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


def test_firmware_imports_no_numeric_stack_and_cli_is_lean() -> None:
    code = (
        "import sys, pkgutil, importlib, rimless.firmware as f\n"
        "import rimless.firmware.cli\n"
        "lean = not any(m in sys.modules for m in ('gpiozero', 'asyncio', 'rimless.firmware.service.app'))\n"
        "for m in pkgutil.iter_modules(f.__path__):\n"
        "    importlib.import_module('rimless.firmware.' + m.name)\n"
        "bad = [m for m in ('numpy', 'scipy', 'pandas', 'matplotlib', 'dask', 'spidev') if m in sys.modules]\n"
        "print(lean, bad)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True []"


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
