"""GPIO helpers: releasing the clutch pins drives each to its off level before giving it back."""

from __future__ import annotations

from rimless.firmware.drivers.gpio import mock_pin_factory, pin_histories, release_pins

PINS = (17, 27, 22)


def test_release_drives_each_pin_to_its_off_level() -> None:
    factory = mock_pin_factory()
    try:
        levels = release_pins(PINS, active_high=True, pin_factory=factory)
        assert set(levels) == {f"GPIO{p}" for p in PINS}
        assert all(h and set(h) == {"0"} for h in levels.values()), levels  # never high: off is low
        assert pin_histories(factory, PINS[:2]) == f"GPIO17={levels['GPIO17']} GPIO27={levels['GPIO27']}"
    finally:
        factory.close()


def test_release_of_active_low_clutches_ends_high() -> None:
    factory = mock_pin_factory()
    try:
        levels = release_pins(PINS, active_high=False, pin_factory=factory)
        assert all(h.endswith("1") for h in levels.values()), levels  # active low: off is high
    finally:
        factory.close()
