"""`rimless robot bench --fake`: the whole app on the fake sensor and mock pins, timed.

Per rate it runs the real app (sampler thread, detector, clutch commands, UDP telemetry to a loopback
socket nobody reads, a trial log on disk) and reports: achieved rate, period jitter (|interval -
period| percentiles), sample-to-command latency (sample timestamp to the end of the control step,
including the clutch write when there is one) percentiles, missed deadlines and CPU share.
The fake's bus costs microseconds; a real Motion_Burst adds ~0.15-0.3 ms of SPI time per sample.
"""

from __future__ import annotations

import asyncio
import dataclasses
import socket
import tempfile
import time
from typing import Any

from rimless.firmware.app import RobotApp
from rimless.firmware.config import CommandsConfig, LogConfig, RobotConfig, SamplingConfig, TelemetryConfig
from rimless.firmware.fake_adns3080 import GaitTrajectory
from rimless.firmware.hardware import build_fake


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0..100), nearest-rank on the sorted values; nan when empty."""
    if not values:
        return float("nan")
    s = sorted(values)
    k = max(0, min(len(s) - 1, round(q / 100 * (len(s) - 1))))
    return s[k]


def bench_rate(rate_hz: float, duration_s: float = 3.0, base: RobotConfig | None = None) -> dict[str, Any]:
    """Run the fake app at `rate_hz` for `duration_s`; return the figures (times in ms)."""
    base = base or RobotConfig()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    port = sink.getsockname()[1]
    with tempfile.TemporaryDirectory(prefix="rimless-bench-") as tmp:
        cfg = dataclasses.replace(
            base,
            sampling=dataclasses.replace(base.sampling if base else SamplingConfig(), rate_hz=float(rate_hz)),
            telemetry=TelemetryConfig(host="127.0.0.1", port=port),
            commands=CommandsConfig(enabled=False),
            log=LogConfig(dir=tmp),
        )
        traj = GaitTrajectory(start_s=time.monotonic() + 0.2, step_period_s=0.25, compression_m=0.008,
                              compression_s=0.06)
        hw = build_fake(cfg, trajectory=traj)

        def ready(app: RobotApp) -> None:
            asyncio.get_running_loop().create_task(app._trial_start("bench"))

        app = RobotApp(cfg, hw, token="bench", record_timing=True, on_ready=ready)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        summary = asyncio.run(app.run(duration_s=duration_s, arm=True, handle_signals=False))
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    sink.close()
    assert app.sampler is not None
    times = list(app.sampler.sample_times_ns)
    period_ms = 1e3 / rate_hz
    jitter = [abs((b - a) * 1e-6 - period_ms) for a, b in zip(times, times[1:])]
    lat = [x * 1e-6 for x in app.sampler.latencies_ns]
    cmd_lat = [x * 1e-6 for x in app.sampler.command_latencies_ns]
    span_s = (times[-1] - times[0]) * 1e-9 if len(times) > 1 else 0.0
    return {
        "rate_hz": float(rate_hz),
        "achieved_rate_hz": round((len(times) - 1) / span_s, 2) if span_s > 0 else 0.0,
        "samples": len(times),
        "period_jitter_p50_ms": round(percentile(jitter, 50), 4),
        "period_jitter_p99_ms": round(percentile(jitter, 99), 4),
        "period_jitter_max_ms": round(max(jitter), 4) if jitter else float("nan"),
        "latency_p50_ms": round(percentile(lat, 50), 4),
        "latency_p99_ms": round(percentile(lat, 99), 4),
        "latency_max_ms": round(max(lat), 4) if lat else float("nan"),
        "clutch_commands": len(cmd_lat),
        "clutch_command_latency_max_ms": round(max(cmd_lat), 4) if cmd_lat else float("nan"),
        "missed_deadlines": summary.missed_deadlines,
        "cpu_share": round(cpu / wall, 3) if wall > 0 else 0.0,
        "faults": summary.faults,
        "duration_s": round(wall, 2),
    }
