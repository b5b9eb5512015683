"""`rimless sim sweep` (the branch sweep, or `--clutch firmware`) and `rimless sim firmware-sweep`: parse the
grids, call rimless.sim.studies.sweep or rimless.sim.in_the_loop.sweep, print the table."""

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.cli_rules import print_json, user_facing
from rimless.errors import ParameterError
from rimless.progress import progress_bar
from rimless.sim.cli.app import (
    NO_FRICTION,
    Backend,
    BackendOpt,
    ClutchKind,
    ElectronicsPowerOpt,
    HoldPowerOpt,
    JsonOpt,
    RtolOpt,
    SwitchEnergyOpt,
    VeElectronicsOpt,
    check_plot_path,
    check_scheduler,
    clutch_power,
    refuse_unused,
    start_slope,
    wheel_params,
)
from rimless.sim.cli.output import console
from rimless.values import parse_list, parse_range

_SWEEP_COLUMNS = (
    ("model", 5),
    ("k", 6),
    ("branch", 13),
    ("stable", 6),
    ("valid", 5),
    ("phi_c deg", 9),
    ("ends by", 17),
    ("CoT", 6),
)


@user_facing
@wheel_params(exclude=NO_FRICTION)
def firmware_sweep_cmd(
    params: Any,
    rates_hz: Annotated[
        str, typer.Option("--rates-hz", help="Sensor rates, Hz (comma-separated or START:STOP:STEP).")
    ] = "300,1000",
    delays_ms: Annotated[str, typer.Option("--delays-ms", help="Clutch engage = release delays, ms.")] = "0,5,10",
    steps: Annotated[int, typer.Option("--steps", min=6, max=200, help="Walk length per point.")] = 8,
    noise_counts: Annotated[
        float, typer.Option("--noise-counts", min=0.0, max=1000.0, help="Sensor noise, counts.")
    ] = 1.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the sensor noise and sampling jitter.")] = 0,
    scheduler: Annotated[
        str, typer.Option("--scheduler", help="sync, local (Dask LocalCluster) or tcp://HOST:PORT.")
    ] = "local",
    workers: Annotated[
        int | None, typer.Option("--workers", min=1, max=256, help="Local Dask workers [cores].")
    ] = None,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot", help="Write the figure: speed and stored energy against delay, per rate (.png, .pdf, .svg)."
        ),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Firmware in the loop over sensor rate and clutch delay: gait, speed and stored energy against the ideal clutch."""
    from rimless.sim.in_the_loop.sweep import firmware_sweep_figure

    if plot is not None:
        check_plot_path(plot)
    check_scheduler(scheduler)
    rates = parse_range(rates_hz, "--rates-hz")
    delays = parse_range(delays_ms, "--delays-ms")
    if any(not 1.0 <= r <= 1e6 for r in rates):
        raise ParameterError(f"--rates-hz must be rates in [1, 1e6] Hz, got {rates_hz!r}")
    if any(not 0.0 <= d <= 1000.0 for d in delays):
        raise ParameterError(f"--delays-ms must be delays in [0, 1000] ms, got {delays_ms!r}")
    with progress_bar("firmware sweep", len(rates) * len(delays), json_out=json_out) as bar:
        out = firmware_sweep_figure(
            params,
            rates,
            [d * 1e-3 for d in delays],
            plot=plot,
            steps=steps,
            noise_counts=noise_counts,
            seed=seed,
            scheduler=scheduler,
            workers=workers,
            progress=lambda n, total: bar.update(n, total),
        )
    if json_out:
        print_json(out)
        return
    if out["plot"]:
        print(f"wrote {out['plot']}")
    print(
        f"ideal clutch: theta'+ {out['ideal']['theta_dot_plus_rad_s']:.4f} rad/s, period "
        f"{out['ideal']['step_period_s']:.4f} s, stored {out['ideal']['stored_energy_J']:.4f} J"
    )
    print(
        f"{'rate_hz':>8} {'delay_ms':>8} {'walks':>5} {'period_s':>8} {'speed/ideal':>11} {'stored/ideal':>12} "
        f"{'|eig|':>6}"
    )
    for r in out["rows"]:
        if not r.get("steps_done"):
            print(f"{r['rate_hz']:>8g} {r['delay_ms']:>8g} {'no':>5}  {r.get('failure')}")
            continue
        eig = r["max_abs_eigenvalue_fitted"]
        print(
            f"{r['rate_hz']:>8g} {r['delay_ms']:>8g} {'yes' if r['walks'] else 'no':>5} {r['step_period_s']:>8.4f} "
            f"{r['speed_ratio']:>11.3f} {r['stored_energy_ratio']:>12.3f} {'-' if eig is None else f'{eig:.3f}':>6}"
        )
    print("speed: step length / period; stored: the stance spring's energy at touchdown; |eig|: fitted to the walk.")


@user_facing
@wheel_params(exclude=NO_FRICTION + ("k", "c", "leg_mass_kg", "hub_mass_kg", "mass_model"))
def sweep_cmd(
    params: Any,
    models: Annotated[str, typer.Option("--model", metavar="er,ve", help="Models, comma-separated: er, ve.")] = "er,ve",
    k_grid: Annotated[
        str | None,
        typer.Option("--k", metavar="START:STOP:STEP|a,b", help="Stiffness grid, N/m: START:STOP:STEP or a,b,c."),
    ] = None,
    c_grid: Annotated[
        str | None,
        typer.Option("--c", metavar="START:STOP:STEP|a,b", help="Damping grid, N s/m: START:STOP:STEP or a,b,c."),
    ] = None,
    leg_mass_grid: Annotated[
        str | None, typer.Option("--leg-mass-kg", metavar="START:STOP:STEP|a,b", help="Leg mass grid, kg.")
    ] = None,
    hub_mass_grid: Annotated[
        str | None, typer.Option("--hub-mass-kg", metavar="START:STOP:STEP|a,b", help="Hub mass grid, kg.")
    ] = None,
    mass_models: Annotated[
        str | None,
        typer.Option(
            "--mass-model",
            metavar="NAME[,NAME]",
            help="Mass models, comma-separated (eight-leg, sliding-leg, active-feet).",
        ),
    ] = None,
    start_slope_rad: Annotated[
        float | None,
        typer.Option(help="Slope where the gaits are searched, rad [the wheel's slope: --slope-deg, 0.05 rad]."),
    ] = None,
    guesses: Annotated[int, typer.Option(min=2, max=200, help="Number of theta'+ guesses in the gait search.")] = 14,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            metavar="STEM",
            help="Output stem: writes STEM.parquet, STEM.csv and STEM-points.parquet/.csv (branch points).",
        ),
    ] = Path("rimless-sweep/sweep"),
    scheduler: Annotated[
        str,
        typer.Option(
            "--scheduler",
            metavar="local|sync|tcp://HOST:8786",
            help="Where grid points run: a local Dask cluster, this process, or a running Dask scheduler.",
        ),
    ] = "local",
    workers: Annotated[
        int | None,
        typer.Option("--workers", min=1, max=256, help="Local cluster worker processes \\[default: one per core]."),
    ] = None,
    cache_dir: Annotated[
        Path | None,
        typer.Option(
            "--cache-dir", help="Per-point result cache [$RIMLESS_CACHE_DIR/sweep, else ~/.cache/rimless/sweep]."
        ),
    ] = None,
    no_cache: Annotated[bool, typer.Option("--no-cache", help="Recompute every point and store nothing.")] = False,
    bench: Annotated[
        bool,
        typer.Option(
            "--bench",
            help="Benchmark instead: the grid (no cache) in-process, on 1 and "
            "on 2 workers, and the branch-end location by pseudo-arclength against "
            "bisection (takes minutes).",
        ),
    ] = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    clutch: Annotated[
        ClutchKind,
        typer.Option(
            "--clutch",
            help="ideal: the branch sweep; firmware: the robot's "
            "controller in the loop over --rate-hz x --clutch-delay-ms (ER, "
            "at --slope-deg).",
        ),
    ] = ClutchKind.ideal,
    fw_rate_hz: Annotated[
        str | None,
        typer.Option(
            "--rate-hz", metavar="START:STOP:STEP|a,b", help="With --clutch firmware: sensor rates, Hz [300,1000]."
        ),
    ] = None,
    fw_delay_ms: Annotated[
        str | None,
        typer.Option(
            "--clutch-delay-ms",
            metavar="START:STOP:STEP|a,b",
            help="With --clutch firmware: clutch engage = release delays, ms [0:10:2.5].",
        ),
    ] = None,
    fw_noise: Annotated[
        float | None, typer.Option("--noise-counts", help="With --clutch firmware: sensor noise, counts [1].")
    ] = None,
    fw_steps: Annotated[
        int, typer.Option("--steps", min=6, max=200, help="With --clutch firmware: walk length per point.")
    ] = 8,
    fw_seed: Annotated[
        int, typer.Option("--seed", help="With --clutch firmware: seed of the sensor noise and sampling jitter.")
    ] = 0,
    fw_critical: Annotated[
        bool,
        typer.Option(
            "--critical-slope/--no-critical-slope",
            help="With --clutch "
            "firmware: bisect each point's critical slope (and the ideal ER and VE "
            "references) for the CoT and the share of the ER advantage kept "
            "(a few walks per point).",
        ),
    ] = False,
    fw_low_deg: Annotated[
        float, typer.Option("--critical-low-deg", help="With --critical-slope: low end of the bisection, deg.")
    ] = 0.5,
    fw_plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="With --clutch firmware: write the figure "
            "(.png, .pdf, .svg): the ER advantage, stored energy and "
            "stability kept against delay, per rate.",
        ),
    ] = None,
    json_out: JsonOpt = False,
    clutch_hold_power_w: HoldPowerOpt = 0.0,
    clutch_switch_energy_j: SwitchEnergyOpt = 0.0,
    electronics_power_w: ElectronicsPowerOpt = 0.0,
    ve_electronics: VeElectronicsOpt = False,
) -> None:
    """Sweep a parameter grid: every period-1 gait at the start slope, each branch continued down to its end.

    Table columns: stable = orbitally stable at the start slope (max |eig| < 1); valid = unilateral contact (stance force >= 0 in single support, impulses > 0); phi_c = critical slope of the branch (end of its stable, valid part); CoT = tan(phi_c)."""
    from rimless.sim.model.params import MASS_MODELS, SPOKE_ANGLE_RAD
    from rimless.sim.step.backend import resolve
    from rimless.sim.studies.sweep import SweepOptions, branch_sweep, default_cache_dir, parse_grid

    if fw_plot is not None:
        check_plot_path(fw_plot)
    power = clutch_power(clutch_hold_power_w, clutch_switch_energy_j, electronics_power_w, ve_electronics)
    if clutch is ClutchKind.firmware and not power.is_zero:
        raise ParameterError(
            "--clutch-hold-power-w, --clutch-switch-energy-j, --electronics-power-w: the system cost "
            "of transport is reported by the branch sweep (--clutch ideal)"
        )
    grid_texts = {"k": k_grid, "c": c_grid, "leg_mass_kg": leg_mass_grid, "hub_mass_kg": hub_mass_grid}
    if clutch is ClutchKind.firmware:
        refuse_unused(("start_slope_rad", "guesses", "backend", "rtol"), "is not used by --clutch firmware")
        _firmware_sweep(
            params,
            models=models,
            grid_texts=grid_texts,
            mass_models=mass_models,
            bench=bench,
            scheduler=scheduler,
            workers=workers,
            cache=None if no_cache else (cache_dir or default_cache_dir()),
            out=out,
            json_out=json_out,
            rate_hz=fw_rate_hz,
            clutch_delay_ms=fw_delay_ms,
            noise_counts=fw_noise,
            steps=fw_steps,
            seed=fw_seed,
            critical_slope=fw_critical,
            critical_low_deg=fw_low_deg,
            plot=fw_plot,
        )
        return
    for flag, given in (
        ("--rate-hz", fw_rate_hz),
        ("--clutch-delay-ms", fw_delay_ms),
        ("--noise-counts", fw_noise),
        ("--plot", fw_plot),
        ("--critical-slope", fw_critical or None),
    ):
        if given is not None:
            raise ParameterError(f"{flag} {given}: needs --clutch firmware")
    refuse_unused(("fw_steps", "fw_seed", "fw_low_deg"), "needs --clutch firmware")
    model_list: list[str] = parse_list(models, "--model", choices=("er", "ve"), lower=True)
    mm: list[str] = parse_list(mass_models or params.mass_model, "--mass-model", choices=MASS_MODELS)
    start_slope_rad = start_slope(params, start_slope_rad)
    if not 0 < start_slope_rad < SPOKE_ANGLE_RAD / 2:
        raise ParameterError(f"--start-slope-rad must be in (0, {SPOKE_ANGLE_RAD / 2:.4f}) rad, got {start_slope_rad}")
    check_scheduler(scheduler)
    grid = parse_grid(params, grid_texts)
    options = SweepOptions(
        backend=resolve(backend.value), rtol=rtol, start_slope_rad=start_slope_rad, n_guesses=guesses
    )
    if bench:
        from rimless.sim.studies.sweepbench import bench_sweep, format_bench

        with progress_bar("benchmark (minutes): sweep on each scheduler, then branch ends", json_out=json_out):
            result = bench_sweep(params, models=model_list, grid=grid, mass_models=mm, options=options)
        if json_out:
            print_json(result)
        else:
            typer.echo(format_bench(result))
        return
    n_points = len(mm) * len(model_list) * math.prod(len(v) for v in grid.values())
    with progress_bar(f"sweep: {n_points} grid points", n_points, json_out=json_out) as bar:
        summary = branch_sweep(
            params,
            models=model_list,
            grid=grid,
            mass_models=mm,
            options=options,
            out=out,
            scheduler=scheduler,
            workers=workers,
            cache_dir=None if no_cache else (cache_dir or default_cache_dir()),
            progress=lambda i, n: bar.update(i, n),
            power=power,
        )
    if json_out:
        print_json(summary)
        return
    _print_sweep_table(summary["rows"])
    if not power.is_zero:
        _print_system_cot(summary["rows"])
    con = console()
    for p in summary["files"]:
        con.print(f"wrote {p}", soft_wrap=True)
    con.print(
        f"{n_points} grid points ({summary['computed']} computed, {summary['cached']} from the cache) in "
        f"{summary['seconds']:.1f} s on {summary['workers']} worker(s), scheduler {scheduler}"
    )


def _firmware_sweep(
    params: Any,
    *,
    models: str,
    grid_texts: dict[str, str | None],
    mass_models: str | None,
    bench: bool,
    scheduler: str,
    workers: int | None,
    cache: Path | None,
    out: Path,
    json_out: bool,
    **options: Any,
) -> None:
    """`sweep --clutch firmware`: one wheel (the branch grid's options take one value), then
    rimless.sim.cli.firmware."""
    from rimless.sim.cli import firmware as firmware_cli
    from rimless.sim.studies.sweep import GRID_PARAMETERS, parse_grid

    if "er" not in parse_list(models, "--model", lower=True):
        raise ParameterError(f"--model: --clutch firmware drives the ER wheel's clutches, got {models!r}")
    changes: dict[str, Any] = {}
    for name, values in parse_grid(params, grid_texts).items():
        if len(values) != 1:
            raise ParameterError(
                f"--{name.replace('_', '-')}: --clutch firmware sweeps --rate-hz x "
                f"--clutch-delay-ms at one wheel; give one value, got {grid_texts[name]!r}"
            )
        changes[GRID_PARAMETERS[name][0]] = values[0]
    if mass_models is not None:
        changes["mass_model"] = parse_list(mass_models, "--mass-model", count=1)[0]
    params = params.replace(**changes)
    if bench:
        firmware_cli.run_bench(params, json_out=json_out)
        return
    check_scheduler(scheduler)
    firmware_cli.run_sweep_command(
        params, out=out, scheduler=scheduler, workers=workers, cache_dir=cache, json_out=json_out, **options
    )


def _print_system_cot(rows: list[dict[str, Any]]) -> None:
    """The system cost of transport per branch: at the start slope and its least along the stable, valid part."""
    con = console()
    for r in rows:
        if "min_system_cot" not in r and "system_cot" not in r:
            continue
        least = (
            f"least {r['min_system_cot']:.4f} at {r['min_system_cot_slope_deg']:.4f} deg"
            + (f" (bound: {r['min_system_cot_at_bound']})" if r.get("min_system_cot_at_bound") else "")
            if "min_system_cot" in r
            else "no stable, valid part"
        )
        con.print(
            f"{r['model']} k={r['k']:g} {r.get('branch')}: system CoT {r.get('system_cot', float('nan')):.4f} at "
            f"the start slope (E_el {r.get('electrical_energy_per_step_j', float('nan')):.4g} J/step); {least}",
            soft_wrap=True,
        )


def _print_sweep_table(rows: list[dict[str, Any]]) -> None:
    """One line per (grid point, branch) in 80 columns; the reasons' details go under the table."""
    from rich.table import Table

    table = Table(show_header=True, header_style="bold", box=None, padding=(0, 1), pad_edge=False)
    for name, width in _SWEEP_COLUMNS:
        table.add_column(
            name,
            justify="right" if name not in ("model", "branch", "ends by") else "left",
            min_width=min(width, len(name)),
            no_wrap=True,
        )
    notes = []
    for r in rows:
        crit = r.get("critical_slope_deg")
        crit_txt = f"{crit:.4f}" if isinstance(crit, float) and crit == crit else "-"
        cot = r.get("cot")
        table.add_row(
            r["model"],
            f"{r['k']:g}",
            str(r.get("branch", ""))[:13],
            "yes" if r.get("stable_at_start") else "no",
            "yes" if r.get("contact_valid_at_start") else "no",
            crit_txt,
            str(r.get("reason", ""))[:17],
            f"{cot:.4f}" if isinstance(cot, float) and cot == cot else "-",
        )
        if r.get("contact_reason"):
            notes.append(f"{r['model']} k={r['k']:g} {r.get('branch')}: not contact-valid: {r['contact_reason']}")
    con = console()
    con.print(table)
    for n in notes:
        con.print(n)
