"""`rimless sim stress`, `rimless bench` and `rimless paper`: parse, call one study of rimless.sim.studies, print."""

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
    ElectronicsPowerOpt,
    HoldPowerOpt,
    JsonOpt,
    RtolOpt,
    SwitchEnergyOpt,
    VeElectronicsOpt,
    check_scheduler,
    clutch_power,
    wheel_params,
)
from rimless.sim.cli.output import console
from rimless.values import parse_numbers, parse_range


@user_facing
@wheel_params(exclude=NO_FRICTION + ("k", "c", "slope_deg", "slope_rad", "leg_mass_kg"))
def stress_cmd(
    params: Any,
    k_values: Annotated[
        str, typer.Option("--k-values", help="Stiffnesses to sweep, N/m, comma-separated.")
    ] = "300,1000,2700,1e4,1e5,1e6",
    c_values: Annotated[str, typer.Option("--c-values", help="Dampings, N s/m.")] = "0,2,8,100",
    slopes_deg: Annotated[
        str, typer.Option("--slopes-deg", help="Slopes, deg (each < 22.5).")
    ] = "0.06,1.15,2.86,8.6,22.2",
    mass_ratios: Annotated[str, typer.Option("--mass-ratios", help="Leg-to-hub mass ratios m/m_H.")] = "0.002,0.02,0.2",
    rtol: RtolOpt = 1e-8,
    json_out: JsonOpt = False,
) -> None:
    """Stress the compiled step map over a parameter grid: every point valid or a classified failure."""
    from rich.table import Table

    from rimless.sim.model.params import SPOKE_ANGLE_RAD
    from rimless.sim.studies.stress import stress_sweep

    slopes = [math.radians(v) for v in parse_numbers(slopes_deg, "--slopes-deg")]
    if not all(0 <= s < SPOKE_ANGLE_RAD / 2 for s in slopes):
        raise ParameterError("--slopes-deg: every slope must be in [0, 22.5) deg")
    ks, cs = parse_numbers(k_values, "--k-values"), parse_numbers(c_values, "--c-values")
    ratios = parse_numbers(mass_ratios, "--mass-ratios")
    if min(ks) <= 0 or min(cs) < 0 or min(ratios) <= 0:
        raise ParameterError("need k > 0, c >= 0 and mass ratios > 0")
    with progress_bar("stress sweep", json_out=json_out) as bar:
        out = stress_sweep(
            params,
            k_values=ks,
            c_values=cs,
            slopes_rad=slopes,
            mass_ratios=ratios,
            rtol=rtol,
            progress=lambda i, n: bar.update(i, n),
        )
    if json_out:
        print_json(out)
    else:
        reasons = sorted({r for m in out["counts"].values() for r in m})
        counts = Table(title=f"stress sweep: {out['points']} steps in {out['seconds']:.1f} s (rtol {rtol:g})")
        counts.add_column("outcome", overflow="fold")
        for model in out["counts"]:
            counts.add_column(model, justify="right", no_wrap=True)
        for r in reasons:
            counts.add_row(r, *[str(out["counts"][m].get(r, 0)) for m in out["counts"]])
        con = console()
        con.print(counts)
        con.print(
            f"max integrator steps in one step: {out['max_integrator_steps']}, slowest step "
            f"{out['slowest_step_s'] * 1e3:.1f} ms, unclassified: {len(out['unclassified'])}"
        )
    if out["unclassified"]:
        raise typer.Exit(1)


@user_facing
def bench_cmd(
    quick: Annotated[bool, typer.Option("--quick", help="Fewer tolerances and repetitions (under a minute).")] = False,
    plot: Annotated[
        Path | None, typer.Option("--plot", help="Write the work-precision figure (.png/.pdf/.svg).")
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Work-precision benchmark: the compiled map against solve_ivp RK45/DOP853, side by side in one run."""
    if plot is not None and plot.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise ParameterError(f"{plot}: the figure must end in .png, .pdf or .svg")
    if plot is not None:  # before minutes of work, not after
        from rimless.output import writable_dir

        writable_dir(plot.parent if str(plot.parent) else Path("."), option="--plot")
    from rimless.sim.studies.bench import bench_study, format_table

    with progress_bar("benchmark (the full run takes minutes; --quick under one)", json_out=json_out) as bar:
        result = bench_study(quick, plot=plot, progress=lambda msg: bar.update(description=str(msg)))
    if json_out:
        print_json(result)
    else:
        typer.echo(format_table(result))
    if plot is not None:
        typer.echo(f"wrote {plot}", err=json_out)


@user_facing
@wheel_params(exclude=NO_FRICTION + ("k",))
def paper_cmd(
    params: Any,
    out: Annotated[
        Path, typer.Option("--out", metavar="DIR", help="Folder for the figures, CSVs and index.html.")
    ] = Path("rimless-paper"),
    k_grid: Annotated[
        str, typer.Option("--k", metavar="START:STOP:STEP", help="Stiffness grid of the sweep, N/m.")
    ] = "1500:3500:250",
    scheduler: Annotated[
        str,
        typer.Option("--scheduler", metavar="local|sync|tcp://HOST:8786", help="Where the sweep's grid points run."),
    ] = "local",
    workers: Annotated[
        int | None,
        typer.Option("--workers", min=1, max=256, help="Local cluster worker processes \\[default: one per core]."),
    ] = None,
    cache_dir: Annotated[
        Path | None,
        typer.Option("--cache-dir", help="Sweep result cache [$RIMLESS_CACHE_DIR/sweep, else ~/.cache/rimless/sweep]."),
    ] = None,
    no_cache: Annotated[bool, typer.Option("--no-cache", help="Recompute every sweep point.")] = False,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
    clutch_hold_power_w: HoldPowerOpt = 0.0,
    clutch_switch_energy_j: SwitchEnergyOpt = 0.0,
    electronics_power_w: ElectronicsPowerOpt = 0.0,
    ve_electronics: VeElectronicsOpt = False,
) -> None:
    """Regenerate the paper's simulation figures (PNG, 150 dpi) with their CSVs, the headline table and an index;
    with the system cost of transport per k (table7_system_cot*.csv) and its figure against the clutch's
    holding power (fig_system_cot_hold_power.png)."""
    from rich.table import Table

    from rimless.sim.studies.paper import paper_study
    from rimless.sim.studies.sweep import default_cache_dir

    ks = tuple(parse_range(k_grid, "--k"))
    check_scheduler(scheduler)
    power = clutch_power(clutch_hold_power_w, clutch_switch_energy_j, electronics_power_w, ve_electronics)
    with progress_bar("paper", json_out=json_out) as bar:
        summary = paper_study(
            out,
            params,
            ks=ks,
            backend=backend.value,
            rtol=rtol,
            scheduler=scheduler,
            workers=workers,
            cache_dir=None if no_cache else (cache_dir or default_cache_dir()),
            progress=lambda msg: bar.update(description=msg),
            power=power,
        )
    if json_out:
        print_json(summary)
        return
    headline = Table(title="the paper's headline numbers beside ours", show_lines=True)
    for col in ("quantity", "paper", "ours"):
        headline.add_column(col, overflow="fold")
    for r in summary["table"]:
        headline.add_row(r["quantity"], r["paper"], r["ours"])
    timings, sweep = summary["timings_s"], summary["sweep"]
    con = console()
    con.print(headline)
    for f in summary["files"]:
        con.print(f"wrote {f}", soft_wrap=True)
    for note in summary["notes"]:
        con.print(f"note: {note}")
    con.print(
        f"load average {timings['load_average_before']:.1f} before, "
        f"{timings['load_average_after']:.1f} after (other work on the machine slows every timing)"
    )
    con.print(
        f"in {timings['total']:.1f} s (sweep {timings['sweep']:.1f} s: {sweep['computed']} grid "
        f"points computed, {sweep['cached']} cached, {sweep['workers']} worker(s))"
    )


def register_top_level(root: typer.Typer) -> None:
    """Commands that live at the top level (`rimless bench`, `rimless paper`)."""
    root.command("bench")(bench_cmd)
    root.command("paper")(paper_cmd)
