"""robot.toml: the example loads, every error names the file and the field, pins are checked."""

from __future__ import annotations

import pytest

from rimless.errors import ParameterError, UserError
from rimless.firmware.errors import ConfigError, ConfigFileError
from rimless.firmware.service.config import config_from_dict, example_config_path, load_config


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
        (
            {"detector": {"confirm_steps": 4, "confirm_within_steps": 5}},
            r"\[detector\] confirm_within_steps must be 0 \(off\) or an integer in confirm_steps \+ 2 \(6\)",
        ),
    ],
)
def test_config_errors_name_the_field(data, match) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        config_from_dict(data, "robot.toml")
    assert str(info.value).startswith("robot.toml")
    assert isinstance(info.value, ParameterError) and isinstance(info.value, UserError)


def test_a_longer_confirmation_keeps_the_default_room_to_confirm_it() -> None:
    """`confirm_within_steps` (robot default 5: the 4 touchdowns `confirm_steps` 2 needs and one bounce) follows a
    robot.toml's larger `confirm_steps` unless set: confirm_steps + 3, never a config error for a field not written."""
    assert config_from_dict({}, "robot.toml").detector.confirm_within_steps == 5
    assert config_from_dict({"detector": {"confirm_steps": 1}}, "robot.toml").detector.confirm_within_steps == 5
    assert config_from_dict({"detector": {"confirm_steps": 6}}, "robot.toml").detector.confirm_within_steps == 9
    off = {"detector": {"confirm_steps": 6, "confirm_within_steps": 0}}
    assert config_from_dict(off, "robot.toml").detector.confirm_within_steps == 0


def test_config_file_syntax_error(tmp_path) -> None:
    p = tmp_path / "robot.toml"
    p.write_text("[sampling]\nrate_hz = = 3\n")
    with pytest.raises(ConfigFileError, match="line 2"):
        load_config(p)


def test_clutch_pins_off_spi_lines_and_off_boot_pull_ups_without_a_reason() -> None:
    with pytest.raises(ConfigError, match="GPIO9 is an SPI line"):
        config_from_dict({"clutch": {"pins": [9, 27]}, "sensor": {"legs": [0, 1]}})
    with pytest.raises(ConfigError, match="GPIO4 is pulled up at power-on"):
        config_from_dict({"clutch": {"pins": [4, 27]}, "sensor": {"legs": [0, 1]}})
    ok = config_from_dict(
        {
            "clutch": {"pins": [4, 27], "boot_pull_up_reason": "1k pull-down on the module input"},
            "sensor": {"legs": [0, 1]},
        }
    )
    assert ok.clutch.pins == (4, 27)
    with pytest.raises(ConfigError, match="GPIO7 is an SPI line"):
        config_from_dict({"clutch": {"pins": [7, 27], "boot_pull_up_reason": "x"}, "sensor": {"legs": [0, 1]}})
    with pytest.raises(ConfigError, match="HAT ID EEPROM"):
        config_from_dict({"clutch": {"pins": [0, 27]}, "sensor": {"legs": [0, 1]}})
    with pytest.raises(ConfigError, match="GPIO19 is an SPI line"):  # SPI1 in use: its lines too
        config_from_dict({"clutch": {"pins": [19, 27]}, "sensor": {"spi_bus": 1, "legs": [0, 1]}})
    with pytest.raises(ConfigError, match="reset_pin GPIO17 is also a clutch pin"):
        config_from_dict({"sensor": {"reset_pin": 17}})
    with pytest.raises(ConfigError, match="cs_pin GPIO5 is also"):
        config_from_dict({"sensor": [{"legs": [0], "cs_pin": 5}, {"legs": [1], "cs_pin": 5}]})
