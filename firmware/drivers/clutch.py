"""Leg clutches: one gpiozero output per leg, switching an XY-GMOS MOSFET module.

All outputs are driven to their *off* level at construction (gpiozero `initial_value=False`), and
`all_off()` is called before `close()`: gpiozero's close leaves the pin a floating input, so the
safe state must be driven first (and an external pull-down should hold the module input low).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from gpiozero import DigitalOutputDevice


class ClutchBank:
    """The clutches of all legs, indexed 0..n-1 in the order of `pins` (BCM numbers).

    :param active_high: True if a high pin engages the clutch.
    :param pin_factory: the gpiozero pin factory (MockFactory in tests and `--fake`).
    :param clock_ns: the time of each engage and release (the fakes' virtual clock with `--fake`).
    """

    def __init__(
        self,
        pins: Sequence[int],
        *,
        active_high: bool = True,
        pin_factory: Any = None,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        if len(set(pins)) != len(pins):
            raise ValueError(f"clutch pins must be distinct, got {list(pins)}")
        self.pins = list(pins)
        self.clock_ns = clock_ns
        self._devices: list[DigitalOutputDevice] = []
        try:
            for pin in self.pins:
                self._devices.append(
                    DigitalOutputDevice(pin, active_high=active_high, initial_value=False, pin_factory=pin_factory)
                )
        except Exception:
            self.close()
            raise
        self._engaged_since_ns: list[int | None] = [None] * len(self.pins)
        self._changed_ns: list[int | None] = [None] * len(self.pins)  # clock_ns of each output's last change

    def __len__(self) -> int:
        return len(self._devices)

    def engage(self, leg: int, t_ns: int | None = None) -> None:
        """Engage (lock) the clutch of `leg`."""
        self._devices[leg].on()
        if self._engaged_since_ns[leg] is None:
            self._engaged_since_ns[leg] = self._changed_ns[leg] = self.clock_ns() if t_ns is None else t_ns

    def release(self, leg: int) -> None:
        """Release the clutch of `leg`."""
        self._devices[leg].off()
        if self._engaged_since_ns[leg] is not None:
            self._changed_ns[leg] = self.clock_ns()
        self._engaged_since_ns[leg] = None

    def all_off(self) -> None:
        """Release every clutch; never raises before trying all of them."""
        first: BaseException | None = None
        for i, dev in enumerate(self._devices):
            try:
                dev.off()
            except Exception as err:  # keep going: the other clutches must still go off  # noqa: BLE001
                first = first or err
            if self._engaged_since_ns[i] is not None:
                self._changed_ns[i] = self.clock_ns()
            self._engaged_since_ns[i] = None
        if first is not None:
            raise first

    def engaged(self) -> list[int]:
        """Indices of the engaged clutches."""
        return [i for i, since in enumerate(self._engaged_since_ns) if since is not None]

    def engaged_since_ns(self, leg: int) -> int | None:
        """`clock_ns` at which `leg` was engaged, or None."""
        return self._engaged_since_ns[leg]

    def changed_ns(self, leg: int) -> int | None:
        """`clock_ns` of the last engage or release of `leg` (None before the first)."""
        return self._changed_ns[leg]

    def longest_hold_s(self, now_ns: int) -> float:
        """How long the longest-engaged clutch has been on (s), 0 if none."""
        held = [now_ns - s for s in self._engaged_since_ns if s is not None]
        return max(held) / 1e9 if held else 0.0

    def close(self) -> None:
        """Drive every clutch off, then release the pins."""
        try:
            for dev in self._devices:
                try:
                    dev.off()
                except Exception:  # noqa: BLE001 - closing must not stop half-way
                    pass
        finally:
            for dev in self._devices:
                dev.close()
            self._devices = []
