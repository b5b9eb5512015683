"""robot.toml: the robot's configuration, strictly validated (unknown keys are errors).

Every error names the file, the section and the field. See `robot.toml` next to this module for
the documented example.
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from rimless.firmware.control.detector import DetectorParams
from rimless.firmware.control.faults import HealthLimits
from rimless.firmware.errors import ConfigError, ConfigFileError

# The robot's detector defaults differ from the library's on the leg-count safety checks (a counted leg locks
# only after two confirmed step intervals; an unconfirmed compression of 0.3 mm loses the count; nothing locks
# until the operator named the stance leg at arm). The firmware-in-the-loop simulator keeps the library
# defaults unless it reads a robot.toml.
ROBOT_DETECTOR_SAFETY: dict[str, Any] = {
    "confirm_steps": 2,
    "confirm_within_steps": 5,
    "doubt_compression_m": 0.0003,
    "doubt_noise_sigmas": 6.0,
    "touch_window_early_fraction": 0.5,
    "named_stance_required": 1,
}
ROBOT_DETECTOR = DetectorParams(**ROBOT_DETECTOR_SAFETY)

DEFAULT_CLUTCH_PINS = (17, 27, 22, 23, 24, 16, 20, 21)  # BCM; all >= 9, so pulled down at power-on
TOKEN_ENV = "RIMLESS_TOKEN"
TOKEN_FILE_ENV = "RIMLESS_TOKEN_FILE"
CREDENTIAL_NAME = "rimless-token"  # systemd LoadCredential= name, read from $CREDENTIALS_DIRECTORY
SPI_PINS = {0: frozenset({7, 8, 9, 10, 11}), 1: frozenset({16, 17, 18, 19, 20, 21})}  # CE*, MISO, MOSI, SCLK
BOOT_PULLED_UP_PINS = frozenset(range(2, 9))  # GPIO 0-8 have pull-ups at power-on; 0-1 are the HAT EEPROM


@dataclass(frozen=True)
class SensorConfig:
    """One ADNS-3080 and the legs (clutch indices, in touchdown order) whose motion it sees."""

    spi_bus: int = 0
    spi_device: int = 0
    spi_speed_hz: int = 2_000_000
    reset_pin: int = 25  # BCM pin wired to RESET (active high); the chip has no power-on reset
    npd_pin: int | None = None  # BCM pin wired to NPD (active-low power-down), if not tied high
    cs_pin: int | None = None  # BCM pin used as this sensor's chip select (active low) instead of the CE line
    resolution_cpi: int = 1600
    frame_rate_hz: float | None = None  # None = automatic (SmartSpeed)
    axis: str = "y"
    sign: int = 1
    counts_per_m: float = 1600 / 0.0254
    legs: tuple[int, ...] = tuple(range(8))
    squal_min: int = 10
    squal_low_s: float = 0.05
    saturated_samples_max: int = 3

    def health(self) -> HealthLimits:
        """The health-check limits of this sensor."""
        return HealthLimits(self.squal_min, self.squal_low_s, self.saturated_samples_max)


@dataclass(frozen=True)
class ClutchConfig:
    """Clutch outputs (BCM pins, leg i on pins[i])."""

    pins: tuple[int, ...] = DEFAULT_CLUTCH_PINS
    active_high: bool = True
    max_hold_s: float = 1.0
    start_leg_index: int = 0  # index into each sensor's `legs` of the leg standing on the ground at start
    boot_pull_up_reason: str = ""  # why clutch pins on GPIO 2-8 (pulled up at power-on) are safe here
    heartbeat_pin: int = 18  # toggled by the control loop at every sample (0 = none): feeds the clutch enable's
    # retriggerable monostable, so that a dead or stalled firmware cannot hold a clutch


@dataclass(frozen=True)
class SamplingConfig:
    """The control loop."""

    rate_hz: float = 300.0
    spin_s: float = 0.0003
    stall_timeout_s: float = 0.1  # the control thread not sampling this long trips the watchdog (s)
    id_check_interval_s: float = 1.0
    readback_every_samples: int = 1  # one identity/configuration register read back every this many samples
    loop_stall_s: float = 0.25  # the event loop not feeding the watchdog this long trips it (s)
    # the control thread SCHED_FIFO on one CPU, memory locked (`run --realtime`); None (not set): on when systemd
    # started this process (the unit), off elsewhere (`decide_realtime`; `run_robot` resolves it)
    realtime: bool | None = None
    realtime_priority: int = 50  # SCHED_FIFO priority (1..99; the unit's LimitRTPRIO must allow it)
    realtime_cpu: int = -1  # the CPU of the control thread (-1: the last one allowed)
    # why `realtime` is what it is (set with it by `with_realtime`; not a robot.toml key)
    realtime_why: str = field(default="", metadata={"toml": False})


@dataclass(frozen=True)
class TelemetryConfig:
    """UDP telemetry; empty host disables it."""

    host: str = ""
    port: int = 9870
    period_s: float = 0.02
    max_datagram_bytes: int = 1200
    batch: bool = True
    decimate: int = 1
    destinations: tuple[str, ...] = ()  # more receivers, "host:port" each

    def destinations_list(self) -> list[tuple[str, int]]:
        """Every receiver: `host`:`port` first (if host is set), then `destinations`."""
        out = [(self.host, self.port)] if self.host else []
        for d in self.destinations:
            out.append(parse_host_port(d))
        return out


@dataclass(frozen=True)
class CommandsConfig:
    """TCP command server. Token: $RIMLESS_TOKEN, else this, else a random one printed at start."""

    bind: str = "0.0.0.0"
    port: int = 9871
    token: str = ""
    token_file: str = ""  # a file holding the token (mode 0600); $RIMLESS_TOKEN_FILE wins
    link_timeout_s: float = 2.0  # armed remotely: disarm when no command or heartbeat for this long (0 = off)
    max_message_bytes: int = 4096
    max_connections: int = 16
    auth_timeout_s: float = 5.0  # a connection must send a valid command within this time
    idle_timeout_s: float = 60.0  # an authenticated connection silent this long is closed
    enabled: bool = True


@dataclass(frozen=True)
class LogConfig:
    """Trial logs on the robot."""

    dir: str = "trials"
    flush_interval_s: float = 0.2


@dataclass(frozen=True)
class RobotConfig:
    """The whole robot.toml."""

    sensors: tuple[SensorConfig, ...] = (SensorConfig(),)
    clutch: ClutchConfig = field(default_factory=ClutchConfig)
    sampling: SamplingConfig = field(default_factory=SamplingConfig)
    detector: DetectorParams = field(default_factory=lambda: ROBOT_DETECTOR)
    telemetry: TelemetryConfig = field(default_factory=TelemetryConfig)
    commands: CommandsConfig = field(default_factory=CommandsConfig)
    log: LogConfig = field(default_factory=LogConfig)

    def configured_stance_leg(self) -> int | None:
        """The clutch index `[clutch] start_leg_index` names on the first sensor counting legs (None: every sensor
        measures its one leg). What a walk that starts as configured stands on, for the fakes and the bench to name
        at arm; a robot does not trust it when `[detector] named_stance_required` is on."""
        for s in self.sensors:
            if len(s.legs) > 1:
                return s.legs[self.clutch.start_leg_index % len(s.legs)]
        return None

    def token(self) -> str:
        """The command token in force: $RIMLESS_TOKEN, $RIMLESS_TOKEN_FILE, the systemd credential
        `rimless-token`, `[commands] token_file`, then `[commands] token`. Raises ConfigError if the credential
        cannot be read, TokenFileError if a token file cannot be read or is not private (mode 0600, this user's)."""
        return self.token_and_setting()[0]

    def token_and_setting(self) -> tuple[str, str]:
        """The command token in force (see `token`) and the name of the setting it came from (for messages)."""
        if os.environ.get(TOKEN_ENV):
            return os.environ[TOKEN_ENV], f"${TOKEN_ENV}"
        from rimless.firmware.link.protocol import read_token_file

        if os.environ.get(TOKEN_FILE_ENV):
            return read_token_file(os.environ[TOKEN_FILE_ENV], f"${TOKEN_FILE_ENV}"), f"${TOKEN_FILE_ENV}"
        if os.environ.get("CREDENTIALS_DIRECTORY"):
            cred = Path(os.environ["CREDENTIALS_DIRECTORY"]) / CREDENTIAL_NAME
            if cred.exists():  # systemd keeps its credentials private to the service
                try:
                    return cred.read_text(encoding="utf-8").strip(), f"systemd credential {CREDENTIAL_NAME}"
                except (OSError, UnicodeDecodeError) as err:
                    raise ConfigError(f"systemd credential {cred}: cannot read the token ({err})") from None
        if self.commands.token_file:
            return read_token_file(self.commands.token_file, "[commands] token_file"), "[commands] token_file"
        return self.commands.token, "[commands] token"


_RANGES: dict[str, tuple[float, float]] = {
    "spi_bus": (0, 6),
    "spi_device": (0, 3),
    "spi_speed_hz": (10_000, 2_000_000),
    "reset_pin": (2, 27),
    "frame_rate_hz": (2000, 6469),
    "counts_per_m": (1.0, 1e8),
    "squal_min": (0, 169),
    "squal_low_s": (0.0, 10.0),
    "saturated_samples_max": (1, 1000),
    "max_hold_s": (0.01, 60.0),
    "start_leg_index": (0, 63),
    "rate_hz": (10.0, 5000.0),
    "spin_s": (0.0, 0.005),
    "stall_timeout_s": (0.005, 10.0),
    "id_check_interval_s": (0.0, 3600.0),
    "readback_every_samples": (0, 100000),
    "port": (0, 65535),
    "period_s": (0.001, 1.0),
    "max_datagram_bytes": (256, 65000),
    "decimate": (1, 1000),
    "link_timeout_s": (0.0, 3600.0),
    "max_message_bytes": (256, 1 << 20),
    "flush_interval_s": (0.01, 10.0),
    "npd_pin": (2, 27),
    "cs_pin": (2, 27),
    "heartbeat_pin": (0, 27),
    "loop_stall_s": (0.02, 10.0),
    "realtime_priority": (1, 99),
    "realtime_cpu": (-1, 1023),
    "max_connections": (2, 256),
    "auth_timeout_s": (0.1, 60.0),
    "idle_timeout_s": (1.0, 86400.0),
}


def parse_host_port(text: str) -> tuple[str, int]:
    """'host:port' or '[v6]:port' to (host, port); ValueError names the text."""
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"{text!r} is not host:port")
    return host, int(port)


def _check_value(where: str, name: str, value: Any, default: Any, hint: str) -> Any:
    """Type- and range-check one field against its default's type."""
    if hint.startswith("int") or isinstance(default, int) and not isinstance(default, bool):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}.{name} must be an integer, got {value!r}")
    elif isinstance(default, bool) or hint == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"{where}.{name} must be true or false, got {value!r}")
    elif isinstance(default, float) or hint.startswith("float"):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{where}.{name} must be a number, got {value!r}")
        value = float(value)
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where}.{name} must be a string, got {value!r}")
    if name in _RANGES and not isinstance(value, (str, bool)):
        lo, hi = _RANGES[name]
        if not lo <= value <= hi:
            raise ConfigError(f"{where}.{name} must be in [{lo:g}, {hi:g}], got {value!r}")
    return value


def _build(cls: type, table: Any, where: str) -> Any:
    if not isinstance(table, dict):
        raise ConfigError(f"{where} must be a table")
    known = {f.name: f for f in fields(cls) if f.metadata.get("toml", True)}
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise ConfigError(f"{where}: unknown field {unknown[0]!r} (known: {', '.join(sorted(known))})")
    defaults = cls()
    kwargs: dict[str, Any] = {}
    for name, value in table.items():
        default = getattr(defaults, name)
        hint = str(known[name].type)
        if name == "destinations":
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise ConfigError(f'{where}.{name} must be a list of "host:port" strings, got {value!r}')
            for v in value:
                try:
                    parse_host_port(v)
                except ValueError as err:
                    raise ConfigError(f"{where}.{name}: {err}") from None
            value = tuple(value)
        elif name in ("legs", "pins"):
            if (
                not isinstance(value, list)
                or not value
                or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
            ):
                raise ConfigError(f"{where}.{name} must be a non-empty list of integers, got {value!r}")
            if len(set(value)) != len(value):
                raise ConfigError(f"{where}.{name} has duplicates: {value!r}")
            value = tuple(value)
        elif name == "realtime":  # omitted = None (decided at start); written, a plain boolean
            value = _check_value(where, name, value, False, "bool")
        elif name in ("npd_pin", "cs_pin", "frame_rate_hz"):
            value = _check_value(where, name, value, 0.0 if name == "frame_rate_hz" else 0, hint)
        elif name == "axis":
            if value not in ("x", "y"):
                raise ConfigError(f'{where}.axis must be "x" or "y", got {value!r}')
        elif name == "sign":
            if value not in (1, -1) or isinstance(value, bool):
                raise ConfigError(f"{where}.sign must be 1 or -1, got {value!r}")
        elif name == "resolution_cpi":
            if value not in (400, 1600) or isinstance(value, bool):
                raise ConfigError(f"{where}.resolution_cpi must be 400 or 1600, got {value!r}")
        else:
            value = _check_value(where, name, value, default, hint)
        kwargs[name] = value
    return cls(**kwargs)


def config_from_dict(data: dict[str, Any], source: str = "robot.toml") -> RobotConfig:
    """Build and cross-check a `RobotConfig` from parsed TOML; errors name `source` and the field."""
    sections = {"sensor", "clutch", "sampling", "detector", "telemetry", "commands", "log"}
    unknown = sorted(set(data) - sections)
    if unknown:
        raise ConfigError(f"{source}: unknown section [{unknown[0]}] (known: {', '.join(sorted(sections))})")
    kw: dict[str, Any] = {}
    if "sensor" in data:
        raw = data["sensor"]
        if isinstance(raw, dict):
            raw = [raw]
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f"{source}: [[sensor]] must be one or more tables")
        kw["sensors"] = tuple(_build(SensorConfig, t, f"{source}: [[sensor]] #{i + 1}") for i, t in enumerate(raw))
    for name, cls in (
        ("clutch", ClutchConfig),
        ("sampling", SamplingConfig),
        ("telemetry", TelemetryConfig),
        ("commands", CommandsConfig),
        ("log", LogConfig),
    ):
        if name in data:
            kw[name] = _build(cls, data[name], f"{source}: [{name}]")
    if "detector" in data:
        det = _build(DetectorParams, data["detector"], f"{source}: [detector]")
        det = replace(det, **{k: v for k, v in ROBOT_DETECTOR_SAFETY.items() if k not in data["detector"]})
        if "confirm_within_steps" not in data["detector"] and det.confirm_within_steps:
            # a longer confirmation keeps the default's room: the touchdowns it needs and one bounce more
            det = replace(det, confirm_within_steps=max(det.confirm_within_steps, det.confirm_steps + 3))
        try:
            det.validated()
        except ValueError as err:
            raise ConfigError(f"{source}: [detector] {err}") from None
        kw["detector"] = det
    cfg = RobotConfig(**kw)
    n_legs = len(cfg.clutch.pins)
    seen: set[int] = set()
    for i, s in enumerate(cfg.sensors):
        for leg in s.legs:
            if not 0 <= leg < n_legs:
                raise ConfigError(
                    f"{source}: [[sensor]] #{i + 1}.legs: leg {leg} has no clutch pin (clutch.pins has {n_legs})"
                )
            if leg in seen:
                raise ConfigError(f"{source}: [[sensor]] #{i + 1}.legs: leg {leg} is watched by two sensors")
            seen.add(leg)
    _check_pins(cfg, source)
    return cfg


def _check_pins(cfg: RobotConfig, source: str) -> None:
    """Clutch pins off the SPI lines in use and the HAT EEPROM lines, on boot pulled-up lines only with
    a stated reason; no pin used twice; every sensor selected by exactly one CE line or GPIO."""
    where = f"{source}: [clutch] pins"
    spi_lines: set[int] = set()
    for s in cfg.sensors:
        spi_lines |= SPI_PINS.get(s.spi_bus, frozenset())
    for pin in cfg.clutch.pins:
        if not 0 <= pin <= 27:
            raise ConfigError(f"{where}: GPIO{pin} is not a Pi GPIO (0-27)")
        if pin in (0, 1):
            raise ConfigError(f"{where}: GPIO{pin} is reserved for the HAT ID EEPROM")
        if pin in spi_lines:
            raise ConfigError(f"{where}: GPIO{pin} is an SPI line in use by a sensor (SPI0 uses GPIO 7-11)")
        if pin in BOOT_PULLED_UP_PINS and not cfg.clutch.boot_pull_up_reason.strip():
            raise ConfigError(
                f"{where}: GPIO{pin} is pulled up at power-on, which engages the clutch while the Pi boots; "
                "use GPIO 12-27, or set [clutch] boot_pull_up_reason to say why it is safe here"
            )
    used = {pin: "a clutch pin" for pin in cfg.clutch.pins}
    hb = cfg.clutch.heartbeat_pin
    if hb:
        if hb == 1:
            raise ConfigError(f"{source}: [clutch] heartbeat_pin GPIO1 is reserved for the HAT ID EEPROM")
        if hb in used:
            raise ConfigError(f"{source}: [clutch] heartbeat_pin GPIO{hb} is also a clutch pin")
        if hb in spi_lines:
            raise ConfigError(f"{source}: [clutch] heartbeat_pin GPIO{hb} is an SPI line in use")
        used[hb] = "[clutch] heartbeat_pin"
    for i, s in enumerate(cfg.sensors):
        for name in ("reset_pin", "npd_pin", "cs_pin"):
            pin = getattr(s, name)
            if pin is None:
                continue
            if name == "reset_pin" and pin in [x.reset_pin for x in cfg.sensors[:i]]:
                continue  # sensors may share one RESET line
            if pin in used:
                raise ConfigError(f"{source}: [[sensor]] #{i + 1}.{name} GPIO{pin} is also {used[pin]}")
            if pin in spi_lines and name != "cs_pin":
                raise ConfigError(f"{source}: [[sensor]] #{i + 1}.{name} GPIO{pin} is an SPI line in use")
            used[pin] = f"[[sensor]] #{i + 1}.{name}"
    selects = [(s.spi_bus, s.spi_device if s.cs_pin is None else f"GPIO{s.cs_pin}") for s in cfg.sensors]
    if len(set(selects)) != len(selects):
        raise ConfigError(f"{source}: two sensors share a chip select (spi_bus/spi_device or cs_pin)")


@dataclass(frozen=True)
class RealtimeChoice:
    """Whether the control thread runs real time (`on`) and why (`why`, for the start-up line)."""

    on: bool
    why: str


def started_by_systemd(environ: Mapping[str, str] | None = None, pid: int | None = None) -> tuple[bool, str]:
    """Whether systemd started this very process as a service (the unit), and the evidence, from the environment
    systemd gives the processes it starts: $INVOCATION_ID (every unit, systemd >= 232) and $SYSTEMD_EXEC_PID
    (the PID it executed, systemd >= 248), or on an older systemd $NOTIFY_SOCKET (the unit is Type=notify).

    A shell or a test run from inside some service inherits $INVOCATION_ID (a desktop's terminal does), but
    $SYSTEMD_EXEC_PID then names another process: that is not the unit. `environ` and `pid` default to this
    process's own."""
    env = os.environ if environ is None else environ
    pid = os.getpid() if pid is None else pid
    if not env.get("INVOCATION_ID"):
        return False, "$INVOCATION_ID not set"
    exec_pid = env.get("SYSTEMD_EXEC_PID", "")
    if exec_pid:
        if exec_pid.strip() == str(pid):
            return True, "$INVOCATION_ID set and $SYSTEMD_EXEC_PID is this process"
        return False, f"$INVOCATION_ID inherited: $SYSTEMD_EXEC_PID is process {exec_pid.strip()}, not this one"
    if env.get("NOTIFY_SOCKET"):
        return True, "$INVOCATION_ID and $NOTIFY_SOCKET set"
    return False, "$INVOCATION_ID set but neither $SYSTEMD_EXEC_PID nor $NOTIFY_SOCKET"


def decide_realtime(
    sampling: SamplingConfig,
    *,
    flag: bool = False,
    source: str = "the configuration",
    environ: Mapping[str, str] | None = None,
    pid: int | None = None,
) -> RealtimeChoice:
    """Real time or not, and why: `--realtime` (`flag`) turns it on; else `[sampling] realtime` in `source` if
    written; else on when systemd started this process (`started_by_systemd`) and off elsewhere (a developer's
    runs, fake or not)."""
    if flag:
        return RealtimeChoice(True, "--realtime")
    if sampling.realtime is not None:
        return RealtimeChoice(sampling.realtime, f"[sampling] realtime = {str(sampling.realtime).lower()} in {source}")
    systemd, evidence = started_by_systemd(environ, pid)
    if systemd:
        return RealtimeChoice(True, f"started by systemd: {evidence}; [sampling] realtime not set")
    return RealtimeChoice(
        False, f"not started by systemd ({evidence}) and [sampling] realtime not set; --realtime turns it on"
    )


def with_realtime(cfg: RobotConfig, choice: RealtimeChoice) -> RobotConfig:
    """`cfg` with `[sampling] realtime` decided (`choice.on`) and the reason kept (`realtime_why`)."""
    return replace(cfg, sampling=replace(cfg.sampling, realtime=choice.on, realtime_why=choice.why))


def load_config(path: str | Path | None) -> RobotConfig:
    """Read robot.toml (None gives the defaults)."""
    if path is None:
        return RobotConfig()
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigFileError(f"{p}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigFileError(f"{p}: cannot read ({err})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigFileError(f"{p}: {err}") from None
    return config_from_dict(data, str(p))


def example_config_path() -> Path:
    """The documented example robot.toml shipped with the package."""
    return Path(__file__).with_name("robot.toml")
