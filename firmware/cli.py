"""`rimless robot ...`: thin commands over the firmware library.

Module level imports only typer and the stdlib, so `rimless --help` stays fast; everything else is
imported inside the commands.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

app = typer.Typer(no_args_is_help=True)

_HOST = Annotated[str, typer.Option("--host", help="Robot host name or IP address.")]
_PORT = Annotated[int, typer.Option("--port", min=1, max=65535, help="Robot command port (TCP).")]
_TOKEN = Annotated[
    Optional[str], typer.Option("--token", help="Shared command token (default: $RIMLESS_TOKEN).", show_default=False)
]
_CONFIG = Annotated[
    Optional[Path], typer.Option("--config", help="robot.toml (default: built-in defaults).", show_default=False)
]


def _user_facing(func: Any) -> Any:
    from rimless.cli import user_facing

    return user_facing(func)


def _token(token: str | None) -> str:
    from rimless.firmware.errors import CommandError

    tok = token or os.environ.get("RIMLESS_TOKEN", "")
    if not tok:
        raise CommandError("no command token: pass --token or set RIMLESS_TOKEN (the robot prints it at start)")
    return tok


def _remote(host: str, port: int, token: str | None, cmd: str, args: dict[str, Any] | None = None) -> None:
    from rimless.cli import print_json, user_facing
    from rimless.firmware.commands import send_command

    @user_facing
    def go() -> None:
        print_json(send_command(host, cmd, args, token=_token(token), port=port))

    go()


@app.command()
def status(host: _HOST, port: _PORT = 9871, token: _TOKEN = None) -> None:
    """Print the robot's state (armed, faults, phases, counters) as JSON."""
    _remote(host, port, token, "status")


@app.command()
def arm(host: _HOST, port: _PORT = 9871, token: _TOKEN = None) -> None:
    """Arm: clear latched faults and let the detector switch the clutches."""
    _remote(host, port, token, "arm")


@app.command()
def disarm(host: _HOST, port: _PORT = 9871, token: _TOKEN = None) -> None:
    """Disarm: every clutch off."""
    _remote(host, port, token, "disarm")


@app.command("set")
def set_param(
    name: Annotated[str, typer.Argument(help="Detector parameter, e.g. touch_velocity_m_s.")],
    value: Annotated[float, typer.Argument(help="New value (SI units, as the name says).")],
    host: _HOST,
    port: _PORT = 9871,
    token: _TOKEN = None,
) -> None:
    """Set a detector parameter on the running robot."""
    v: float | int = int(value) if name.endswith("_samples") and value == int(value) else value
    _remote(host, port, token, "set", {"name": name, "value": v})


@app.command("trial-start")
def trial_start(
    host: _HOST,
    name: Annotated[str, typer.Option("--name", help="Trial name (letters, digits, _.-).")] = "trial",
    port: _PORT = 9871,
    token: _TOKEN = None,
) -> None:
    """Start a trial log on the robot (every sample and event)."""
    _remote(host, port, token, "trial_start", {"name": name})


@app.command("trial-stop")
def trial_stop(host: _HOST, port: _PORT = 9871, token: _TOKEN = None) -> None:
    """Stop the running trial log; prints its path on the robot."""
    _remote(host, port, token, "trial_stop")


@app.command()
def run(
    config: _CONFIG = None,
    fake: Annotated[bool, typer.Option("--fake", help="Fake sensor replaying a synthetic gait, mock pins.")] = False,
    duration_s: Annotated[
        Optional[float], typer.Option("--duration-s", min=0.0, help="Stop after this many seconds.", show_default=False)
    ] = None,
    arm_at_start: Annotated[bool, typer.Option("--arm", help="Arm at start (default: wait for `arm`).")] = False,
) -> None:
    """Run the firmware until SIGINT/SIGTERM (or --duration-s); clutches off on every exit path."""
    import asyncio
    import logging
    import sys

    from rimless.cli import user_facing

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s", stream=sys.stderr)

    @user_facing
    def go() -> int:
        from rimless.firmware.app import RobotApp
        from rimless.firmware.config import load_config
        from rimless.firmware.errors import SensorError
        from rimless.firmware.hardware import build_fake, build_real

        cfg = load_config(config)
        try:
            hw = build_fake(cfg) if fake else build_real(cfg)
        except SensorError as err:
            from rimless.firmware.errors import CommandError

            raise CommandError(f"sensor: {err}") from None
        robot = RobotApp(cfg, hw)
        if robot.token_generated:
            typer.echo(f"command token (generated): {robot.token}", err=True)
        mode = "fake" if fake else "hardware"
        typer.echo(f"rimless robot: running ({mode}) at {cfg.sampling.rate_hz:g} Hz", err=True)
        try:
            summary = asyncio.run(robot.run(duration_s=duration_s, arm=arm_at_start))
        except OSError as err:
            from rimless.firmware.errors import CommandError

            raise CommandError(f"cannot start: {err}") from None
        typer.echo(
            f"stopped ({summary.stop_reason}): {summary.samples} samples at {summary.achieved_rate_hz:.1f} Hz, "
            f"{summary.missed_deadlines} missed deadlines, {summary.clutch_commands} clutch commands, "
            f"faults: {', '.join(summary.faults) or 'none'}",
            err=True,
        )
        if fake and hw.pin_factory is not None:
            # The mock pins' histories, so a test (or a curious user) can see the clutches ended off.
            hist = []
            for pin in cfg.clutch.pins:
                states = hw.pin_factory.pin(pin).states
                levels = "".join("1" if st.state else "0" for st in states)
                hist.append(f"GPIO{pin}={levels}")
            typer.echo("fake clutch pin levels (history): " + " ".join(hist), err=True)
        if summary.error:
            typer.echo(f"error: {summary.error}", err=True)
            return 1
        return 0

    code = go()
    if code:
        raise typer.Exit(code)


@app.command()
def check(
    config: _CONFIG = None,
    fake: Annotated[bool, typer.Option("--fake", help="Check the fake sensor and mock pins.")] = False,
    click: Annotated[bool, typer.Option("--click/--no-click", help="Click each clutch on for 0.2 s.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Check the hardware: sensor IDs, SQUAL, frame rate, and a clutch click test."""
    import time

    from rimless.cli import print_json, user_facing

    @user_facing
    def go() -> None:
        from rimless.firmware.config import load_config
        from rimless.firmware.errors import CommandError, SensorError
        from rimless.firmware.hardware import build_fake, build_real

        cfg = load_config(config)
        try:
            hw = build_fake(cfg) if fake else build_real(cfg)
        except SensorError as err:
            raise CommandError(f"sensor check failed: {err}") from None
        report: dict[str, Any] = {"sensors": [], "clutches": []}
        try:
            for i, sensor in enumerate(hw.sensors):
                rev = sensor.verify_id()
                squal = [sensor.squal() for _ in range(5)]
                report["sensors"].append({
                    "index": i, "product_id_ok": True, "revision_id": rev, "squal": max(squal),
                    "frame_rate_hz": round(sensor.frame_rate_hz(), 1), "resolution_cpi": int(sensor.resolution()),
                })
            if click:
                for leg, pin in enumerate(hw.clutches.pins):
                    hw.clutches.engage(leg)
                    time.sleep(0.2)
                    hw.clutches.release(leg)
                    time.sleep(0.1)
                    report["clutches"].append({"leg": leg, "pin": pin, "clicked": True})
        except SensorError as err:
            raise CommandError(f"sensor check failed: {err}") from None
        finally:
            hw.close()
        if as_json:
            print_json(report)
            return
        for s in report["sensors"]:
            typer.echo(
                f"sensor {s['index']}: ADNS-3080 found (revision 0x{s['revision_id']:02X}), SQUAL {s['squal']}, "
                f"{s['frame_rate_hz']:.0f} fps, {s['resolution_cpi']} cpi"
            )
        for c in report["clutches"]:
            typer.echo(f"clutch {c['leg']} (GPIO{c['pin']}): clicked on for 0.2 s, off")

    go()


@app.command()
def listen(
    port: Annotated[int, typer.Option("--port", min=1, max=65535, help="UDP port to listen on.")] = 9870,
    bind: Annotated[str, typer.Option("--bind", help="Local address to bind.")] = "0.0.0.0",
    out: Annotated[
        Optional[Path], typer.Option("--out", help="Record every telemetry object to this JSON Lines file.", show_default=False)
    ] = None,
    duration_s: Annotated[
        Optional[float], typer.Option("--duration-s", min=0.0, help="Stop after this many seconds.", show_default=False)
    ] = None,
    summary_every_s: Annotated[float, typer.Option("--summary-every-s", min=0.05, help="Live summary period.")] = 1.0,
) -> None:
    """Receive the robot's UDP telemetry: record it to a file and show a live summary."""
    from rimless.cli import user_facing

    @user_facing
    def go() -> None:
        from rimless.firmware.listen import listen as do_listen

        do_listen(bind=bind, port=port, out=out, duration_s=duration_s, summary_every_s=summary_every_s,
                  echo=lambda line: typer.echo(line, err=True))

    go()


@app.command()
def bench(
    fake: Annotated[bool, typer.Option("--fake", help="Run on the fake sensor and mock pins (required).")] = False,
    rate_hz: Annotated[str, typer.Option("--rate-hz", help="Comma-separated sampling rates.")] = "300,1000,2000",
    duration_s: Annotated[float, typer.Option("--duration-s", min=0.5, help="Seconds per rate.")] = 3.0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object per rate (a JSON list).")] = False,
) -> None:
    """Benchmark the control loop: rate, period jitter, sample-to-command latency, missed deadlines, CPU."""
    from rimless.cli import print_json, user_facing

    @user_facing
    def go() -> None:
        from rimless.errors import ParameterError
        from rimless.firmware.bench import bench_rate

        if not fake:
            raise ParameterError("--fake is required: the bench runs on the fake sensor (use `run` on the robot)")
        try:
            rates = [float(r) for r in rate_hz.split(",") if r.strip()]
        except ValueError:
            raise ParameterError(f"--rate-hz must be comma-separated numbers, got {rate_hz!r}") from None
        if not rates or any(not 10 <= r <= 5000 for r in rates):
            raise ParameterError(f"--rate-hz values must be in 10..5000, got {rate_hz!r}")
        results = []
        for r in rates:
            res = bench_rate(r, duration_s)
            results.append(res)
            if not as_json:
                typer.echo(
                    f"{r:7.0f} Hz: achieved {res['achieved_rate_hz']:.1f} Hz, period jitter p50/p99 "
                    f"{res['period_jitter_p50_ms']:.3f}/{res['period_jitter_p99_ms']:.3f} ms, latency p50/p99/max "
                    f"{res['latency_p50_ms']:.3f}/{res['latency_p99_ms']:.3f}/{res['latency_max_ms']:.3f} ms, "
                    f"missed {res['missed_deadlines']}, CPU {100 * res['cpu_share']:.0f} %, "
                    f"{res['clutch_commands']} clutch commands"
                )
        if as_json:
            print_json(results)

    go()
