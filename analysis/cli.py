"""``rimless trials``: import Vicon CSV exports as Parquet trials, show them, benchmark the import.

Only typer and the standard library at module level (``rimless --help`` stays fast).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Optional, TypeVar

import typer

from rimless.errors import ParameterError, UserError

F = TypeVar("F", bound=Callable[..., Any])


# rimless.cli is imported only when a command runs: importing it registers the sub-apps, which imports this
# module; doing it here would make that registration fail when this module is imported first.
def user_facing(func: F) -> F:
    """`rimless.cli.user_facing`, looked up when the command runs."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from rimless.cli import user_facing as real

        return real(func)(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def print_json(obj: Any) -> None:
    """`rimless.cli.print_json`."""
    from rimless.cli import print_json as real

    real(obj)

app = typer.Typer(no_args_is_help=True, help="Vicon trials: import, show, benchmark.")

EXIT_REFUSED = 2


def _parse_offset(text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        vals = tuple(float(p) / 1000.0 for p in parts)
    except ValueError:
        raise ParameterError(f"--hub-offset-mm must be three numbers X,Y,Z in mm, got {text!r}") from None
    if len(vals) != 3:
        raise ParameterError(f"--hub-offset-mm must be three numbers X,Y,Z in mm, got {text!r}")
    return vals  # type: ignore[return-value]


def _import_one(path: Path, out: Path, kwargs: dict[str, Any]) -> dict[str, Any]:
    from .trial import import_trial

    row: dict[str, Any] = {"file": str(path), "status": "refused", "reason": None, "frames": None,
                           "rate_hz": None, "steps": None}
    try:
        trial = import_trial(path, **kwargs)
        target = out / (path.stem + ".trial.parquet")
        trial.to_parquet(target)
    except UserError as err:
        row["reason"] = str(err)
        return row
    except OSError as err:
        row["reason"] = f"{path}: {err}"
        return row
    row.update(status="imported", frames=trial.meta.n_frames, rate_hz=trial.meta.rate_hz,
               steps=int(trial.step_period_s.size),
               reason=None if trial.meta.step_refused is None else f"steps not detected: {trial.meta.step_refused}")
    row["_trial"] = str(target)
    row["_slope"] = trial.meta.slope_deg
    return row


@app.command("import")
@user_facing
def import_cmd(
    files: Annotated[list[Path], typer.Argument(help="Vicon CSV exports (Tracker or Nexus).")],
    slope_deg: Annotated[Optional[float], typer.Option("--slope-deg", min=-45, max=45,
                                                       help="Known slope, deg (default: estimated).")] = None,
    out: Annotated[Path, typer.Option("--out", help="Folder for the <name>.trial.parquet files.")] = Path("."),
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON list, one object per file.")] = False,
    object_: Annotated[Optional[str], typer.Option("--object", help="Tracked object, or the markers' subject.")] = None,
    markers: Annotated[Optional[str], typer.Option("--markers", help="Wheel marker names, comma-separated.")] = None,
    hub_offset_mm: Annotated[Optional[str], typer.Option(
        "--hub-offset-mm", help="Hub in the object frame X,Y,Z, mm (default: estimated).")] = None,
    leg_length_m: Annotated[Optional[float], typer.Option(
        "--leg-length-m", min=0.0, help="Leg length, m: CoM height measured from the slope plane.")] = None,
    max_gap_ms: Annotated[float, typer.Option(
        "--max-gap-ms", min=0.0, help="Interpolate gaps up to this long, ms (default 0: none).")] = 0.0,
) -> None:
    """Import Vicon CSV exports as Parquet trials; a refused file does not stop the others."""
    kwargs: dict[str, Any] = {"slope_deg": slope_deg, "object": object_, "hub_offset_m": _parse_offset(hub_offset_mm),
                              "leg_length_m": leg_length_m, "max_gap_s": max_gap_ms / 1000.0,
                              "markers": [m.strip() for m in markers.split(",")] if markers else None}
    rows: list[dict[str, Any]] = []
    if len(files) > 1 and not json_out:
        from rich.progress import Progress

        with Progress(transient=True) as progress:
            task = progress.add_task("importing", total=len(files))
            for f in files:
                progress.update(task, description=f"importing {f.name}")
                rows.append(_import_one(f, out, kwargs))
                progress.advance(task)
    else:
        rows = [_import_one(f, out, kwargs) for f in files]
    if json_out:
        print_json([{k: v for k, v in r.items() if not k.startswith("_")} for r in rows])
    else:
        from rich.console import Console
        from rich.table import Table

        table = Table(title="Vicon import")
        for col in ("file", "status", "frames", "rate Hz", "slope deg", "steps", "trial / reason"):
            table.add_column(col, overflow="fold")
        for r in rows:
            ok = r["status"] == "imported"
            table.add_row(Path(r["file"]).name, "[green]imported[/]" if ok else "[red]refused[/]",
                          str(r["frames"] or ""), f"{r['rate_hz']:g}" if r["rate_hz"] else "",
                          f"{r['_slope']:.3f}" if ok else "", str(r["steps"] if ok else ""),
                          (r["_trial"] + (f"\n{r['reason']}" if r["reason"] else "")) if ok
                          else str(r["reason"]).removeprefix(r["file"] + ": "))
        Console().print(table)
    if any(r["status"] == "refused" for r in rows):
        raise typer.Exit(EXIT_REFUSED)


@app.command("show")
@user_facing
def show_cmd(
    trial: Annotated[Path, typer.Argument(help="A Parquet trial written by `rimless trials import`.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Print a trial's metadata, slope estimate, steps and step periods."""
    from .trial import read_trial

    s = read_trial(trial).summary()
    if json_out:
        print_json(s)
        return
    from rich.console import Console
    from rich.table import Table

    meta = Table(title=str(trial), show_header=False)
    meta.add_column("key", style="bold")
    meta.add_column("value", overflow="fold")
    for k in ("file", "section", "object", "markers", "frames", "first_frame", "rate_hz", "duration_s",
              "file_units", "hub_source", "orientation", "slope_deg", "slope_source", "slope_residual_m",
              "com_height_reference", "gap_frames", "interpolated_frames", "max_gap_s", "step_method",
              "step_refused", "notes"):
        v = s[k]
        if isinstance(v, float):
            v = f"{v:.6g}"
        meta.add_row(k, str(v))
    console = Console()
    console.print(meta)
    if s["steps"]:
        steps = Table(title="steps")
        for col in ("step", "impact s", "period s"):
            steps.add_column(col, justify="right")
        t = s["impact_time_s"]
        for k, period in enumerate(s["step_period_s"], start=1):
            steps.add_row(str(k), f"{t[k]:.4f}", f"{period:.4f}")
        console.print(steps)


@app.command("bench-import")
def bench_cmd(
    rows: Annotated[int, typer.Option("--rows", min=100, help="Rows in the synthetic Tracker file.")] = 1_000_000,
) -> None:
    """Time the import of a synthetic Tracker export against plain pandas.read_csv (prints, asserts nothing)."""
    from .bench_import import main

    main([str(rows)])


# ------------------------------------------------------------------------------------- report and demo

DEMO_NOTE = ("SYNTHETIC DATA: the bundled example trials are simulated (ER wheel, Table 1 parameters, slopes "
             "1.5/2/2.5 deg, 0.3 mm noise), not measured; see rimless/analysis/data/README.md. The SYNTHETIC_crit "
             "series (1.3-2.05 deg, two release speeds, an 11-step ramp) comes from another truth model (c = 10 N s/m "
             "and guide friction) for the critical slope and the calibration.")


def _run_report(files: list[Path], out: Path, *, json_out: bool, import_kwargs: dict[str, Any], model: str,
                slope_bin_deg: float, note: str | None = None, title: str = "Vicon trials vs simulation",
                **report_kwargs: Any) -> Any:
    from rich.console import Console
    from rich.progress import Progress

    from .compare import Simulator
    from .report import build_report

    err = Console(stderr=True)
    with Progress(console=err, transient=True, disable=json_out) as progress:
        task = progress.add_task("simulator", total=len(files))
        sim = Simulator(model=model)
        progress.update(task, description="comparing")

        def step(name: str) -> None:
            progress.update(task, description=f"compared {name}")
            progress.advance(task)

        res = build_report(files, out, sim=sim, import_kwargs=import_kwargs, slope_bin_deg=slope_bin_deg,
                           note=note, title=title, progress=step, **report_kwargs)
    if json_out:
        print_json(res.summary())
    else:
        from rich.table import Table

        table = Table(title=f"{len(res.comparisons)} trial(s) vs the {model.upper()} simulation", show_edge=False)
        for col in ("trial", "status", "slope deg", "steps", "RMS mm", "|dT| ms", "θ'+ rad/s"):
            table.add_column(col, no_wrap=col == "trial", justify="left" if col in ("trial", "status") else "right")

        def f(v: Any, fmt: str) -> str:
            return "" if v is None or (isinstance(v, float) and v != v) else format(v, fmt)

        for r in res.metrics():
            table.add_row(Path(str(r["trial"])).stem, "[green]ok[/]" if r["status"] == "ok" else f"[red]{r['status']}[/]",
                          f(r["slope_deg"], ".3f"), f(r["steps"], "d"), f(r["rms_com_error_mm"], ".2f"),
                          f(r["mean_abs_period_error_ms"], ".1f"), f(r["theta_dot_plus_rad_s"], ".3f"))
        Console().print(table)
        for r in res.refused:
            typer.echo(f"refused: {r.reason}", err=True)
        for c in res.comparisons:
            if c.status != "ok":
                typer.echo(f"{'' if c.status == 'suspect' else 'not compared: '}{c.file}: {c.message}", err=True)
        typer.echo(f"report: {res.report_html}")
    return res


_MODELS = ("er", "ve")


@app.command("report")
@user_facing
def report_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon CSVs.")],
    out: Annotated[Path, typer.Option("--out", help="Folder for report.html, the PNG figures and metrics.csv.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print a JSON summary (report path, metrics).")] = False,
    slope_deg: Annotated[Optional[float], typer.Option(
        "--slope-deg", min=-45, max=45, help="Known slope for CSV inputs, deg (default: estimated).")] = None,
    max_gap_ms: Annotated[float, typer.Option(
        "--max-gap-ms", min=0.0, help="CSV inputs: interpolate gaps up to this long, ms.")] = 50.0,
    leg_length_m: Annotated[Optional[float], typer.Option(
        "--leg-length-m", min=0.0, help="CSV inputs: CoM height from the slope plane (else from the impact line).")] = None,
    model: Annotated[str, typer.Option("--model", help="Simulated model: er or ve.")] = "er",
    slope_bin_deg: Annotated[float, typer.Option(
        "--slope-bin-deg", min=0.01, help="Group trials by slope rounded to this, deg.")] = 0.5,
) -> None:
    """Compare trials with the simulation and write an HTML report (exit 2 if an input was refused)."""
    if model not in _MODELS:
        raise ParameterError(f"--model must be one of {', '.join(_MODELS)}, got {model!r}")
    kwargs: dict[str, Any] = {"slope_deg": slope_deg, "max_gap_s": max_gap_ms / 1000.0, "leg_length_m": leg_length_m}
    res = _run_report(trials, out, json_out=json_out, import_kwargs=kwargs, model=model, slope_bin_deg=slope_bin_deg)
    if res.refused:
        raise typer.Exit(EXIT_REFUSED)


def demo_cmd(
    out: Annotated[Path, typer.Option("--out", help="Folder for the demo report.")] = Path("rimless-demo"),
    json_out: Annotated[bool, typer.Option("--json", help="Print a JSON summary instead of the table.")] = False,
) -> None:
    """Import the bundled SYNTHETIC example trials, compare them with the simulation, write an HTML report."""
    from .example import data_files
    from .example_critical import data_files as critical_files

    files = sorted(set(data_files()) | set(critical_files()))
    if not files:
        raise UserError("the bundled example dataset is missing from this install (rimless/analysis/data)")
    if not json_out:
        typer.echo(f"{len(files)} bundled SYNTHETIC trials -> {out}/ (a first run compiles the simulator)", err=True)
    res = _run_report(files, out, json_out=json_out, import_kwargs={"max_gap_s": 0.05}, model="er",
                      slope_bin_deg=0.5, note=DEMO_NOTE, title="rimless demo: SYNTHETIC trials vs simulation",
                      critical_files=critical_files(), calibrate_c=True)
    if not json_out:
        from .cli_critical import critical_lines

        typer.echo(critical_lines(res))
        typer.echo(f"open file://{res.report_html.resolve()}")


def register_top_level(root_app: typer.Typer) -> None:
    """Add the top-level ``rimless demo`` command to the root app."""
    root_app.command("demo")(user_facing(demo_cmd))


from .cli_critical import register as _register_critical  # noqa: E402  (critical-slope, calibrate)

_register_critical(app)
