"""``rimless trials``: import Vicon CSV exports as Parquet trials, show them, benchmark the import.

Only typer and the standard library at module level (``rimless --help`` stays fast).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from rimless.cli import print_json, user_facing
from rimless.errors import ParameterError, UserError

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
