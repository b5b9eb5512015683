"""GPIO beyond the clutch bank: the mock pin factory of `--fake`, plain outputs (RESET, NPD, chip selects),
a GPIO chip select around a shared SPI bus, and opening or releasing the clutch pins with one-line errors."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import Any

from rimless.errors import UserError
from rimless.firmware.drivers.clutch import ClutchBank

PI4_REVISION = "c03111"  # MockFactory reports a Pi 4B with this revision


class GpioUnavailable(UserError):
    """No GPIO on this machine (not a Pi, or no GPIO library)."""


def mock_pin_factory() -> Any:
    """gpiozero's MockFactory for a Pi 4B: the pins of `--fake` and of the tests."""
    from gpiozero.pins.mock import MockFactory

    return MockFactory(revision=PI4_REVISION)


def output(pin: int, *, active_high: bool, pin_factory: Any = None) -> Any:
    """A gpiozero output on BCM `pin`, starting at its off level."""
    from gpiozero import DigitalOutputDevice

    return DigitalOutputDevice(pin, active_high=active_high, initial_value=False, pin_factory=pin_factory)


class GpioChipSelectBus:
    """An `SpiBus` whose chip select is a GPIO (active low) around each message of a shared bus
    opened without its own CS (`dtoverlay=spi0-0cs`): one sensor per leg on one SPI bus."""

    def __init__(self, bus: Any, cs: Any) -> None:
        self.bus = bus
        self.cs = cs  # a gpiozero DigitalOutputDevice with active_high=False: on() = CS low

    def message(self, segments: Any) -> list[bytes]:
        """CS low, the message, CS high (also when the transfer fails)."""
        self.cs.on()
        try:
            return self.bus.message(segments)
        finally:
            self.cs.off()

    def close(self) -> None:
        """Deselect; the shared bus is closed by its owner."""
        self.cs.off()


def open_clutches(pins: Any, *, active_high: bool, pin_factory: Any = None) -> ClutchBank:
    """The clutch outputs, driven off; `GpioUnavailable` (one line) when this machine has no GPIO."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # gpiozero warns once per factory it falls back from
            return ClutchBank(pins, active_high=active_high, pin_factory=pin_factory)
    except Exception as err:  # noqa: BLE001 - gpiozero, lgpio and the OS each raise their own
        if type(err).__name__ in ("BadPinFactory", "PinFactoryFallback") or isinstance(err, ImportError):
            raise GpioUnavailable(
                f"no GPIO on this machine ({type(err).__name__}: {err}); on a PC use --fake, on a Pi install "
                "the robot extra (lgpio)"
            ) from None
        raise GpioUnavailable(
            f"cannot drive the clutch pins {list(pins)} ({type(err).__name__}: {err}); is another process "
            "(a running firmware) holding them?"
        ) from None


def level_history(pin_factory: Any, pin: int) -> str:
    """The levels a mock pin went through, oldest first ("010": low, high, low)."""
    return "".join("1" if st.state else "0" for st in pin_factory.pin(pin).states)


def pin_histories(pin_factory: Any, pins: Iterable[int]) -> str:
    """The mock pins' level histories ("GPIO17=010 GPIO27=00 ..."), to show the clutches end off."""
    return " ".join(f"GPIO{pin}={level_history(pin_factory, pin)}" for pin in pins)


def release_pins(pins: Any, *, active_high: bool, pin_factory: Any = None) -> dict[str, str]:
    """Drive every clutch pin to its off level, then release the lines (`rimless robot release`).

    Returns each pin's level history ("0", "01"...), as read back from the pin factory (empty without one).
    """
    bank = open_clutches(pins, active_high=active_high, pin_factory=pin_factory)
    try:
        bank.all_off()
        levels = {f"GPIO{p}": level_history(pin_factory, p) for p in pins} if pin_factory is not None else {}
    finally:
        bank.close()
    return levels
