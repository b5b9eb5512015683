"""`rimless sim basin`, `sensitivity` and `mfpt`: robustness beyond local stability; parse, call `Wheel`, print."""

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
    JsonOpt,
    Model,
    ModelOpt,
    RtolOpt,
    check_scheduler,
    option_given,
    wheel_params,
)
from rimless.sim.cli.output import console, table


def _wheel(params: Any, model: Model, backend: Backend, rtol: float) -> Any:
    from rimless.sim.api.wheel import Wheel

    return Wheel(params, model.value, backend=backend.value, rtol=rtol)


@user_facing
@wheel_params(exclude=NO_FRICTION)
def basin_cmd(
    params: Any,
    model: ModelOpt = Model.er,
    grid: Annotated[
        int, typer.Option("--grid", min=2, max=1000, metavar="N", help="N x N section points over the box.")
    ] = 50,
    steps: Annotated[
        int, typer.Option("--steps", min=1, max=100000, help="Map steps that decide each point's fate at most.")
    ] = 100,
    theta_min: Annotated[float | None, typer.Option(help="Box: smallest theta+, rad [the gait's - 0.15].")] = None,
    theta_max: Annotated[float | None, typer.Option(help="Box: largest theta+, rad [the gait's + 0.15].")] = None,
    theta_dot_min: Annotated[
        float | None, typer.Option(help="Box: smallest theta'+, rad/s [0.02 x the gait's].")
    ] = None,
    theta_dot_max: Annotated[float | None, typer.Option(help="Box: largest theta'+, rad/s [2.5 x the gait's].")] = None,
    out: Annotated[
        Path | None, typer.Option("--out", metavar="DIR", help="Folder for basin.png and basin.csv (every point).")
    ] = None,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    scheduler: Annotated[
        str,
        typer.Option(
            "--scheduler",
            metavar="auto|local|sync|tcp://HOST:8786",
            help="Where the grid's rows run: auto (a local Dask cluster from 64 x 64 points), a local Dask "
            "cluster, this process, or a running Dask scheduler.",
        ),
    ] = "auto",
    workers: Annotated[
        int | None,
        typer.Option("--workers", min=1, max=256, help="Local cluster worker processes \\[default: one per core]."),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Basin of attraction of the period-1 gait: the fate of every point of a grid over the section."""
    if scheduler != "auto" or option_given("workers"):
        check_scheduler("local" if scheduler == "auto" else scheduler)
    given = [theta_min, theta_max, theta_dot_min, theta_dot_max]
    box = None
    if any(v is not None for v in given):
        if any(v is None for v in given):
            raise ParameterError(
                "--theta-min, --theta-max, --theta-dot-min and --theta-dot-max: give all four or none (the default box)"
            )
        box = ((theta_min, theta_max), (theta_dot_min, theta_dot_max))
    wheel = _wheel(params, model, backend, rtol)
    with progress_bar("basin of attraction", grid * grid, json_out=json_out) as bar:
        res = wheel.basin(
            grid=grid,
            steps=steps,
            box=box,
            out=out,
            progress=lambda i, n: bar.update(i, n),
            scheduler=scheduler,
            workers=workers,
        )
    data = res.to_dict()
    if json_out:
        print_json(data)
        return
    fp = data["fixed_point"]
    counts = ", ".join(f"{f} {n}" for f, n in data["fate_counts"].items() if n)
    rows = [
        ("model, slope (deg)", f"{data['model']}, {data['slope_deg']:.4f}"),
        ("gait z* (rad, rad/s)", f"{fp['theta_plus_rad']:.5f}, {fp['theta_dot_plus_rad_s']:.5f}"),
        ("box theta+ (rad)", "[{:.4f}, {:.4f}]".format(*data["box"]["theta_plus_rad"])),
        ("box theta'+ (rad/s)", "[{:.4f}, {:.4f}]".format(*data["box"]["theta_dot_plus_rad_s"])),
        ("grid, steps", f"{data['grid']} x {data['grid']}, {data['steps']}"),
        ("basin area (rad rad/s)", data["basin_area_rad2_per_s"]),
        ("basin fraction of the box", data["basin_area_fraction"]),
        ("fates", counts),
        (
            "nearest failure (scaled)",
            f"{data['nearest_failure_distance']:.4f}"
            + (" (lower bound: none in the box)" if data["nearest_failure_is_lower_bound"] else "")
            + f" +- {data['resolution_scaled']:.3f}",
        ),
        ("map evaluations", data["map_evaluations"]),
        ("scheduler, workers", f"{data['scheduler']}, {data['workers']}"),
    ]
    if "files" in data:
        rows.append(("written", f"{data['files']['figure']}, {data['files']['csv']}"))
    console().print(table("basin of attraction", rows))
    console().print(f"scaled: {data['metric']}")


@user_facing
@wheel_params(exclude=NO_FRICTION)
def sensitivity_cmd(
    params: Any,
    model: ModelOpt = Model.er,
    push: Annotated[
        float, typer.Option("--push-rad-s", help="Size of the simulated push (theta'+ change), rad/s.")
    ] = 0.02,
    slope_step_deg: Annotated[
        float, typer.Option("--slope-step-deg", help="Size of the simulated one-step slope change, deg.")
    ] = 0.05,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
) -> None:
    """Gait sensitivity norm (Hobbelen-Wisse) for a one-step slope change and a push, linear and simulated."""
    with progress_bar("gait sensitivity", json_out=json_out):
        data = _wheel(params, model, backend, rtol).sensitivity(push_rad_s=push, slope_step_deg=slope_step_deg)
    data = data.to_dict()
    if json_out:
        print_json(data)
        return
    rows: list[tuple[str, Any]] = [
        ("model, slope (deg)", f"{data['model']}, {data['slope_deg']:.4f}"),
        ("indicators", data["indicator_choice"]),
        ("map Jacobian", data["map_jacobian"]),
        ("max |eigenvalue|", data["max_abs_eigenvalue"]),
    ]
    for name in ("slope", "push"):
        d = data[name]
        per = f"per {d['unit']}"
        rows += [
            (f"{name}: GSN ({per})", d["gsn"]),
            (f"{name}: by indicator ({per})", ", ".join(f"{k} {v:.5g}" for k, v in d["gsn_by_indicator"].items())),
            (f"{name}: simulated, {d['simulated']['disturbance']:.4g} {d['unit']}", d["simulated"]["gsn"]),
            (f"{name}: relative difference", d["relative_difference"]),
            (f"{name}: two-sided (+-e), difference", d["relative_difference_two_sided"]),
        ]
    console().print(table("gait sensitivity norm", rows))


@user_facing
@wheel_params(exclude=NO_FRICTION)
def mfpt_cmd(
    params: Any,
    terrain_sd_deg: Annotated[
        float,
        typer.Option("--terrain-sd-deg", help="Standard deviation of each step's slope about --slope-deg, deg (> 0)."),
    ],
    model: ModelOpt = Model.er,
    method: Annotated[
        str, typer.Option("--method", metavar="[mesh|monte-carlo]", help="Markov chain on a mesh, or random walks.")
    ] = "mesh",
    walks: Annotated[int, typer.Option("--walks", min=2, max=10_000_000, help="Monte Carlo: number of walks.")] = 200,
    cap: Annotated[
        int, typer.Option("--cap", min=1, max=100_000_000, help="Monte Carlo: steps at most per walk (reported).")
    ] = 10_000,
    seed: Annotated[int, typer.Option("--seed", help="Monte Carlo: random seed.")] = 0,
    nodes_theta: Annotated[int, typer.Option("--nodes-theta", min=1, max=2000, help="Mesh: theta+ nodes.")] = 15,
    nodes_theta_dot: Annotated[
        int, typer.Option("--nodes-theta-dot", min=2, max=2000, help="Mesh: theta'+ nodes.")
    ] = 60,
    slopes: Annotated[int, typer.Option("--slopes", min=3, max=10_000, help="Mesh: slope values per node.")] = 48,
    backend: BackendOpt = Backend.auto,
    rtol: RtolOpt = 1e-10,
    json_out: JsonOpt = False,
) -> None:
    """Mean first-passage time on rough terrain: mean steps before a failure, slopes drawn per step."""
    import math

    if not (math.isfinite(terrain_sd_deg) and terrain_sd_deg > 0):
        raise ParameterError(f"--terrain-sd-deg must be a number > 0, got {terrain_sd_deg:g}")
    if method not in ("mesh", "monte-carlo"):
        raise ParameterError(f"--method must be mesh or monte-carlo, got {method!r}")
    with progress_bar(f"MFPT ({method})", json_out=json_out) as bar:
        data = (
            _wheel(params, model, backend, rtol)
            .mfpt(
                terrain_sd_deg,
                method=method,
                walks=walks,
                cap=cap,
                seed=seed,
                nodes=(nodes_theta, nodes_theta_dot),
                slopes=slopes,
                progress=lambda i, n: bar.update(i, n),
            )
            .to_dict()
        )
    if json_out:
        print_json(data)
        return
    rows: list[tuple[str, Any]] = [
        ("model, slope (deg)", f"{data['model']}, {data['slope_deg']:.4f}"),
        ("terrain sd (deg)", data["terrain_sd_deg"]),
        ("method", data["method"]),
        ("MFPT (steps)", data["mfpt_steps"]),
    ]
    if data["method"] == "mesh":
        rows += [
            ("discretisation error (steps)", f"{data['mfpt_discretisation_error_steps']:.4g} (fine vs coarse mesh)"),
            ("coarse mesh MFPT (steps)", data["coarse"]["mfpt_steps"]),
            ("lambda2, quasi-stationary MFPT", f"{data['lambda2']:.6f}, {data['mfpt_quasi_stationary_steps']:.4g}"),
            ("nodes (theta+, theta'+), slopes", f"{data['fine']['nodes']}, {data['fine']['slopes']}"),
            ("largest probability outside the box", data["fine"]["max_probability_outside_box"]),
        ]
    else:
        lo, hi = data["mfpt_ci_steps"]
        rows += [
            ("95 % interval (steps)", f"[{lo:.4g}, {hi:.4g}]"),
            ("walks, cap (steps)", f"{data['walks']}, {data['cap_steps']}"),
            (
                "walks that reached the cap",
                f"{data['capped_walks']}" + (" (the MFPT is a lower bound)" if data["mfpt_is_lower_bound"] else ""),
            ),
            ("failures by reason", ", ".join(f"{k} {v}" for k, v in data["failures_by_reason"].items())),
        ]
    rows.append(("map evaluations", data["map_evaluations"]))
    console().print(table("mean first-passage time", rows))
