"""``rimless trials``: import Vicon CSV exports as Parquet trials, show them, benchmark the import.

Only typer and the standard library at module level (``rimless --help`` stays fast).
"""

from __future__ import annotations

import functools
import math
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
EXIT_NOTHING_COMPARED = 1
#: `rimless.analysis.io.trial.DEFAULT_MAX_GAP_S` in ms (kept here so that ``--help`` needs no numpy import).
DEFAULT_MAX_GAP_MS = 50.0


def _parse_offset(text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        vals = tuple(float(p) / 1000.0 for p in parts)
    except ValueError:
        raise ParameterError(f"--hub-offset-mm must be three numbers X,Y,Z in mm, got {text!r}") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ParameterError(f"--hub-offset-mm must be three finite numbers X,Y,Z in mm, got {text!r}")
    return vals  # type: ignore[return-value]


def _parse_markers(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = [m.strip() for m in text.split(",")]
    if not all(names):
        raise ParameterError(f"--markers must be marker names separated by commas, got {text!r}")
    return names


def shown_path(path: str | Path) -> str:
    """``path`` relative to the working directory when it lies below it, else as given."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):
        return str(p)


def import_options(object_: str | None, markers: str | None, hub_offset_mm: str | None, slope_deg: float | None,
                   leg_length_m: float | None, max_gap_ms: float) -> dict[str, Any]:
    """Keyword arguments of `import_trial` from the CLI options shared by ``import`` and ``report``."""
    return {"slope_deg": slope_deg, "object": object_, "markers": _parse_markers(markers),
            "hub_offset_m": _parse_offset(hub_offset_mm), "leg_length_m": leg_length_m,
            "max_gap_s": max_gap_ms / 1000.0}


def _clean_reason(err: Exception) -> str:
    """The message of a user error with the Python argument names replaced by the CLI option names."""
    msg = str(err)
    for py, opt in (("object=", "--object "), ("markers=", "--markers "), ("hub_offset_m=", "--hub-offset-mm "),
                    ("max_gap_s", "--max-gap-ms")):
        msg = msg.replace(py, opt)
    return msg


def import_row(path: Path, trial: Any | None, error: Exception | None) -> dict[str, Any]:
    """The JSON row of one imported (or refused) file: the `trials import --json` contract."""
    from rimless.analysis.io.vicon_csv import ViconCsvError

    row: dict[str, Any] = {"file": shown_path(path), "status": "refused", "reason": None, "frames": None,
                           "rate_hz": None, "steps": None, "source": None, "slope_deg": None, "ramp_slope_deg": None,
                           "outcome": None, "window_s": None, "impact_times_s": [], "step_periods_s": [],
                           "hub_offset_mm": None, "warnings": [], "errors": [], "trial": None}
    if error is not None or trial is None:
        row["reason"] = _clean_reason(error) if error is not None else "not imported"
        if isinstance(error, ViconCsvError):
            row["errors"] = error.all_locations()
        else:
            row["errors"] = [row["reason"]]
        return row
    m = trial.meta
    row.update(
        status="imported", frames=m.n_frames, rate_hz=m.rate_hz, steps=int(trial.step_period_s.size),
        reason=None if m.step_refused is None else f"steps not detected: {m.step_refused}",
        source={"object": m.object, "markers": list(m.markers), "section": m.section, "why": m.source_reason},
        slope_deg=m.slope_deg, ramp_slope_deg=m.ramp_slope_deg, outcome=m.outcome,
        window_s=list(m.window_s) if m.window_s else None,
        impact_times_s=trial.impact_time_s.tolist(), step_periods_s=trial.step_period_s.tolist(),
        hub_offset_mm=None if m.hub_offset_m is None else [round(v * 1e3, 3) for v in m.hub_offset_m],
        warnings=list(m.warnings) + ([f"steps not detected: {m.step_refused}"] if m.step_refused else []),
    )
    return row


def _import_one(path: Path, out: Path, kwargs: dict[str, Any]) -> dict[str, Any]:
    from rimless.analysis.io.trial import import_trial

    try:
        trial = import_trial(path, **kwargs)
        target = out / (_stem(path) + ".trial.parquet")
        trial.to_parquet(target)
    except UserError as err:
        return import_row(path, None, err)
    except OSError as err:
        return import_row(path, None, UserError(f"{shown_path(path)}: {err.strerror or err}"))
    row = import_row(path, trial, None)
    row["trial"] = row["_trial"] = shown_path(target)
    row["_outcome_reason"] = trial.meta.outcome_reason
    return row


def _stem(path: Path) -> str:
    name = path.name
    for suffix in (".csv", ".c3d", ".txt"):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return path.stem


def _check_inputs(files: list[Path]) -> None:
    for f in files:
        if f.is_dir():
            raise UserError(f"{shown_path(f)}: is a folder, not a Vicon export (give the files, e.g. {f}/*.csv)")
        if not f.exists():
            raise UserError(f"{shown_path(f)}: no such file")


GAP_HELP = ("Bridge gaps up to this long by interpolation, ms (the same rule for import and report); "
            "longer gaps split the trial and no step period spans them.")


@app.command("import")
@user_facing
def import_cmd(
    files: Annotated[list[Path], typer.Argument(help="Vicon exports: Tracker or Nexus CSV, or C3D.")],
    slope_deg: Annotated[Optional[float], typer.Option("--slope-deg", min=-45, max=45,
                                                       help="Known slope, deg (default: estimated).")] = None,
    out: Annotated[Path, typer.Option("--out", help="Folder for the <name>.trial.parquet files.",
                                      metavar="DIR")] = Path("."),
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON list, one object per file.")] = False,
    object_: Annotated[Optional[str], typer.Option(
        "--object", help="Tracked object, or the markers' subject (default: what moves like the wheel).",
        metavar="NAME")] = None,
    markers: Annotated[Optional[str], typer.Option("--markers", help="Wheel marker names, comma-separated.",
                                                   metavar="A,B,C,D")] = None,
    hub_offset_mm: Annotated[Optional[str], typer.Option(
        "--hub-offset-mm", help="Hub in the object frame X,Y,Z, mm (default: fitted centre of rotation).",
        metavar="X,Y,Z")] = None,
    leg_length_m: Annotated[Optional[float], typer.Option(
        "--leg-length-m", min=0.0, help="Leg length, m: CoM height measured from the slope plane.")] = None,
    max_gap_ms: Annotated[float, typer.Option("--max-gap-ms", min=0.0, help=GAP_HELP)] = DEFAULT_MAX_GAP_MS,
) -> None:
    """Import Vicon exports as Parquet trials; a refused file does not stop the others (exit 2 if any)."""
    from rimless.output import writable_dir

    kwargs = import_options(object_, markers, hub_offset_mm, slope_deg, leg_length_m, max_gap_ms)
    _check_inputs(files)
    writable_dir(out, option="--out")
    rows: list[dict[str, Any]] = []
    from rich.console import Console
    from rich.progress import Progress

    with Progress(console=Console(stderr=True), transient=True, disable=len(files) < 2) as progress:
        task = progress.add_task("importing", total=len(files))
        for f in files:
            progress.update(task, description=f"importing {f.name}")
            rows.append(_import_one(f, out, kwargs))
            progress.advance(task)
    if json_out:
        print_json([{k: v for k, v in r.items() if not k.startswith("_")} for r in rows])
    else:
        from rich.table import Table

        table = Table(title="Vicon import", show_edge=False)
        for col in ("file", "status", "slope°", "outcome", "steps"):
            table.add_column(col, no_wrap=True, justify="left" if col in ("file", "status", "outcome") else "right")
        for r in rows:
            ok = r["status"] == "imported"
            table.add_row(Path(r["file"]).name, "[green]imported[/]" if ok else "[red]refused[/]",
                          f"{r['slope_deg']:.3f}" if ok else "", str(r["outcome"] or ""),
                          str(r["steps"] if ok else ""))
        console = Console()
        console.print(table)
        for r in rows:
            name = Path(r["file"]).name
            if r["status"] == "imported":
                typer.echo(f"{name}: wrote {r['_trial']}; {r['_outcome_reason']}")
                if r["ramp_slope_deg"] is not None:
                    typer.echo(f"{name}: ramp slope {r['ramp_slope_deg']:.3f} deg (static ramp), "
                               f"hub path {r['slope_deg']:.3f} deg")
                for w in r["warnings"]:
                    typer.echo(f"{name}: warning: {w}")
            else:
                for e in r["errors"][:20]:
                    typer.echo(f"error: {e}", err=True)
    if any(r["status"] == "refused" for r in rows):
        raise typer.Exit(EXIT_REFUSED)


@app.command("show")
@user_facing
def show_cmd(
    trial: Annotated[Path, typer.Argument(help="A Parquet trial written by `rimless trials import`.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Print a trial's metadata, slope estimate, steps and step periods."""
    from rimless.analysis.io.trial import read_trial

    if trial.is_dir():
        raise UserError(f"{shown_path(trial)}: is a folder; give one <name>.trial.parquet file from it")
    s = read_trial(trial).summary()
    if json_out:
        print_json(s)
        return
    from rich.console import Console
    from rich.table import Table

    typer.echo(shown_path(trial))
    meta = Table(show_header=False, show_edge=False)
    meta.add_column("key", style="bold", no_wrap=True)
    meta.add_column("value", overflow="fold", max_width=56)
    for k in ("object", "markers", "frames", "rate_hz", "duration_s", "outcome", "window_s", "slope_deg",
              "ramp_slope_deg", "hub_offset_mm", "gap_frames", "interpolated_frames", "max_gap_s", "step_method",
              "steps"):
        v = s[k]
        if isinstance(v, float):
            v = f"{v:.6g}"
        elif isinstance(v, list) and v and isinstance(v[0], float):
            v = ", ".join(f"{x:.4g}" for x in v)
        meta.add_row(k, str(v))
    console = Console()
    console.print(meta)
    for k in ("file", "source", "outcome_reason", "hub_source", "slope_source", "ramp_source",
              "com_height_reference", "step_refused"):
        if s.get(k):
            typer.echo(f"{k}: {s[k]}")
    for n in s["notes"]:
        typer.echo(f"note: {n}")
    for w in s["warnings"]:
        typer.echo(f"warning: {w}")
    if s["steps"]:
        steps = Table(title="steps (periods whose two impacts were observed)", show_edge=False)
        for col in ("step", "impact s", "period s"):
            steps.add_column(col, justify="right")
        t = dict(zip(s["impact_step"], s["impact_time_s"]))
        for k, period in zip(s["period_step"], s["step_period_s"]):
            steps.add_row(str(k), f"{t[k]:.4f}", f"{period:.4f}")
        console.print(steps)


@app.command("bench-import")
def bench_cmd(
    rows: Annotated[int, typer.Option("--rows", min=100, help="Rows in the synthetic Tracker file.")] = 1_000_000,
    mb: Annotated[Optional[float], typer.Option("--mb", min=0.01, help="Size of the synthetic file, MB "
                                                "(instead of --rows).")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the figures as one JSON object (times in s, "
                                                          "memory in MB, load average before and after).")] = False,
) -> None:
    """Time the import of a synthetic Tracker export against plain pandas.read_csv (prints, asserts nothing)."""
    from rimless.analysis.io.bench_import import BYTES_PER_ROW, main, run_benchmark

    if not json_out:
        main(["--mb", str(mb)] if mb is not None else [str(rows)])
        return
    import os

    n = max(100, int(mb * 1e6 / BYTES_PER_ROW)) if mb is not None else rows
    load_before = os.getloadavg()[0]
    res = run_benchmark(n)
    print_json({**res, "load_average_before": load_before, "load_average_after": os.getloadavg()[0],
                "cpus": os.cpu_count()})


# ------------------------------------------------------------------------------------- report and demo

DEMO_NOTE = ("SYNTHETIC DATA: the bundled example trials are simulated (ER wheel, Table 1 parameters, slopes "
             "1.5/2/2.5 deg, 0.3 mm noise), not measured; see rimless/analysis/data/README.md. The SYNTHETIC_crit "
             "series (1.3-2.05 deg, two release speeds, an 11-step ramp) comes from another truth model (c = 10 N s/m "
             "and guide friction) for the critical slope and the calibration.")


def _report_with_progress(files: list[Path], out: Path, err: Any, *, json_out: bool, import_kwargs: dict[str, Any],
                          model: str, slope_bin_deg: float, note: str | None, title: str, **report_kwargs: Any) -> Any:
    from rich.progress import Progress

    from rimless.analysis.inference.compare import Simulator
    from rimless.analysis.report.html import build_report

    with Progress(console=err, transient=True, disable=json_out) as progress:
        task = progress.add_task("simulator", total=len(files))
        sim = Simulator(model=model)
        progress.update(task, description="comparing")

        def step(name: str) -> None:
            progress.update(task, description=f"compared {name}")
            progress.advance(task)

        return build_report(files, out, sim=sim, import_kwargs=import_kwargs, slope_bin_deg=slope_bin_deg,
                            note=note, title=title, progress=step, **report_kwargs)


def _run_report(files: list[Path], out: Path, *, json_out: bool, import_kwargs: dict[str, Any], model: str,
                slope_bin_deg: float, note: str | None = None, title: str = "Vicon trials vs simulation",
                **report_kwargs: Any) -> Any:
    from rich.console import Console

    err = Console(stderr=True)
    out_is_new = not Path(out).exists()
    try:
        res = _report_with_progress(files, out, err, json_out=json_out, import_kwargs=import_kwargs, model=model,
                                    slope_bin_deg=slope_bin_deg, note=note, title=title, **report_kwargs)
    except BaseException as err:
        from rimless.errors import interrupted_by_user

        if out_is_new and interrupted_by_user(err):  # an interrupted report leaves no half-filled folder behind
            import shutil

            shutil.rmtree(out, ignore_errors=True)
        raise
    if json_out:
        print_json(res.summary())
    else:
        from rich.table import Table

        table = Table(title=f"{len(res.comparisons)} trial(s) vs the {model.upper()} simulation", show_edge=False,
                      collapse_padding=True, pad_edge=False)
        for col in ("trial", "status", "slope\ndeg", "steps", "RMS\nmm", "|dT|\nms", "θ'+\nrad/s"):
            table.add_column(col, no_wrap=True, justify="left" if col in ("trial", "status") else "right")

        def f(v: Any, fmt: str) -> str:
            return "" if v is None or (isinstance(v, float) and v != v) else format(v, fmt)

        for r in res.metrics():
            table.add_row(Path(str(r["trial"])).name.removesuffix(".parquet").removesuffix(".trial")
                          .removesuffix(".csv").removesuffix(".c3d"), "[green]ok[/]" if r["status"] == "ok" else f"[red]{r['status']}[/]",
                          f(r["slope_deg"], ".3f"), f(r["steps"], "d"), f(r["rms_com_error_mm"], ".2f"),
                          f(r["mean_abs_period_error_ms"], ".1f"), f(r["theta_dot_plus_rad_s"], ".3f"))
        Console().print(table)
        typer.echo("RMS: CoM-height RMS error; |dT|: mean |period error|; θ'+: fitted post-impact speed")
        for r in res.refused:
            typer.echo(f"refused: {r.reason}", err=True)
        for c in res.comparisons:
            if c.status != "ok":
                typer.echo(f"{'' if c.status == 'suspect' else 'not compared: '}{shown_path(c.file)}: {c.message}",
                           err=True)
        typer.echo(f"report: {shown_path(res.report_html)}")
    return res


_MODELS = ("er", "ve")


@app.command("report")
@user_facing
def report_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon exports.")],
    out: Annotated[Path, typer.Option("--out", help="Folder for report.html, the PNG figures and metrics.csv.",
                                      metavar="DIR")],
    json_out: Annotated[bool, typer.Option("--json", help="Print a JSON summary (report path, metrics).")] = False,
    slope_deg: Annotated[Optional[float], typer.Option(
        "--slope-deg", min=-45, max=45, help="Known slope for raw inputs, deg (default: estimated).")] = None,
    object_: Annotated[Optional[str], typer.Option(
        "--object", help="Raw inputs: tracked object or markers' subject.", metavar="NAME")] = None,
    markers: Annotated[Optional[str], typer.Option("--markers", help="Raw inputs: wheel marker names.",
                                                   metavar="A,B,C,D")] = None,
    hub_offset_mm: Annotated[Optional[str], typer.Option(
        "--hub-offset-mm", help="Raw inputs: hub in the object frame X,Y,Z, mm.", metavar="X,Y,Z")] = None,
    max_gap_ms: Annotated[float, typer.Option("--max-gap-ms", min=0.0, help=GAP_HELP)] = DEFAULT_MAX_GAP_MS,
    leg_length_m: Annotated[Optional[float], typer.Option(
        "--leg-length-m", min=0.0, help="Raw inputs: CoM height from the slope plane (else from the impact line).")] = None,
    model: Annotated[str, typer.Option("--model", help="Simulated model: er or ve.", metavar="er|ve")] = "er",
    slope_bin_deg: Annotated[float, typer.Option(
        "--slope-bin-deg", min=0.01, help="Group trials by slope rounded to this, deg.")] = 0.5,
) -> None:
    """Compare trials with the simulation and write an HTML report.

    Exit 2 if an input was refused, 1 if no trial could be compared.
    """
    if model not in _MODELS:
        raise ParameterError(f"--model must be one of {', '.join(_MODELS)}, got {model!r}")
    kwargs = import_options(object_, markers, hub_offset_mm, slope_deg, leg_length_m, max_gap_ms)
    _check_inputs(trials)
    res = _run_report(trials, out, json_out=json_out, import_kwargs=kwargs, model=model, slope_bin_deg=slope_bin_deg)
    if res.refused:
        raise typer.Exit(EXIT_REFUSED)
    if not any(c.status == "ok" for c in res.comparisons):
        typer.echo(f"error: no trial could be compared with the simulation ({len(res.comparisons)} failed; "
                   "reasons above)", err=True)
        raise typer.Exit(EXIT_NOTHING_COMPARED)


def demo_cmd(
    out: Annotated[Path, typer.Option("--out", help="Folder for the demo report.")] = Path("rimless-demo"),
    json_out: Annotated[bool, typer.Option("--json", help="Print a JSON summary instead of the table.")] = False,
) -> None:
    """Import the bundled SYNTHETIC example trials, compare them with the simulation, write an HTML report."""
    from rimless.analysis.examples.bundled import data_files
    from rimless.analysis.examples.critical_series import data_files as critical_files

    files = sorted(set(data_files()) | set(critical_files()))
    if not files:
        raise UserError("the bundled example dataset is missing from this install (rimless/analysis/data)")
    from rimless.output import check_output_folder

    check_output_folder(out, option="--out")
    if not json_out:
        typer.echo(f"{len(files)} bundled SYNTHETIC trials -> {out}/ (a first run compiles the simulator)", err=True)
    res = _run_report(files, out, json_out=json_out, import_kwargs={"max_gap_s": DEFAULT_MAX_GAP_MS / 1000.0},
                      model="er", slope_bin_deg=0.5, note=DEMO_NOTE,
                      title="rimless demo: SYNTHETIC trials vs simulation",
                      critical_files=critical_files(), calibrate_c=True)
    if not json_out:
        from rimless.analysis.cli.critical import critical_lines

        typer.echo(critical_lines(res))
        typer.echo(f"open file://{res.report_html.resolve()}")


def register_top_level(root_app: typer.Typer) -> None:
    """Add the top-level ``rimless demo`` command to the root app."""
    root_app.command("demo")(user_facing(demo_cmd))


from rimless.analysis.cli.critical import register as _register_critical  # noqa: E402  (critical-slope, calibrate)

_register_critical(app)
