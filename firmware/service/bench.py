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
import contextlib
import dataclasses
import logging
import os
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
        summary = asyncio.run(
            app.run(
                duration_s=duration_s,
                arm=True,
                handle_signals=handle_signals,
                stance_leg=cfg.configured_stance_leg(),  # the fake gait starts on it: named at arm
            )
        )
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


# --- the reserved UDP path under a flood (issue 32) ----------------------------------------------------------

FLOOD_SOURCES = {
    "none": [],
    "spoof": ["127.0.0.1"],
    "spread": [f"127.0.{1 + k // 250}.{1 + k % 250}" for k in range(900)],
}

#: the flood's own bound (a safety: the bench stops it long before)
FLOOD_MAX_DATAGRAMS = 50_000_000

# argv: sources (comma-separated), port, count, listen (1: after each datagram, read what came back); stdin: a line
# stops it; stdout: "flooding" once its sockets are bound, then "sent answered stopped" (stopped: 1 if by stdin)
_FLOOD = """
import random, socket, sys, threading
sources, port, count, listen = sys.argv[1].split(","), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "1"
socks = []
for src in sources:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind((src, 0)); s.setblocking(False); socks.append(s)
junk = [b"rimless3 disarm " + b"%032x" % random.getrandbits(128) + b" - - " + b"0" * 64 + b" " + b"x" * 300,
        b'{"disarm": 9223372036854775807, "mac": "' + b"0" * 64 + b'", "pad": "' + b"x" * 300 + b'"}',
        b"garbage" * 50]
stop = threading.Event()
threading.Thread(target=lambda: (sys.stdin.readline(), stop.set()), daemon=True).start()
answered = sent = 0
print("flooding", flush=True)
for k in range(count):
    if stop.is_set():
        break
    s = socks[k % len(socks)]
    try:
        s.sendto(junk[k % 3], ("127.0.0.1", port)); sent += 1
    except OSError:
        pass
    if listen:
        try:
            s.recv(65536); answered += 1
        except OSError:
            pass
print(sent, answered, int(stop.is_set()), flush=True)
"""


@dataclasses.dataclass(frozen=True)
class FloodCount:
    """What a `Flood` did: datagrams sent, answers it read (0 unless it listened), and whether it was still
    flooding when stopped (False: it had ended on its count)."""

    sent: int
    answered: int
    stopped: bool


class Flood:
    """A flood of junk datagrams (a version-3 disarm with a bad MAC, a version-2 disarm numbered 2^63-1, garbage)
    to 127.0.0.1:`port` from another process, at the rate it can send, from each address of `sources` in turn,
    up to `count` datagrams; with `listen`, it reads after each datagram whatever was answered. It floods once
    constructed (it has said so: its sockets are bound); `stop()` ends it and returns its counts."""

    def __init__(
        self,
        sources: Sequence[str],
        port: int,
        *,
        count: int = FLOOD_MAX_DATAGRAMS,
        listen: bool = False,
        preexec_fn: Callable[[], Any] | None = None,
    ) -> None:
        import subprocess
        import sys

        self.proc = subprocess.Popen(
            [sys.executable, "-c", _FLOOD, ",".join(sources), str(port), str(count), str(int(listen))],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            preexec_fn=preexec_fn,
        )
        assert self.proc.stdin is not None and self.proc.stdout is not None
        first = self.proc.stdout.readline().strip()
        if first != "flooding":
            self.close()
            raise RuntimeError(f"the flood did not start (it said {first!r})")

    def stop(self) -> FloodCount:
        """Stop the flood (if it still runs) and return its counts."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        with contextlib.suppress(BrokenPipeError):  # a flood that ended on its count
            self.proc.stdin.write("stop\n")
            self.proc.stdin.flush()
        words = self.proc.stdout.readline().split()
        if len(words) != 3:
            raise RuntimeError(f"the flood ended without its counts (it said {' '.join(words)!r})")
        sent, answered, stopped = (int(w) for w in words)
        return FloodCount(sent, answered, bool(stopped))

    def close(self) -> None:
        """Kill the flood's process if it still runs, and wait for it."""
        self.proc.kill()
        self.proc.wait(30)

    def __enter__(self) -> Flood:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_DISARMS = """
import sys, time
from rimless.errors import RimlessError
from rimless.firmware.link.remote import send_disarm_datagram
port, n, token = int(sys.argv[1]), int(sys.argv[2]), sys.stdin.readline().strip()
for _ in range(n):
    t0 = time.perf_counter()
    try:
        send_disarm_datagram("127.0.0.1", token=token, port=port, timeout_s=2.0)
        print(round((time.perf_counter() - t0) * 1e3, 3), flush=True)
    except RimlessError:
        print("lost", flush=True)
    time.sleep(0.05)
"""


def bench_flood(
    flood: str = "spoof", rate_hz: float = 1000.0, phase_s: float = 2.0, disarms: int = 10, realtime: bool = False
) -> dict[str, Any]:
    """The whole fake app with its command server on the loopback, armed, at `rate_hz`: `phase_s` without a
    flood (the reference), then `phase_s` with a flood of junk (bad MACs, version-2 garbage, garbage) from
    another process at the rate it can send, from the operator's own address (`flood="spoof"`) or spread over
    900 addresses (`"spread"`), or none; during the flood, `disarms` UDP disarms from a third process (an
    operator PC on the same machine). Returns the loop rate of each phase and their ratio, the time each
    disarm took to be confirmed (the robot's signed answer to its first round: the disarm is acted on before
    it is sent), the datagrams the flood sent and the reserved path checked. Everything shares this machine's
    CPUs: a real flood and operator would be other machines."""
    import secrets
    import subprocess
    import sys
    import threading

    if flood not in FLOOD_SOURCES:
        raise ValueError(f"flood must be one of {', '.join(FLOOD_SOURCES)}, got {flood!r}")
    token = secrets.token_urlsafe(24)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    marks: dict[str, int] = {}
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="rimless-bench-") as tmp:
        cfg = RobotConfig(
            sampling=SamplingConfig(rate_hz=float(rate_hz), realtime=realtime),
            telemetry=TelemetryConfig(host="127.0.0.1", port=sink.getsockname()[1]),
            commands=CommandsConfig(bind="127.0.0.1", port=0, token=token, link_timeout_s=0.0),
            log=LogConfig(dir=tmp),
        )
        traj = GaitTrajectory(
            start_s=time.monotonic() + 0.3, step_period_s=0.25, compression_m=0.008, compression_s=0.06
        )
        hw = build_fake(cfg, trajectory=traj)

        def plain() -> None:  # the flood and the operator are other machines: never the robot's real-time class
            with contextlib.suppress(OSError, AttributeError):
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

        def drive(app: RobotApp, loop: asyncio.AbstractEventLoop) -> None:
            proc = None
            try:
                port = app.command_port
                if port is None:
                    raise RuntimeError("the command server did not start")
                time.sleep(phase_s)
                marks["flood_ns"] = time.monotonic_ns()
                if FLOOD_SOURCES[flood]:
                    proc = Flood(FLOOD_SOURCES[flood], port, preexec_fn=plain)
                client = subprocess.run(
                    [sys.executable, "-c", _DISARMS, str(port), str(disarms)],
                    input=token + "\n",
                    capture_output=True,
                    text=True,
                    timeout=120,
                    preexec_fn=plain,
                )
                out["disarm_ms"] = [float(x) if x != "lost" else None for x in client.stdout.split()]
                time.sleep(max(0.0, phase_s - (time.monotonic_ns() - marks["flood_ns"]) * 1e-9))
                marks["end_ns"] = time.monotonic_ns()
                udp = app.server._udp if app.server is not None else None
                out["reserved_checked"] = 0 if udp is None else udp.received
                out["reserved_rejected"] = 0 if udp is None else udp.rejected
                if proc is not None:
                    out["flood_sent"] = proc.stop().sent
            finally:
                if proc is not None:
                    proc.close()
                loop.call_soon_threadsafe(app.request_stop, "bench done")

        def ready(app: RobotApp) -> None:
            threading.Thread(target=drive, args=(app, asyncio.get_running_loop()), daemon=True).start()

        app = RobotApp(cfg, hw, token=token, record_timing=True, on_ready=ready)
        cpu0 = time.process_time()
        asyncio.run(
            app.run(
                duration_s=4 * phase_s + 120, arm=True, handle_signals=False, stance_leg=cfg.configured_stance_leg()
            )
        )
        cpu = time.process_time() - cpu0
    sink.close()
    assert app.sampler is not None
    times = list(app.sampler.sample_times_ns)

    def rate(lo: int, hi: int) -> float:
        ts = [t for t in times if lo <= t < hi]
        return round((len(ts) - 1) / ((ts[-1] - ts[0]) * 1e-9), 1) if len(ts) > 1 else 0.0

    if "end_ns" not in marks:
        raise RuntimeError("the flood bench did not complete (see the error above)")
    before = rate(times[0] + 300_000_000, marks["flood_ns"])
    during = rate(marks["flood_ns"], marks["end_ns"])
    ms = [x for x in out.get("disarm_ms", []) if x is not None]
    return {
        "flood": flood,
        "sources": len(FLOOD_SOURCES[flood]),
        "rate_hz": float(rate_hz),
        "loop_rate_before_hz": before,
        "loop_rate_during_hz": during,
        "loop_rate_ratio": round(during / before, 3) if before else float("nan"),
        "disarms": disarms,
        "disarms_confirmed": len(ms),
        "disarm_ms": out.get("disarm_ms", []),
        **_ms(ms, "disarm"),
        "flood_sent": out.get("flood_sent", 0),
        "reserved_checked": out.get("reserved_checked", 0),
        "reserved_rejected": out.get("reserved_rejected", 0),
        "cpu_s": round(cpu, 2),
        "realtime": realtime,
    }


def bench_check_cost(n: int = 20000) -> dict[str, Any]:
    """CPU time per junk datagram of the reserved path's check (`check_reserved_request`: layout, one HMAC with
    precomputed pads, no JSON) beside the reference the version-2 path did on every datagram (`json.loads`, then
    `hmac.new` over the number), both on the same datagrams in one run; the ratio from CPU time."""
    import hashlib
    import hmac
    import json
    import random

    from rimless.firmware.link.protocol import Sha256Mac, check_reserved_request

    token = f"bench-{random.getrandbits(128):032x}"
    mac = Sha256Mac(token.encode())
    v3 = b"rimless3 disarm " + b"%032x" % random.getrandbits(128) + b" - - " + b"0" * 64 + b" " + b"x" * 300
    v2 = json.dumps({"disarm": 2**62, "mac": "0" * 64, "pad": "x" * 300}).encode()

    def reference(data: bytes) -> bool:
        obj = json.loads(data)
        n = obj["disarm"]
        good = hmac.new(token.encode(), f"disarm\n{n}".encode(), hashlib.sha256).hexdigest()
        return hmac.compare_digest(obj["mac"].encode(), good.encode())

    t0 = time.process_time()
    for _ in range(n):
        check_reserved_request(v3, mac)
    fast = (time.process_time() - t0) / n
    t0 = time.process_time()
    for _ in range(n):
        reference(v2)
    ref = (time.process_time() - t0) / n
    return {
        "datagrams": n,
        "check_us": round(fast * 1e6, 2),
        "reference_us": round(ref * 1e6, 2),
        "ratio": round(ref / fast, 2) if fast > 0 else float("nan"),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m rimless.firmware.service.bench --flood none,spoof,spread [--rate-hz 1000] [--phase-s 2]
    [--realtime]`: the reserved path's figures under floods, one JSON object per line."""
    import argparse
    import json

    p = argparse.ArgumentParser(prog="python -m rimless.firmware.service.bench")
    p.add_argument("--flood", default="none,spoof,spread")
    p.add_argument("--rate-hz", type=float, default=1000.0)
    p.add_argument("--phase-s", type=float, default=2.0)
    p.add_argument("--disarms", type=int, default=10)
    p.add_argument("--realtime", action="store_true")
    args = p.parse_args(argv)
    print(json.dumps({"check_cost": bench_check_cost()}), flush=True)
    for flood in args.flood.split(","):
        with NonBlockingLog(level=logging.ERROR):
            res = bench_flood(flood, args.rate_hz, args.phase_s, args.disarms, args.realtime)
        print(json.dumps(res), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
