"""`rimless robot ...`: thin commands over the firmware library; each parses its options, calls one library
function and prints what it returns.

Module level imports only typer, the stdlib and the CLI rules (`rimless.cli_rules`), so `rimless --help`
stays fast; the firmware is imported inside the commands.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.cli_rules import EXIT_INTERRUPTED, print_json, user_facing

# Usage errors (one line, exit 2) and negative numbers as values come from the root group (rimless.cli).
app = typer.Typer(no_args_is_help=True)

_HOST = Annotated[str, typer.Option("--host", help="Robot host name or IP address.")]
_PORT = Annotated[int, typer.Option("--port", min=1, max=65535, help="Robot command port (TCP).")]
_TOKEN = Annotated[
    str | None,
    typer.Option(
        "--token",
        help="Shared command token (visible in the process list: prefer --token-file or $RIMLESS_TOKEN).",
        show_default=False,
    ),
]
_TOKEN_FILE = Annotated[
    Path | None,
    typer.Option(
        "--token-file",
        help="File holding the command token, mode 0600 (default: $RIMLESS_TOKEN_FILE).",
        show_default=False,
    ),
]
_CONFIG = Annotated[
    Path | None, typer.Option("--config", help="robot.toml (default: built-in defaults).", show_default=False)
]


def _say(line: str) -> bool:
    """One line to stderr that never blocks: written straight to the descriptor in non-blocking mode, dropped
    (False) when stderr is full or gone, so a stalled terminal or journal never holds up start-up or exit."""
    import sys

    try:
        sys.stderr.flush()
    except Exception:  # noqa: BLE001
        pass
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # no descriptor (a test runner): the ordinary way
        typer.echo(line, err=True)
        return True
    data = (line + "\n").encode(errors="replace")
    blocking = os.get_blocking(fd)
    try:
        os.set_blocking(fd, False)
        os.write(fd, data)
        return True
    except OSError:
        return False
    finally:
        try:
            os.set_blocking(fd, blocking)
        except OSError:
            pass


def _token(token: str | None, token_file: Path | None = None) -> str:
    """The command token: --token (warned: the process list shows it), --token-file, $RIMLESS_TOKEN, then
    $RIMLESS_TOKEN_FILE. A token file must be private (mode 0600)."""
    from rimless.firmware.errors import CommandError
    from rimless.firmware.link.protocol import read_token_file

    if token:
        typer.echo(
            "warning: --token is visible to every user in the process list; use --token-file or $RIMLESS_TOKEN",
            err=True,
        )
        return token
    if token_file is not None:
        return read_token_file(token_file, "--token-file")
    if os.environ.get("RIMLESS_TOKEN"):
        return os.environ["RIMLESS_TOKEN"]
    if os.environ.get("RIMLESS_TOKEN_FILE"):
        return read_token_file(os.environ["RIMLESS_TOKEN_FILE"], "$RIMLESS_TOKEN_FILE")
    raise CommandError(
        "no command token: pass --token-file or set RIMLESS_TOKEN_FILE or RIMLESS_TOKEN (the robot "
        "says at start where its generated token is)"
    )


def _remote(
    host: str, port: int, tokens: tuple[str | None, Path | None], cmd: str, args: dict[str, Any] | None = None
) -> None:
    from rimless.firmware.link.remote import send_command

    @user_facing
    def go() -> None:
        print_json(send_command(host, cmd, args, token=_token(*tokens), port=port))

    _interruptible(go)


def _interruptible(fn: Any) -> Any:
    """Run `fn`; Ctrl-C (or SIGTERM/SIGHUP/SIGQUIT) ends it with one line and 128 + the signal number."""
    from rimless.firmware.service.safety import Interrupted, stop_on_signals

    try:
        with stop_on_signals():
            return fn()
    except Interrupted as sig:
        typer.echo("interrupted" if sig.name == "SIGINT" else f"error: {sig}", err=True)
        raise typer.Exit(sig.exit_code) from None
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        raise typer.Exit(EXIT_INTERRUPTED) from None


_JSON = Annotated[bool, typer.Option("--json", help="Print JSON (these commands always do; accepted for scripts).")]


@app.command()
def status(
    host: _HOST, port: _PORT = 9871, token: _TOKEN = None, token_file: _TOKEN_FILE = None, as_json: _JSON = False
) -> None:
    """Print the robot's state (armed, faults, phases, stance legs, counters, link) as JSON.

    When the TCP channel does not answer, the short status of the reserved UDP path is printed
    instead (armed, faults, engaged clutches), with "via": "udp".
    """
    from rimless.firmware.link.remote import robot_status

    @user_facing
    def go() -> None:
        print_json(robot_status(host, token=_token(token, token_file), port=port))

    _interruptible(go)


@app.command()
def ping(
    host: _HOST, port: _PORT = 9871, token: _TOKEN = None, token_file: _TOKEN_FILE = None, as_json: _JSON = False
) -> None:
    """Check that the robot answers (and count as a heartbeat)."""
    _remote(host, port, (token, token_file), "ping")


@app.command()
def arm(
    host: _HOST,
    port: _PORT = 9871,
    token: _TOKEN = None,
    token_file: _TOKEN_FILE = None,
    stance_leg: Annotated[
        int | None,
        typer.Option(
            "--stance-leg",
            min=0,
            help="Clutch index of the leg on the ground now: re-synchronises "
            "the leg count (needed after a leg_sync_lost fault).",
            show_default=False,
        ),
    ] = None,
    as_json: _JSON = False,
) -> None:
    """Arm: clear latched faults and let the detector switch the clutches.

    Armed from here, the robot disarms itself when no command or heartbeat arrives for its
    link_timeout_s (2 s by default): keep `rimless robot listen --host ...` or
    `rimless robot heartbeat` running.
    """
    _remote(host, port, (token, token_file), "arm", {} if stance_leg is None else {"stance_leg": stance_leg})


@app.command()
def disarm(
    host: _HOST, port: _PORT = 9871, token: _TOKEN = None, token_file: _TOKEN_FILE = None, as_json: _JSON = False
) -> None:
    """Disarm: every clutch off.

    Sent first over the robot's reserved UDP path (no connection to wait for, so a flood of TCP
    connections cannot delay it), then confirmed over TCP; prints the robot's state.
    """
    from rimless.firmware.link.remote import robot_disarm

    @user_facing
    def go() -> None:
        print_json(robot_disarm(host, token=_token(token, token_file), port=port))

    _interruptible(go)


@app.command("set")
def set_param(
    name: Annotated[str, typer.Argument(help="Detector parameter, e.g. touch_velocity_m_s.")],
    value: Annotated[
        str, typer.Argument(help="New value (SI units, as the name says; negative numbers are values, not options).")
    ],
    host: _HOST,
    port: _PORT = 9871,
    token: _TOKEN = None,
    token_file: _TOKEN_FILE = None,
    as_json: _JSON = False,
) -> None:
    """Set a detector parameter on the running robot."""
    from rimless.errors import ParameterError

    @user_facing
    def parse() -> float | int:
        try:
            v = float(value)
        except ValueError:
            raise ParameterError(f"VALUE must be a number, got {value!r}") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise ParameterError(f"VALUE must be a finite number, got {value!r}")
        return int(v) if name.endswith("_samples") and v == int(v) else v

    _remote(host, port, (token, token_file), "set", {"name": name, "value": parse()})


@app.command("trial-start")
def trial_start(
    host: _HOST,
    name: Annotated[str, typer.Option("--name", help="Trial name (letters, digits, _.-).")] = "trial",
    port: _PORT = 9871,
    token: _TOKEN = None,
    token_file: _TOKEN_FILE = None,
    as_json: _JSON = False,
) -> None:
    """Start a trial log on the robot (every sample and event)."""
    _remote(host, port, (token, token_file), "trial_start", {"name": name})


@app.command("trial-stop")
def trial_stop(
    host: _HOST, port: _PORT = 9871, token: _TOKEN = None, token_file: _TOKEN_FILE = None, as_json: _JSON = False
) -> None:
    """Stop the running trial log; prints its path on the robot."""
    _remote(host, port, (token, token_file), "trial_stop")


@app.command()
def heartbeat(
    host: _HOST,
    port: _PORT = 9871,
    token: _TOKEN = None,
    token_file: _TOKEN_FILE = None,
    period_s: Annotated[float, typer.Option("--period-s", min=0.05, max=10.0, help="Seconds between pings.")] = 0.5,
    duration_s: Annotated[
        float | None, typer.Option("--duration-s", min=0.0, help="Stop after this many seconds.", show_default=False)
    ] = None,
) -> None:
    """Keep the link alive while the robot is armed remotely.

    Pings every --period-s on one connection and prints a line when the robot's state changes.
    Ctrl-C stops it; the robot then disarms after its link_timeout_s.
    """
    from rimless.firmware.link.heartbeat import Heartbeat

    @user_facing
    def go() -> None:
        hb = Heartbeat(
            host,
            port=port,
            token=_token(token, token_file),
            period_s=period_s,
            echo=lambda line: typer.echo(line, err=True),
        )
        hb.run(duration_s=duration_s)

    _interruptible(go)


@app.command()
def release(
    config: _CONFIG = None,
    fake: Annotated[bool, typer.Option("--fake", help="Mock pins (to try it on a PC).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Drive every clutch pin of the configuration to its off level, then release the lines.

    The second line of defence when the firmware could not clean up (SIGKILL, a crash): run it from the
    systemd unit's ExecStopPost= (and ExecStartPre=). It does not need the sensor.
    """

    @user_facing
    def go() -> None:
        from rimless.firmware.service.config import load_config
        from rimless.firmware.service.hardware import release_clutches

        report = release_clutches(load_config(config), fake=fake)
        if as_json:
            print_json(report.to_json())
        else:
            typer.echo(
                f"released: GPIO {', '.join(str(p) for p in report.pins)} driven {report.off_level} "
                "(clutch off), then given back; the module inputs' pull-downs hold them off from here"
            )

    _interruptible(go)


@app.command()
def run(
    config: _CONFIG = None,
    fake: Annotated[bool, typer.Option("--fake", help="Fake sensor replaying a synthetic gait, mock pins.")] = False,
    duration_s: Annotated[
        float | None, typer.Option("--duration-s", min=0.0, help="Stop after this many seconds.", show_default=False)
    ] = None,
    arm_at_start: Annotated[bool, typer.Option("--arm", help="Arm at start (default: wait for `arm`).")] = False,
    stance_leg: Annotated[
        int | None,
        typer.Option(
            "--stance-leg",
            min=0,
            help="With --arm: the clutch index of the leg on the ground at start (needed by a sensor "
            "counting legs: [detector] named_stance_required).",
            show_default=False,
        ),
    ] = None,
    telemetry: Annotated[
        list[str] | None,
        typer.Option(
            "--telemetry",
            metavar="HOST:PORT",
            help="Send telemetry here too (repeatable), on top of [telemetry] in the config.",
            show_default=False,
        ),
    ] = None,
    fake_fault: Annotated[
        str | None,
        typer.Option(
            "--fake-fault",
            metavar="NAME",
            help="With --fake: play a fault scenario "
            "(missed-first-touchdown, first-step-bounce, brown-out, wrong-product-id, loop-stall, "
            "log-disk-full, wrong-start-leg).",
            show_default=False,
        ),
    ] = None,
    pin_log: Annotated[
        Path | None,
        typer.Option(
            "--pin-log",
            metavar="FILE",
            help="With --fake: write every pin change as JSON lines (t_s, pin, level).",
            show_default=False,
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="End with one JSON summary on stdout.")] = False,
    realtime: Annotated[
        bool,
        typer.Option(
            "--realtime",
            help="Real-time control thread (as [sampling] realtime "
            "= true): SCHED_FIFO on one CPU, mlockall, gc frozen.",
        ),
    ] = False,
) -> None:
    """Run the firmware until SIGINT/SIGTERM/SIGHUP/SIGQUIT (or --duration-s); clutches off on every exit path.

    Exit code: 0 after --duration-s or SIGTERM (a service stop), 130 after Ctrl-C, 128 + n after
    another signal n, 1 after a fault in the firmware itself, 2 for a user mistake.
    """
    from rimless.errors import ParameterError
    from rimless.firmware.service.config import parse_host_port
    from rimless.firmware.service.runner import run_robot

    def started(robot: Any) -> None:
        if robot.token_path is not None:
            _say(
                f"command token (generated) in {robot.token_path} (mode 0600): on this machine, "
                f"export RIMLESS_TOKEN_FILE={robot.token_path}"
            )

    def running(robot: Any) -> None:  # in the firmware's loop, which handles the stop signals from here
        mode = "fake" if fake else "hardware"
        sampling = robot.cfg.sampling
        _say(
            f"rimless robot: running ({mode}) at {sampling.rate_hz:g} Hz, real time "
            f"{'on' if sampling.realtime else 'off'} ({sampling.realtime_why})"
        )

    @user_facing
    def go() -> Any:
        for d in telemetry or []:
            try:
                parse_host_port(d)
            except ValueError as err:
                raise ParameterError(f"--telemetry: {err}") from None
        return run_robot(
            config,
            telemetry=telemetry or (),
            fake=fake,
            duration_s=duration_s,
            arm=arm_at_start,
            on_start=started,
            on_running=running,
            fake_fault=fake_fault,
            pin_log=pin_log,
            realtime=realtime,
            stance_leg=stance_leg,
        )

    outcome = go()
    summary = outcome.summary
    if as_json:
        print_json(outcome.to_json())
    if summary is None:  # a stop signal before the firmware ran
        _say(f"stopped ({outcome.signal}) before the firmware ran; every clutch released")
        if outcome.signal == "SIGINT":
            _say("interrupted")  # the last line of every command stopped by Ctrl-C
        raise typer.Exit(outcome.exit_code)
    _say(
        f"stopped ({summary.stop_reason}): {summary.samples} samples at {summary.achieved_rate_hz:.1f} Hz, "
        f"{summary.missed_deadlines} missed deadlines, {summary.clutch_commands} clutch commands, "
        f"faults: {', '.join(summary.faults) or 'none'}; every clutch released"
    )
    if summary.log_errors:
        _say(
            f"trial log degraded: {summary.log_errors} failed writes, {summary.log_dropped_lines} lines "
            f"dropped ({summary.log_last_error})"
        )
    if outcome.fake_pins:
        _say("fake clutch pin levels (history): " + outcome.fake_pins)
    if outcome.airborne_leg_locks is not None:
        _say(
            f"fake walk{' (' + outcome.fake_fault + ')' if outcome.fake_fault else ''}: {outcome.engages} "
            f"clutch engages, {outcome.airborne_leg_locks} on a leg in the air"
        )
    if summary.error:
        _say(f"error: {summary.error}")
    elif outcome.signal == "SIGINT":
        _say("interrupted")  # the last line of every command stopped by Ctrl-C
    if outcome.exit_code:
        raise typer.Exit(outcome.exit_code)


@app.command()
def check(
    config: _CONFIG = None,
    fake: Annotated[bool, typer.Option("--fake", help="Check the fake sensor and mock pins.")] = False,
    click: Annotated[bool, typer.Option("--click/--no-click", help="Click each clutch on for --click-s.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    click_s: Annotated[
        float,
        typer.Option("--click-s", min=0.01, max=10.0, help="How long each clutch is engaged in the click test (s)."),
    ] = 0.2,
) -> None:
    """Check the hardware: sensor IDs, SQUAL, frame rate, and a clutch click test.

    Any signal (Ctrl-C, SIGTERM, SIGHUP, SIGQUIT) releases every clutch and exits with 128 + its number.
    """
    from rimless.firmware.service.selftest import self_test

    def clicking(leg: int, pin: int) -> None:
        typer.echo(f"clicking clutch {leg} (GPIO{pin}) ...", err=True)

    @user_facing
    def go() -> Any:
        return self_test(config, fake=fake, click=click, on_click=clicking, click_s=click_s)

    report = go()
    if report.interrupted:
        pins = f" (fake pins: {report.fake_pins})" if report.fake_pins else ""
        typer.echo(f"error: check interrupted by {report.interrupted}; every clutch released{pins}", err=True)
        raise typer.Exit(report.exit_code)
    if as_json:
        print_json(report.to_json())
        return
    for s in report.sensors:
        typer.echo(
            f"sensor {s.index}: ADNS-3080 found (revision 0x{s.revision_id:02X}), SQUAL {s.squal}, "
            f"{s.frame_rate_hz:.0f} fps, {s.resolution_cpi} cpi"
        )
    for c in report.clutches:
        typer.echo(f"clutch {c.leg} (GPIO{c.pin}): clicked on for {click_s:g} s, off")


@app.command()
def listen(
    port: Annotated[int, typer.Option("--port", min=1, max=65535, help="UDP port to listen on.")] = 9870,
    bind: Annotated[str, typer.Option("--bind", help="Local address to bind.")] = "0.0.0.0",
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Record every telemetry object to this JSON Lines file.", show_default=False),
    ] = None,
    csv_out: Annotated[
        Path | None, typer.Option("--csv", help="Record samples and events to this CSV file.", show_default=False)
    ] = None,
    mcap_out: Annotated[
        Path | None,
        typer.Option(
            "--mcap",
            help="Record to this MCAP file (Foxglove): a topic per series, "
            "/leg0../leg7 per leg, /events; needs the mcap package (pc extra).",
            show_default=False,
        ),
    ] = None,
    duration_s: Annotated[
        float | None, typer.Option("--duration-s", min=0.0, help="Stop after this many seconds.", show_default=False)
    ] = None,
    max_datagrams: Annotated[
        int | None,
        typer.Option(
            "--max-datagrams",
            min=1,
            help="Stop after this many datagrams from the robot (default: no limit).",
            show_default=False,
        ),
    ] = None,
    summary_every_s: Annotated[
        float, typer.Option("--summary-every-s", min=0.05, help="Live view refresh period (s).")
    ] = 1.0,
    stale_s: Annotated[
        float, typer.Option("--stale-s", min=0.05, help='Say "data stopped" after this long without data (s).')
    ] = 1.0,
    live: Annotated[
        bool | None,
        typer.Option(
            "--live/--no-live",
            help="Redraw plots in the terminal (default: when stderr is a terminal).",
            show_default=False,
        ),
    ] = None,
    host: Annotated[
        str | None,
        typer.Option("--host", help="Also keep the command link to this robot alive (heartbeat).", show_default=False),
    ] = None,
    robot_port: Annotated[
        int, typer.Option("--robot-port", min=1, max=65535, help="Robot command port (TCP), with --host.")
    ] = 9871,
    token: _TOKEN = None,
    token_file: _TOKEN_FILE = None,
    timeout_s: Annotated[
        float,
        typer.Option(
            "--timeout-s",
            min=0.0,
            help="Exit 1 when no datagram arrives for this long (s): no file written if none arrived, else the "
            "recording up to then; 0 = wait forever.",
        ),
    ] = 10.0,
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot",
            help="Accept telemetry only from this host (default: --host; else, with the token, any address whose "
            "telemetry authenticates, without it the first sender whose datagrams carry a tag).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Receive the robot's UDP telemetry: live view, JSONL/CSV/MCAP recording, "data stopped" notices.

    The live view (in a terminal) draws leg velocity, compression and one strip per clutch. With
    --host it also keeps the robot's command link alive (a heartbeat), so a remote arm holds. The command
    token (--token-file, $RIMLESS_TOKEN_FILE or $RIMLESS_TOKEN) authenticates the telemetry: without it
    any host on the LAN can forge what is recorded (said at the start).
    """
    import sys

    @user_facing
    def go() -> None:
        from rimless.firmware.link.listen import listen as do_listen

        hb = None
        # the token authenticates the telemetry (and, with --host, keeps the command link alive); without one
        # in an option or the environment, listen runs unauthenticated and says so
        has_token = bool(token or token_file is not None or os.environ.get("RIMLESS_TOKEN"))
        key = _token(token, token_file) if has_token or os.environ.get("RIMLESS_TOKEN_FILE") else None
        if host is not None:
            from rimless.firmware.link.heartbeat import Heartbeat

            hb = Heartbeat(
                host, port=robot_port, token=_token(token, token_file), echo=lambda line: typer.echo(line, err=True)
            )
        use_live = sys.stderr.isatty() if live is None else live
        do_listen(
            bind=bind,
            port=port,
            out=out,
            csv_out=csv_out,
            duration_s=duration_s,
            summary_every_s=summary_every_s,
            stale_s=stale_s,
            live=use_live,
            write_screen=lambda text: (sys.stderr.write(text), sys.stderr.flush()),
            echo=lambda line: typer.echo(line, err=True),
            heartbeat=hb,
            timeout_s=timeout_s,
            robot=robot if robot is not None else host,
            mcap_out=mcap_out,
            token=key,
            max_datagrams=max_datagrams,
        )

    _interruptible(go)


@app.command()
def bench(
    fake: Annotated[bool, typer.Option("--fake", help="Run on the fake sensor and mock pins (required).")] = False,
    rate_hz: Annotated[str, typer.Option("--rate-hz", help="Comma-separated sampling rates (Hz).")] = "300,1000,2000",
    duration_s: Annotated[float, typer.Option("--duration-s", min=0.5, help="Seconds per rate.")] = 3.0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object per rate (a JSON list).")] = False,
    realtime: Annotated[
        bool,
        typer.Option(
            "--realtime",
            help="The service's real-time settings for the control "
            "thread (SCHED_FIFO on one CPU, mlockall, gc frozen).",
        ),
    ] = False,
) -> None:
    """Benchmark the control loop on the fake: rate, jitter, wake-up lateness, control latency, SPI wire
    time at the configured clock, and the detector's delay after the true compression peak and touchdown.

    Times are in ms; p50/p99 are percentiles. The SPI wire time is what a real bus adds per sample
    (the fake answers at once). Ctrl-C stops it (exit 130).
    """

    @user_facing
    def go() -> None:
        from rimless.errors import ParameterError
        from rimless.firmware.service.bench import MAX_RATE_HZ, MIN_RATE_HZ, bench_rates
        from rimless.values import parse_numbers

        if not fake:
            raise ParameterError("--fake is required: the bench runs on the fake sensor (use `run` on the robot)")
        rates = parse_numbers(rate_hz, "--rate-hz")
        if any(not MIN_RATE_HZ <= r <= MAX_RATE_HZ for r in rates):
            raise ParameterError(f"--rate-hz values must be in {MIN_RATE_HZ:g}..{MAX_RATE_HZ:g}, got {rate_hz!r}")
        results = bench_rates(
            rates,
            duration_s,
            realtime=realtime,
            on_rate=lambda r: typer.echo(f"bench: {r:g} Hz for {duration_s:g} s ...", err=True),
            on_result=None if as_json else lambda res: typer.echo(_bench_text(res)),
        )
        if as_json:
            print_json(results)

    _interruptible(go)


def _bench_text(res: dict[str, Any]) -> str:
    """The figures of one rate of `robot bench`, as lines (times in ms)."""
    return (
        f"{res['rate_hz']:7.0f} Hz: achieved {res['achieved_rate_hz']:.1f} Hz, missed {res['missed_deadlines']}, "
        f"CPU {100 * res['cpu_share']:.0f} %\n"
        f"  period jitter p50/p99     {res['period_jitter_p50_ms']:.3f}/{res['period_jitter_p99_ms']:.3f} ms\n"
        f"  wake-up late p50/p99/max  {res['wake_late_p50_ms']:.3f}/{res['wake_late_p99_ms']:.3f}/"
        f"{res['wake_late_max_ms']:.3f} ms\n"
        f"  control p50/p99/max       {res['latency_p50_ms']:.3f}/{res['latency_p99_ms']:.3f}/"
        f"{res['latency_max_ms']:.3f} ms (sample to clutch write)\n"
        f"  SPI wire per sample       {res['spi_wire_per_sample_ms']:.3f} ms at "
        f"{res['spi_clock_hz'] / 1e6:g} MHz ({100 * res['spi_wire_share']:.0f} % of the period)\n"
        f"  lock after true peak      p50 {res['lock_after_peak_p50_ms']:.2f}, max "
        f"{res['lock_after_peak_max_ms']:.2f} ms ({res['locks']} locks)\n"
        f"  touchdown detected after  p50 {res['touchdown_detect_p50_ms']:.2f}, max "
        f"{res['touchdown_detect_max_ms']:.2f} ms ({res['touchdowns']} touchdowns)"
        + (
            ""
            if not res.get("realtime")
            else f"\n  real time                 {res['realtime']['policy']} {res['realtime']['priority']} on CPU "
            f"{res['realtime']['cpu']}, memory {'locked' if res['realtime']['memory_locked'] else 'not locked'}, "
            f"other threads {res['realtime'].get('others_policy', 'SCHED_OTHER')}"
            + (f" ({'; '.join(res['realtime']['errors'])})" if res["realtime"]["errors"] else "")
        )
    )


@app.command("leg-test")
def leg_test(
    leg: Annotated[
        int,
        typer.Option(
            "--leg",
            min=0,
            max=63,
            metavar="K",
            help="Clutch index of the leg under test (hanging free, the wheel held up).",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option("--out", metavar="FILE", help="The log to write (JSON Lines; `rimless trials leg-fit` reads it)."),
    ] = Path("leg-test.jsonl"),
    config: _CONFIG = None,
    fake: Annotated[
        bool,
        typer.Option(
            "--fake",
            help="A simulated leg (spring, damper, guide friction, gravity), "
            "a scripted hand, the fake sensor and mock pins.",
        ),
    ] = False,
    hold_s: Annotated[
        float,
        typer.Option(
            "--hold-s",
            min=0.01,
            max=60.0,
            help="Seconds the clutch holds the compressed leg before the release (below [clutch] max_hold_s).",
        ),
    ] = 0.5,
    record_s: Annotated[
        float, typer.Option("--record-s", min=0.1, max=10.0, help="Seconds of free motion recorded after the release.")
    ] = 1.0,
    timeout_s: Annotated[
        float,
        typer.Option(
            "--timeout-s",
            min=1.0,
            max=600.0,
            help="Fail when no maximum compression is found within this many seconds.",
        ),
    ] = 30.0,
    rate_hz: Annotated[
        float,
        typer.Option(
            "--rate-hz",
            min=1000.0,
            max=20000.0,
            help="Sensor reads per second "
            "(back to back when the bus is slower; one per frame is the most "
            "that is useful).",
        ),
    ] = 6000.0,
    frame_rate_hz: Annotated[
        float,
        typer.Option(
            "--frame-rate-hz",
            min=2000.0,
            max=6051.0,
            help="Fixed ADNS-3080 frame rate, fps (6051 is the highest that leaves a shutter).",
        ),
    ] = 6000.0,
    fake_k: Annotated[
        float, typer.Option("--fake-k-n-per-m", min=1.0, max=1e6, help="With --fake: spring stiffness, N/m.")
    ] = 2700.0,
    fake_c: Annotated[
        float, typer.Option("--fake-c-n-s-per-m", min=0.0, max=1e4, help="With --fake: damping, N s/m.")
    ] = 8.0,
    fake_friction: Annotated[
        float,
        typer.Option("--fake-guide-friction-n", min=0.0, max=100.0, help="With --fake: Coulomb guide friction, N."),
    ] = 0.4,
    fake_mass: Annotated[
        float, typer.Option("--fake-moving-mass-kg", min=1e-4, max=10.0, help="With --fake: the leg's moving mass, kg.")
    ] = 0.0378,
    fake_compression_mm: Annotated[
        float,
        typer.Option(
            "--fake-compression-mm", min=0.0, max=20.0, help="With --fake: how far the hand compresses the leg, mm."
        ),
    ] = 2.0,
    fake_noise: Annotated[
        float,
        typer.Option(
            "--fake-noise-counts",
            min=0.0,
            max=100.0,
            help="With --fake: the sensor's position noise, counts (1 sigma).",
        ),
    ] = 0.3,
    seed: Annotated[int, typer.Option("--seed", min=0, help="With --fake: the noise's random seed.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Measure a leg's free motion: compress it by hand, the clutch holds it at maximum compression, then lets
    go after --hold-s; the leg's ADNS-3080 records the motion to --out.

    Fit k, c and the guide friction with `rimless trials leg-fit`. Any signal releases the clutch at once
    and exits 128 + its number (nothing written); a fault releases it and exits 1 (the log says why).
    """

    @user_facing
    def go() -> Any:
        from rimless.errors import ParameterError
        from rimless.firmware.drivers.fake_leg import FakeLegParams
        from rimless.firmware.service.leg_test import LegTestOptions, run_leg_test

        given = {
            "--fake-k-n-per-m": fake_k != 2700.0,
            "--fake-c-n-s-per-m": fake_c != 8.0,
            "--fake-guide-friction-n": fake_friction != 0.4,
            "--fake-moving-mass-kg": fake_mass != 0.0378,
            "--fake-compression-mm": fake_compression_mm != 2.0,
            "--fake-noise-counts": fake_noise != 0.3,
            "--seed": seed != 0,
        }
        if not fake and any(given.values()):
            raise ParameterError(f"{next(k for k, v in given.items() if v)} acts only with --fake (the simulated leg)")

        truth = FakeLegParams(
            stiffness_n_per_m=fake_k,
            damping_n_s_per_m=fake_c,
            friction_n=fake_friction,
            moving_mass_kg=fake_mass,
            compression_m=fake_compression_mm / 1000.0,
        )
        opts = LegTestOptions(
            leg=leg,
            hold_s=hold_s,
            record_s=record_s,
            timeout_s=timeout_s,
            rate_hz=rate_hz,
            frame_rate_hz=frame_rate_hz,
            fake_leg=truth,
            noise_counts=fake_noise,
            seed=seed,
        )
        return run_leg_test(config, opts, out, fake=fake, on_status=lambda text: _say(f"leg test: {text}"))

    report = go()
    if report.interrupted:
        pins = f" (fake pins: {report.fake_pins})" if report.fake_pins else ""
        _say(f"leg test stopped by {report.interrupted}; clutch released, nothing written{pins}")
        _say("interrupted" if report.interrupted == "SIGINT" else f"error: stopped by {report.interrupted}")
        raise typer.Exit(report.exit_code)
    for w in report.warnings:
        _say(f"warning: {w}")
    if as_json:
        print_json(report.to_json())
    else:
        typer.echo(
            f"leg {report.leg}: {report.samples} reads at {report.achieved_rate_hz:.0f} Hz (frame rate "
            f"{report.frame_rate_hz:.0f} fps), locked at {report.lock_compression_mm:.2f} mm, held "
            f"{report.held_s:.3f} s, {report.free_samples} reads of free motion (peak "
            f"{report.peak_speed_m_s:.2f} m/s); log {report.out}; clutch released"
        )
    if report.fault:
        _say(f"error: leg test failed ({report.fault}): {report.detail}; clutch released, log {report.out}")
        raise typer.Exit(report.exit_code)
