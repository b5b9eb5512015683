"""`rimless sim replay`: a robot trial log beside the simulated ER step (rimless.sim.in_the_loop.replay)."""

from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.cli_rules import print_json, user_facing
from rimless.errors import ParameterError
from rimless.sim.cli.app import NO_FRICTION, JsonOpt, check_plot_path, wheel_params
from rimless.sim.cli.output import console, table


@user_facing
@wheel_params(exclude=NO_FRICTION)
def replay_cmd(
    params: Any,
    log: Annotated[Path, typer.Argument(help="Trial log of `rimless robot run` (JSON Lines).")],
    plot: Annotated[Path | None, typer.Option("--plot", help="Write the overlay figure (.png, .pdf, .svg).")] = None,
    rate_hz: Annotated[
        float | None,
        typer.Option("--rate-hz", help="Firmware in the loop: sampling rate, Hz [300, or the --robot-config's]."),
    ] = None,
    clutch_delay_ms: Annotated[
        float, typer.Option("--clutch-delay-ms", help="Firmware in the loop: clutch engage = release delay, ms.")
    ] = 5.0,
    noise_counts: Annotated[
        float, typer.Option("--noise-counts", help="Firmware in the loop: sensor noise, counts.")
    ] = 1.0,
    robot_config: Annotated[
        Path | None,
        typer.Option("--robot-config", help="The robot.toml the trial ran with (detector, sensor and rate settings)."),
    ] = None,
    ideal_only: Annotated[
        bool,
        typer.Option("--ideal-only", help="Compare with the ideal clutch only (skip the firmware-in-the-loop step)."),
    ] = False,
    json_out: JsonOpt = False,
) -> None:
    """Replay a robot trial log against the simulator: recorded steps beside the simulated ER step, under the
    ideal clutch and under the firmware in the loop."""
    from rimless.sim.in_the_loop.config import build_config
    from rimless.sim.in_the_loop.replay import replay_log

    if not log.is_file():
        raise ParameterError(f"{log}: no such trial log")
    if plot is not None:
        check_plot_path(plot)
    fw_config = None
    if not ideal_only:
        if robot_config is not None and not robot_config.is_file():
            raise ParameterError(f"--robot-config {robot_config}: no such file")
        fw_config = build_config(
            rate_hz=rate_hz,
            clutch_delay_ms=clutch_delay_ms,
            release_delay_ms=None,
            noise_counts=noise_counts,
            jitter_ms=0.05,
            holding_force_n=100.0,
            seed=0,
            robot_config=robot_config,
        )
    out = replay_log(log, params, firmware_config=fw_config, plot=plot)
    if json_out:
        print_json(out)
        return

    def f(v: Any, scale: float = 1.0) -> str:
        return "-" if v is None else f"{v * scale:.4g}"

    console().print(
        table(
            f"replay of {log.name}",
            [
                ("recorded steps", str(out["steps"])),
                (
                    "step period recorded mean / simulated (s)",
                    f"{f(out['recorded_period_s']['mean'])} / {f(out['simulated_period_s'])}",
                ),
                (
                    "lock after touchdown recorded / peak simulated (ms)",
                    f"{f(out['recorded_lock_after_touchdown_s']['mean'], 1e3)} / {f(out['simulated_peak_after_impact_s'], 1e3)}",
                ),
                (
                    "max compression recorded / simulated (mm)",
                    f"{f(out['recorded_max_compression_m'], 1e3)} / {f(out['simulated_max_compression_m'], 1e3)}",
                ),
                ("faults in the log", ", ".join(out["faults"]) or "none"),
                *_replay_firmware_rows(out["firmware_in_the_loop"], f),
                ("figure", out["plot"] or "-"),
            ],
        )
    )
    if out["plot"]:
        print(out["plot"])


def _replay_firmware_rows(fw: dict[str, Any] | None, f: Any) -> list[tuple[str, str]]:
    if fw is None:
        return []
    if fw["simulated_period_s"] is None:
        return [("firmware in the loop", f"the walk failed: {fw['failure']}")]
    return [
        ("firmware in the loop: rate, delay", f"{fw['rate_hz']:g} Hz, {fw['engage_delay_ms']:g} ms"),
        ("  step period (s)", f(fw["simulated_period_s"])),
        (
            "  lock command / engaged after impact (ms)",
            f"{f(fw['lock_command_after_impact_s'], 1e3)} / {f(fw['lock_after_impact_s'], 1e3)} ({fw['lock_class']})",
        ),
        ("  max compression (mm)", f(fw["max_compression_m"], 1e3)),
    ]
