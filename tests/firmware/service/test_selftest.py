"""The self-test of `robot check` as a library call, on the fakes."""

from __future__ import annotations

import pytest

from rimless.firmware.service.config import RobotConfig
from rimless.firmware.service.selftest import self_test


def test_self_test_identifies_every_sensor_and_clicks_every_clutch_in_order() -> None:
    cfg = RobotConfig()
    clicked: list[tuple[int, int]] = []
    report = self_test(cfg, fake=True, on_click=lambda leg, pin: clicked.append((leg, pin)))
    assert report.interrupted is None and report.exit_code == 0
    assert [s.index for s in report.sensors] == list(range(len(cfg.sensors)))
    assert all(s.resolution_cpi == cfg.sensors[s.index].resolution_cpi for s in report.sensors)
    assert clicked == list(enumerate(cfg.clutch.pins))
    assert [(c.leg, c.pin) for c in report.clutches] == clicked
    js = report.to_json()
    assert set(js) == {"sensors", "clutches"} and all(s["product_id_ok"] for s in js["sensors"])


def test_self_test_without_click_touches_no_clutch() -> None:
    report = self_test(RobotConfig(), fake=True, click=False, on_click=lambda leg, pin: pytest.fail("clicked"))
    assert report.clutches == [] and report.sensors
