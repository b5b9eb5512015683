"""The firmware-in-the-loop configuration from the command's options or a robot.toml; errors name the option."""

from __future__ import annotations

from typing import Any

from rimless.errors import ParameterError


def build_config(
    *,
    rate_hz: float | None,
    clutch_delay_ms: float,
    release_delay_ms: float | None,
    noise_counts: float,
    jitter_ms: float,
    holding_force_n: float,
    seed: int,
    robot_config: Any = None,
) -> Any:
    """FirmwareLoopConfig from the CLI options; errors name the option.

    robot_config: a robot.toml (read by the firmware's own loader) supplying the detector parameters, the
    first sensor's resolution, calibration and health limits, the clutch timeout, whether there is one sensor
    or one per leg, and the sampling rate unless --rate-hz is given."""
    from rimless.firmware.control.faults import HealthLimits
    from rimless.sim.in_the_loop.loop import FirmwareLoopConfig

    extra: dict[str, Any] = {}
    if robot_config is not None:
        from rimless.firmware.service.config import load_config

        robot = load_config(robot_config)
        sensor = robot.sensors[0]
        if len(robot.sensors) == 1:
            sensors = "one"
        elif (
            len(robot.sensors) == 8
            and sorted(leg for s in robot.sensors for leg in s.legs) == list(range(8))
            and all(len(s.legs) == 1 for s in robot.sensors)
        ):
            sensors = "per-leg"
        else:
            raise ParameterError(
                f"--robot-config {robot_config}: the loop models one sensor counting the legs or "
                f"one sensor per leg (legs 0..7), not {len(robot.sensors)} sensors on "
                f"{[list(s.legs) for s in robot.sensors]}"
            )
        cpm_1600 = sensor.counts_per_m * (1.0 if sensor.resolution_cpi == 1600 else 4.0)
        extra = {
            "detector": robot.detector,
            "cpi": sensor.resolution_cpi,
            "counts_per_m_1600": cpm_1600,
            "health": HealthLimits(sensor.squal_min, sensor.squal_low_s, sensor.saturated_samples_max),
            "max_hold_s": robot.clutch.max_hold_s,
            "sensors": sensors,
        }
        if rate_hz is None:
            rate_hz = robot.sampling.rate_hz
    if rate_hz is None:
        rate_hz = 300.0

    checks = [
        ("--rate-hz", rate_hz, 1.0 <= rate_hz <= 1e6, "a sampling rate in [1, 1e6] Hz"),
        ("--clutch-delay-ms", clutch_delay_ms, 0.0 <= clutch_delay_ms <= 1000.0, "a delay in [0, 1000] ms"),
        ("--noise-counts", noise_counts, 0.0 <= noise_counts <= 1000.0, "a noise level in [0, 1000] counts"),
        ("--jitter-ms", jitter_ms, 0.0 <= jitter_ms <= 100.0, "a jitter in [0, 100] ms"),
        ("--holding-force-n", holding_force_n, holding_force_n > 0.0, "a force > 0 N (inf: a rigid clutch)"),
    ]
    if release_delay_ms is not None:
        checks.append(
            ("--release-delay-ms", release_delay_ms, 0.0 <= release_delay_ms <= 1000.0, "a delay in [0, 1000] ms")
        )
    for flag, value, ok, what in checks:
        if value != value or not ok:
            raise ParameterError(f"{flag} must be {what}, got {value}")
    release = clutch_delay_ms if release_delay_ms is None else release_delay_ms
    return FirmwareLoopConfig(
        rate_hz=rate_hz,
        jitter_s=jitter_ms * 1e-3,
        noise_counts=noise_counts,
        engage_delay_s=clutch_delay_ms * 1e-3,
        release_delay_s=release * 1e-3,
        holding_force_N=holding_force_n,
        seed=seed,
        **extra,
    ).validated()
