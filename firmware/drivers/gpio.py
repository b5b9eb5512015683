"""GPIO beyond the clutch bank: the mock pin factory of `--fake`, plain outputs (RESET, NPD, chip selects),
a GPIO chip select around a shared SPI bus, and opening or releasing the clutch pins with one-line errors."""

from __future__ import annotations

import json
import os
import threading
import time
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from rimless.errors import UserError
from rimless.firmware.drivers.clutch import ClutchBank

PI4_REVISION = "c03111"  # MockFactory reports a Pi 4B with this revision


class GpioUnavailable(UserError):
    """No GPIO on this machine (not a Pi, or no GPIO library)."""


class PinLog:
    """Every level change of the mock pins, kept in memory (`transitions`: (t_s, BCM pin, level)) and, with
    `path`, appended at once to a JSON Lines file (`{"t_s", "pin", "level"}`; `t_s` on `clock`, the monotonic
    clock or the fakes' virtual clock) with one `os.write` per line, so that a reader outside the process sees
    each change as it happens, including those made in a signal handler just before the process dies."""

    def __init__(self, path: Path | str | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.path = None if path is None else Path(path)
        self.clock = clock
        self.transitions: list[tuple[float, int, int]] = []
        # held across a pin's change and its record, so that the file's order is the order of the changes (the
        # control thread's heartbeat and the shutdown's `off` race); re-entrant: a signal handler in the main
        # thread may switch pins off while the main thread is inside a change
        self._lock = threading.RLock()
        self._fd = (
            None
            if self.path is None
            else os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        )

    def change(self, pin: int, level: int, apply: Callable[[], bool]) -> bool:
        """`apply()` (changes BCM `pin` to `level`, True if the level changed) and its record, as one step."""
        with self._lock:
            changed = apply()
            if changed:
                self.record(pin, level)
        return changed

    def record(self, pin: int, level: int) -> None:
        """One change of BCM `pin` to `level` (0 or 1), now."""
        with self._lock:
            t = self.clock()
            self.transitions.append((t, pin, level))
            if self._fd is not None:
                line = json.dumps({"t_s": round(t, 6), "pin": pin, "level": level}) + "\n"
                try:
                    os.write(self._fd, line.encode())
                except OSError:
                    pass  # a full disk loses log lines, never a pin change

    def rising(self, pin: int) -> list[float]:
        """The times `pin` went high."""
        return [t for t, p, level in self.transitions if p == pin and level]

    def close(self) -> None:
        """Close the file (the in-memory record stays)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def mock_pin_factory(pin_log: PinLog | None = None) -> Any:
    """gpiozero's MockFactory for a Pi 4B: the pins of `--fake` and of the tests; with `pin_log`, every level
    change of every pin is recorded there."""
    from gpiozero.pins.mock import MockFactory, MockPin

    if pin_log is None:
        return MockFactory(revision=PI4_REVISION)
    log = pin_log  # not None (narrowed for the method below)

    class LoggedMockPin(MockPin):
        def _change_state(self, value: Any) -> bool:
            return log.change(
                int(self.info.name.removeprefix("GPIO")),
                1 if value else 0,
                lambda: super(LoggedMockPin, self)._change_state(value),
            )

    return MockFactory(revision=PI4_REVISION, pin_class=LoggedMockPin)


def output(pin: int, *, active_high: bool, pin_factory: Any = None) -> Any:
    """A gpiozero output on BCM `pin`, starting at its off level."""
    from gpiozero import DigitalOutputDevice

    return DigitalOutputDevice(pin, active_high=active_high, initial_value=False, pin_factory=pin_factory)


class HeartbeatOutput:
    """The heartbeat pin: `toggle()` flips it (called by the control loop at every sample); `stop()` drives it
    low and keeps it there (a retriggerable monostable fed by it then times out and drops the clutch enable)."""

    def __init__(self, pin: int, *, pin_factory: Any = None) -> None:
        self.pin = pin
        self._dev = output(pin, active_high=True, pin_factory=pin_factory)
        self._level = False
        self.enabled = True
        self.toggles = 0

    def toggle(self) -> None:
        """Flip the pin, unless stopped."""
        if self.enabled:
            self._level = not self._level
            self._dev.value = self._level
            self.toggles += 1
            if not self.enabled:  # stopped meanwhile (another thread): stay low
                self._dev.off()

    def stop(self) -> None:
        """Low, and no more toggling."""
        self.enabled = False
        self._level = False
        self._dev.off()

    def close(self) -> None:
        """Low, then release the line."""
        try:
            self.stop()
        finally:
            self._dev.close()


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
    """The clutch outputs, driven off; `GpioUnavailable` (one line) when this machine has no GPIO, naming why each
    of gpiozero's pin factories failed (a sandbox hiding /proc/cpuinfo shows there, not only a missing library)."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")  # gpiozero warns once per factory it falls back from: kept for the error
            return ClutchBank(pins, active_high=active_high, pin_factory=pin_factory)
    except Exception as err:  # noqa: BLE001 - gpiozero, lgpio and the OS each raise their own
        if type(err).__name__ in ("BadPinFactory", "PinFactoryFallback") or isinstance(err, ImportError):
            tried = [
                str(w.message).removeprefix("Falling back from ")
                for w in caught
                if type(w.message).__name__ == "PinFactoryFallback"
            ]
            why = f"; {'; '.join(tried)}" if tried else ""
            raise GpioUnavailable(
                f"no GPIO on this machine ({type(err).__name__}: {err}{why}); on a PC use --fake, on a Pi install "
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
