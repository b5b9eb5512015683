"""Exceptions of the robot firmware, under `rimless.errors.RimlessError`, and `Interrupted` (a stop signal).

Leaves also inherit a builtin, so callers that only know `OSError`/`ValueError` still catch them.
`Interrupted` is a `BaseException`, like `KeyboardInterrupt`, so that no `except Exception` swallows it.
"""

from __future__ import annotations

import signal

from rimless.errors import InputFileError, ParameterError, RimlessError, UserError


class FirmwareError(RimlessError):
    """Base class of the firmware's own exceptions."""


class SensorError(FirmwareError, OSError):
    """The optical-flow sensor failed: SPI error, bad data, lost sync."""


class SensorNotFound(SensorError):
    """Product_ID / Inverse_Product_ID mismatch: no sensor, or wrong wiring."""


class SensorReset(SensorError):
    """A configuration register reads its power-on value again: the chip reset itself (a brown-out)."""


class SpiProtocolError(SensorError):
    """A transaction broke the ADNS-3080 SPI protocol (framing or timing); raised by the fake."""


class ConfigError(ParameterError):
    """A robot.toml field is invalid; the message names the file and the field."""


class ConfigFileError(InputFileError):
    """robot.toml cannot be read or parsed; the message names the file, line and column."""


class CommandError(UserError):
    """The robot refused a remote command, or the command channel failed; the message says why."""


class RobotUnreachable(CommandError, ConnectionError):
    """No answer from the robot's command port (bad host, robot down, firewall)."""


class Interrupted(BaseException):
    """A stop signal arrived; `exit_code` is 128 + its number (130 for Ctrl-C)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.name = signal.Signals(signum).name
        super().__init__(f"interrupted by {self.name}")

    @property
    def exit_code(self) -> int:
        """The shell's convention for a process ended by this signal."""
        return 128 + self.signum


__all__ = [
    "CommandError",
    "ConfigError",
    "ConfigFileError",
    "FirmwareError",
    "Interrupted",
    "RobotUnreachable",
    "SensorError",
    "SensorNotFound",
    "SpiProtocolError",
]
