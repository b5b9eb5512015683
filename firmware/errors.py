"""Exceptions of the robot firmware, under `rimless.errors.RimlessError`.

Leaves also inherit a builtin, so callers that only know `OSError`/`ValueError` still catch them.
"""

from __future__ import annotations

from rimless.errors import InputFileError, ParameterError, RimlessError, UserError


class FirmwareError(RimlessError):
    """Base class of the firmware's own exceptions."""


class SensorError(FirmwareError, OSError):
    """The optical-flow sensor failed: SPI error, bad data, lost sync."""


class SensorNotFound(SensorError):
    """Product_ID / Inverse_Product_ID mismatch: no sensor, or wrong wiring."""


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


__all__ = [
    "CommandError",
    "ConfigError",
    "ConfigFileError",
    "FirmwareError",
    "RobotUnreachable",
    "SensorError",
    "SensorNotFound",
    "SpiProtocolError",
]
