"""`rimless sim gait`: N steps with the ideal clutch (rimless.sim.studies.walk) or with the robot's controller
in the loop (`--clutch firmware`, printed by rimless.sim.cli.firmware)."""

from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.cli_rules import fail, print_json, user_facing
from rimless.errors import ParameterError
from rimless.progress import progress_bar
from rimless.sim.cli.app import (
    Backend,
    BackendOpt,
    ClutchKind,
    GaitOpt,
    GuessOpt,
    JsonOpt,
    Model,
    ModelOpt,
    RtolOpt,
    ThetaGuessOpt,
    option_given,
    wheel_params,
)
from rimless.sim.cli.output import console, table

_FIRMWARE_ONLY = (
    "rate_hz",
    "clutch_delay_ms",
    "release_delay_ms",
    "noise_counts",
    "jitter_ms",
    "holding_force_n",
    "seed",
    "bench",
    "critical_slope",
    "critical_low_deg",
    "critical_tol_deg",
)
_IDEAL_ONLY = ("theta_dot_guess", "theta_plus_guess", "theta_plus_rad", "forces", "sample_dt_s")


@user_facing
@wheel_params
def gait_cmd(
    params: Any,
    model: ModelOpt = Model.er,
    theta_dot_guess: GuessOpt = None,
    theta_plus_guess: ThetaGuessOpt = None,
    gait: GaitOpt = None,
    steps: Annotated[int, typer.Option("--steps", min=1, max=10000, help="Number of steps to simulate.")] = 6,
    theta_dot: Annotated[
        float | None,
        typer.Option(
            "--theta-dot", help="Start from this theta'+ (rad/s) just after an impact instead of the fixed point."
        ),
    ] = None,
    theta_plus_rad: Annotated[
        float | None,
        typer.Option(help="With --theta-dot: post-impact stance angle, rad [-alpha/2: both legs at rest length]."),
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", help="Write the trajectory (.parquet or .csv).")] = None,
    plot: Annotated[Path | None, typer.Option("--plot", help="Write the gait figure (.png, .pdf, .svg).")] = None,
    forces: Annotated[
        bool,
        typer.Option(
            "--forces",
            help="Also record the constraint forces (lambda, N) and plot the normal forces and a stick diagram.",
        ),
    ] = False,
    sample_dt_s: Annotated[
        float, typer.Option(min=1e-5, max=0.05, help="Sampling interval of the trajectory, s.")
    ] = 1e-3,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
    clutch: Annotated[
        ClutchKind,
        typer.Option(
            "--clutch",
            help="ideal: lock at maximum compression, release at "
            "touchdown; firmware: the robot's controller in the loop (ER).",
            rich_help_panel="Firmware in the loop",
        ),
    ] = None,  # type: ignore[assignment]
    rate_hz: Annotated[
        float | None,
        typer.Option(
            "--rate-hz",
            help="Sensor sampling rate, Hz [300, or the --robot-config's].",
            rich_help_panel="Firmware in the loop",
        ),
    ] = None,
    robot_config: Annotated[
        Path | None,
        typer.Option(
            "--robot-config",
            help="robot.toml whose detector, sensor and rate settings the firmware runs with.",
            rich_help_panel="Firmware in the loop",
        ),
    ] = None,
    clutch_delay_ms: Annotated[
        float,
        typer.Option(
            "--clutch-delay-ms",
            help="Clutch engage delay (pin on -> leg locked), ms; also the release delay unless --release-delay-ms.",
            rich_help_panel="Firmware in the loop",
        ),
    ] = 5.0,
    release_delay_ms: Annotated[
        float | None,
        typer.Option("--release-delay-ms", help="Clutch release delay, ms.", rich_help_panel="Firmware in the loop"),
    ] = None,
    noise_counts: Annotated[
        float,
        typer.Option(
            "--noise-counts", help="ADNS-3080 position noise (sd), counts.", rich_help_panel="Firmware in the loop"
        ),
    ] = 1.0,
    jitter_ms: Annotated[
        float, typer.Option("--jitter-ms", help="Sampling lateness (sd), ms.", rich_help_panel="Firmware in the loop")
    ] = 0.05,
    holding_force_n: Annotated[
        float,
        typer.Option(
            "--holding-force-n",
            help="Clutch holding force along the leg, N (it slips beyond; inf: rigid).",
            rich_help_panel="Firmware in the loop",
        ),
    ] = 100.0,
    seed: Annotated[
        int,
        typer.Option(
            "--seed", help="Seed of the sensor noise and sampling jitter.", rich_help_panel="Firmware in the loop"
        ),
    ] = 0,
    bench: Annotated[
        bool,
        typer.Option(
            "--bench",
            help="With --clutch firmware: print simulated steps per second "
            "at 300 Hz and 1 kHz beside the ideal clutch, and exit.",
            rich_help_panel="Firmware in the loop",
        ),
    ] = False,
    critical_slope: Annotated[
        bool,
        typer.Option(
            "--critical-slope",
            help="With --clutch firmware: bisect the lowest slope that still walks (a walk of --steps per slope).",
            rich_help_panel="Firmware in the loop",
        ),
    ] = False,
    critical_low_deg: Annotated[
        float,
        typer.Option(
            "--critical-low-deg", help="Low end of the bisection, deg.", rich_help_panel="Firmware in the loop"
        ),
    ] = 0.5,
    critical_tol_deg: Annotated[
        float,
        typer.Option(
            "--critical-tol-deg",
            min=1e-4,
            max=1.0,
            help="Bisection tolerance, deg.",
            rich_help_panel="Firmware in the loop",
        ),
    ] = 0.05,
) -> None:
    """Simulate N steps from the fixed point (or from --theta-dot) and export or plot them."""
    if robot_config is not None:
        if not robot_config.is_file():
            raise ParameterError(f"--robot-config {robot_config}: no such file")
        if clutch is not ClutchKind.firmware:
            raise ParameterError("--robot-config needs --clutch firmware")
    firmware_only = [f"--{n.replace('_', '-')}" for n in _FIRMWARE_ONLY if option_given(n)]
    if clutch is not ClutchKind.firmware and firmware_only:
        raise ParameterError(f"{firmware_only[0]} needs --clutch firmware")
    ideal_only = [f"--{n.replace('_', '-')}" for n in _IDEAL_ONLY if option_given(n)]
    if clutch is ClutchKind.firmware and ideal_only:
        raise ParameterError(
            f"{ideal_only[0]}: --clutch firmware starts from the ideal fixed point and writes no trajectory; drop it"
        )
    if clutch is ClutchKind.firmware:
        from rimless.sim.cli import firmware as firmware_cli
        from rimless.sim.in_the_loop.config import build_config

        if model is not Model.er:
            raise ParameterError("--clutch firmware needs --model er (the viscoelastic wheel has no clutch)")
        if params.guide_friction_n > 0.0:
            raise ParameterError("--guide-friction-n is not modelled with --clutch firmware (the ideal clutch only)")
        if theta_dot is not None or gait is not None or out is not None or plot is not None:
            raise ParameterError(
                "--clutch firmware starts from the ideal fixed point and writes no trajectory: "
                "drop --theta-dot, --gait, --out and --plot"
            )
        if bench:
            firmware_cli.run_bench(params, json_out=json_out)
            return
        config = build_config(
            rate_hz=rate_hz,
            clutch_delay_ms=clutch_delay_ms,
            release_delay_ms=release_delay_ms,
            noise_counts=noise_counts,
            jitter_ms=jitter_ms,
            holding_force_n=holding_force_n,
            seed=seed,
            robot_config=robot_config,
        )
        if critical_slope:
            firmware_cli.run_critical(
                params, config, steps=steps, low_deg=critical_low_deg, tol_deg=critical_tol_deg, json_out=json_out
            )
        else:
            firmware_cli.run_gait(params, config, steps=steps, backend=backend.value, rtol=rtol, json_out=json_out)
        return
    from rimless.sim.studies.walk import walk_gait

    with progress_bar("simulating steps", steps, json_out=json_out) as bar:
        summary = walk_gait(
            params,
            model.value,
            steps=steps,
            theta_dot=theta_dot,
            theta_plus_rad=theta_plus_rad,
            theta_dot_guess=theta_dot_guess,
            theta_plus_guess=theta_plus_guess,
            gait=gait,
            out=out,
            plot=plot,
            forces=forces,
            sample_dt_s=sample_dt_s,
            backend=backend.value,
            rtol=rtol,
            progress=bar.update,
        )
    failure = summary["failure"]
    if failure is not None and not summary["steps_done"]:
        fail(
            f"no step completed from theta+ = {summary['theta_plus_rad']:.4f} rad, theta'+ = "
            f"{summary['theta_dot_plus_rad_s']:.4f} rad/s: {failure['message']}"
        )
    if json_out:
        print_json(summary)
    else:
        done, more = summary["steps_done"], (" ..." if summary["steps_done"] > 8 else "")
        con = console()
        con.print(
            table(
                f"{model.value} gait from the {summary['start']}",
                [
                    ("steps", f"{done} of {steps}"),
                    ("step periods (s)", ", ".join(f"{p:.4f}" for p in summary["step_periods_s"][:8]) + more),
                    ("energy ratios", ", ".join(f"{p:.4f}" for p in summary["energy_ratios"][:8]) + more),
                    *(
                        [
                            (
                                "friction work per step (J)",
                                ", ".join(f"{w:.4g}" for w in summary["friction_work_per_step_j"][:8]) + more,
                            )
                        ]
                        if params.guide_friction_n > 0.0
                        else []
                    ),
                    ("trajectory", summary["out"] or "-"),
                    ("figure", summary["plot"] or "-"),
                ],
            )
        )
        if failure is not None:
            con.print(f"[yellow]the walk ended early: {failure['message']}[/yellow]")
