"""`rimless robot bench --fake`: the whole app on the fake sensor and mock pins, timed, with every
part of the delay from the leg's true maximum compression to the clutch command reported apart.

Per rate it runs the real app (sampler thread, detector, clutch commands, UDP telemetry to a loopback
socket nobody reads, a trial log on disk) and reports:
- achieved rate, period jitter (|interval - period|) and missed deadlines;
- wake-up lateness: sample time minus its deadline (the thread's sleep and the GIL);
- control latency: sample timestamp to the end of the control step (clutch write included);
- SPI wire time per sample at the configured clock (bytes x 8 / clock + the in-window t_SRAD gaps,
  counted on the fake's bus): the fake answers in microseconds, a real bus takes this long;
- detector delay: lock time minus the true compression peak, and touchdown detection time minus the
  true touchdown, both on the fake's scripted trajectory;
- CPU share.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import signal
import socket
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import Any

from rimless.firmware.control.controller import EventRecord
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory
from rimless.firmware.errors import Interrupted
from rimless.firmware.service.app import RobotApp
from rimless.firmware.service.config import CommandsConfig, LogConfig, RobotConfig, SamplingConfig, TelemetryConfig
from rimless.firmware.service.hardware import build_fake
from rimless.firmware.service.logsetup import NonBlockingLog

MIN_RATE_HZ = 10.0  # the range `rimless robot bench --rate-hz` accepts
MAX_RATE_HZ = 5000.0


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0..100), nearest-rank on the sorted values; nan when empty."""
    if not values:
        return float("nan")
    s = sorted(values)
    k = max(0, min(len(s) - 1, round(q / 100 * (len(s) - 1))))
    return s[k]


def _ms(values: list[float], prefix: str) -> dict[str, float]:
    """p50/p99/max of `values` (already in ms) under `prefix`."""
    return {
        f"{prefix}_p50_ms": round(percentile(values, 50), 4),
        f"{prefix}_p99_ms": round(percentile(values, 99), 4),
        f"{prefix}_max_ms": round(max(values), 4) if values else float("nan"),
    }


def detector_delays(events: list[EventRecord], traj: GaitTrajectory) -> tuple[list[float], list[float]]:
    """(lock minus true peak, touchdown detected minus true touchdown), in ms, per step seen."""
    lock, touch = [], []
    for ev in events:
        t = ev.t_ns * 1e-9
        if ev.name == "lock":
            k = round((t - traj.start_s - traj.compression_s) / traj.step_period_s)
            lock.append((t - traj.max_compression_s(k)) * 1e3)
        elif ev.name == "touchdown":
            k = round((t - traj.start_s) / traj.step_period_s)
            touch.append((t - traj.touchdown_s(k)) * 1e3)
    return lock, touch


def bench_rate(
    rate_hz: float,
    duration_s: float = 3.0,
    base: RobotConfig | None = None,
    handle_signals: bool = False,
    realtime: bool = False,
) -> dict[str, Any]:
    """Run the fake app at `rate_hz` for `duration_s`; return the figures (times in ms). With `realtime`, the
    control thread takes the service's real-time settings (`[sampling] realtime`); `realtime` in the figures
    says what it got.

    With `handle_signals`, SIGINT/SIGTERM stop the run early; `stopped_by` then names the signal.
    """
    base = base or RobotConfig()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    port = sink.getsockname()[1]
    events: list[EventRecord] = []
    with tempfile.TemporaryDirectory(prefix="rimless-bench-") as tmp:
        cfg = dataclasses.replace(
            base,
            sampling=dataclasses.replace(
                base.sampling if base else SamplingConfig(),
                rate_hz=float(rate_hz),
                realtime=realtime or base.sampling.realtime,
            ),
            telemetry=TelemetryConfig(host="127.0.0.1", port=port),
            commands=CommandsConfig(enabled=False),
            log=LogConfig(dir=tmp),
        )
        traj = GaitTrajectory(
            start_s=time.monotonic() + 0.3, step_period_s=0.25, compression_m=0.008, compression_s=0.06
        )
        hw = build_fake(cfg, trajectory=traj)
        wire0 = sum(f.wire_time_s for f in hw.fakes)

        def ready(app: RobotApp) -> None:
            asyncio.get_running_loop().create_task(app.start_trial("bench"))

        app = RobotApp(cfg, hw, token="bench", record_timing=True, on_ready=ready, event_sink=events)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        summary = asyncio.run(app.run(duration_s=duration_s, arm=True, handle_signals=handle_signals))
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    sink.close()
    assert app.sampler is not None
    times = list(app.sampler.sample_times_ns)
    period_ms = 1e3 / rate_hz
    jitter = [abs((b - a) * 1e-6 - period_ms) for a, b in zip(times, times[1:])]
    lat = [x * 1e-6 for x in app.sampler.latencies_ns]
    cmd_lat = [x * 1e-6 for x in app.sampler.command_latencies_ns]
    late = [x * 1e-6 for x in app.sampler.wake_late_ns]
    span_s = (times[-1] - times[0]) * 1e-9 if len(times) > 1 else 0.0
    wire_s = sum(f.wire_time_s for f in hw.fakes) - wire0
    reads = max(1, summary.samples)
    lock_ms, touch_ms = detector_delays(events, traj)
    return {
        "rate_hz": float(rate_hz),
        "achieved_rate_hz": round((len(times) - 1) / span_s, 2) if span_s > 0 else 0.0,
        "samples": len(times),
        "period_jitter_p50_ms": round(percentile(jitter, 50), 4),
        "period_jitter_p99_ms": round(percentile(jitter, 99), 4),
        "period_jitter_max_ms": round(max(jitter), 4) if jitter else float("nan"),
        **_ms(late, "wake_late"),
        "latency_p50_ms": round(percentile(lat, 50), 4),
        "latency_p99_ms": round(percentile(lat, 99), 4),
        "latency_max_ms": round(max(lat), 4) if lat else float("nan"),
        "spi_clock_hz": cfg.sensors[0].spi_speed_hz,
        "spi_wire_per_sample_ms": round(wire_s / reads * 1e3, 4),
        "spi_wire_share": round(wire_s / reads * rate_hz, 3),
        "clutch_commands": len(cmd_lat),
        "clutch_command_latency_max_ms": round(max(cmd_lat), 4) if cmd_lat else float("nan"),
        "locks": len(lock_ms),
        **_ms(lock_ms, "lock_after_peak"),
        "lock_after_peak_min_ms": round(min(lock_ms), 4) if lock_ms else float("nan"),
        "touchdowns": len(touch_ms),
        **_ms(touch_ms, "touchdown_detect"),
        "missed_deadlines": summary.missed_deadlines,
        "cpu_share": round(cpu / wall, 3) if wall > 0 else 0.0,
        "faults": summary.faults,
        "duration_s": round(wall, 2),
        "stopped_by": app.signal_received,
        "realtime": summary.realtime,
    }


def bench_rates(
    rates_hz: Sequence[float],
    duration_s: float = 3.0,
    *,
    realtime: bool = False,
    on_rate: Callable[[float], None] | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """`bench_rate` at each rate in turn, logging only warnings; `on_rate(rate_hz)` before each run,
    `on_result(figures)` after it. A stop signal ends the bench: raises `Interrupted` naming it."""
    results = []
    for rate in rates_hz:
        if on_rate is not None:
            on_rate(rate)
        with NonBlockingLog(level=logging.WARNING):
            res = bench_rate(rate, duration_s, handle_signals=True, realtime=realtime)
        if res["stopped_by"]:
            raise Interrupted(int(getattr(signal, res["stopped_by"])))
        results.append(res)
        if on_result is not None:
            on_result(res)
    return results
