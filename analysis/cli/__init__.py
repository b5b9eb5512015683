"""``rimless trials``: import Vicon CSV exports as Parquet trials, show them, compare them with the simulation.

Each command parses its options, calls one library function (`rimless.analysis.report.batch`,
`rimless.analysis.io.trial`, `rimless.analysis.kinematics.bench_import`) and prints. The rules (errors, exit
codes, JSON) come from `rimless.cli_rules`; lists are parsed by `rimless.values`.

May import: rimless.cli_rules, rimless.values, rimless.errors and every layer of rimless.analysis (inside the
commands, so that ``rimless --help`` needs no numpy); never rimless.cli.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.analysis.cli.adequacy import register as register_adequacy
from rimless.analysis.cli.critical import ParamsOpt, critical_lines, held_lines, print_refused
from rimless.analysis.cli.critical import register as register_critical
from rimless.analysis.cli.floquet import register as register_floquet
from rimless.analysis.cli.leg import register as register_leg
from rimless.analysis.cli.names import names_shown
from rimless.analysis.cli.slope import register as register_slope
from rimless.cli_rules import EXIT_USER_ERROR, echo_text, fail, print_json, user_facing
from rimless.errors import ParameterError, UserError
from rimless.values import parse_list, parse_numbers

app = typer.Typer(no_args_is_help=True, help="Vicon trials: import, show, benchmark.")

EXIT_REFUSED = EXIT_USER_ERROR  # an input file was refused (the others were still done)
#: `rimless.analysis.kinematics.build.DEFAULT_MAX_GAP_S` in ms (kept here so that ``--help`` needs no numpy import).
DEFAULT_MAX_GAP_MS = 50.0
MODELS = ("er", "ve")


def import_options(
    object_: str | None,
    markers: str | None,
    hub_offset_mm: str | None,
    slope_deg: float | None,
    leg_length_m: float | None,
    max_gap_ms: float,
    slopes: Path | None = None,
    up_axis: str | None = None,
) -> dict[str, Any]:
    """Keyword arguments of `import_trial` from the CLI options shared by ``import`` and ``report``."""
    offset = (
        None
        if hub_offset_mm is None
        else tuple(v / 1000.0 for v in parse_numbers(hub_offset_mm, "--hub-offset-mm", count=3))
    )
    kw: dict[str, Any] = {
        "slope_deg": slope_deg,
        "object": object_,
        "markers": None if markers is None else parse_list(markers, "--markers"),
        "hub_offset_m": offset,
        "leg_length_m": leg_length_m,
        "max_gap_s": max_gap_ms / 1000.0,
        "up_axis": parse_up_axis(up_axis),
    }
    if slopes is not None:
        from rimless.analysis.io.manifest import read_slope_manifest

        if slope_deg is not None:
            raise ParameterError(
                "give either --slope-deg (one slope for every file) or --slopes (one per file), not both"
            )
        kw["slopes"] = read_slope_manifest(slopes)
    return kw


UP_AXES = ("x", "y", "z", "-x", "-y", "-z")
UP_AXIS_HELP = "The lab's up axis (x, y, z, -x, -y, -z; default: found from the data: the ramp's normal)."


def parse_up_axis(up_axis: str | None) -> str | None:
    """``--up-axis`` checked (one of `UP_AXES`, a leading + allowed), lower case; None stays None."""
    if up_axis is None:
        return None
    key = up_axis.strip().lower().lstrip("+")
    if key not in UP_AXES:
        raise ParameterError(f"--up-axis must be one of {', '.join(UP_AXES)}, got {up_axis!r}")
    return key


SLOPES_HELP = (
    "CSV 'file,slope_deg': the measured slope of each export (by file name); files not listed get "
    "their slope from a ramp object or the motion."
)


GAP_HELP = (
    "Bridge gaps up to this long by interpolation, ms (the same rule for import and report); "
    "longer gaps split the trial and no step period spans them."
)


@app.command("import")
@user_facing
def import_cmd(
    files: Annotated[list[Path], typer.Argument(help="Vicon exports: Tracker or Nexus CSV, or C3D.")],
    slope_deg: Annotated[
        float | None, typer.Option("--slope-deg", min=-45, max=45, help="Known slope, deg (default: estimated).")
    ] = None,
    out: Annotated[
        Path, typer.Option("--out", help="Folder for the <name>.trial.parquet files.", metavar="DIR")
    ] = Path("."),
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON list, one object per file.")] = False,
    object_: Annotated[
        str | None,
        typer.Option(
            "--object",
            help="Tracked object, or the markers' subject (default: what moves like the wheel).",
            metavar="NAME",
        ),
    ] = None,
    markers: Annotated[
        str | None, typer.Option("--markers", help="Wheel marker names, comma-separated.", metavar="A,B,C,D")
    ] = None,
    hub_offset_mm: Annotated[
        str | None,
        typer.Option(
            "--hub-offset-mm",
            help="Hub in the object frame X,Y,Z, mm (default: fitted centre of rotation).",
            metavar="X,Y,Z",
        ),
    ] = None,
    leg_length_m: Annotated[
        float | None,
        typer.Option("--leg-length-m", min=0.0, help="Leg length, m: CoM height measured from the slope plane."),
    ] = None,
    max_gap_ms: Annotated[float, typer.Option("--max-gap-ms", min=0.0, help=GAP_HELP)] = DEFAULT_MAX_GAP_MS,
    slopes: Annotated[Path | None, typer.Option("--slopes", help=SLOPES_HELP, metavar="FILE")] = None,
    up_axis: Annotated[str | None, typer.Option("--up-axis", help=UP_AXIS_HELP, metavar="AXIS")] = None,
    params: ParamsOpt = None,
    rigid_legs: Annotated[
        bool,
        typer.Option(
            "--rigid-legs",
            help="The wheel's legs have no springs: the slope's interval allows no drift of their compression "
            "(default: the --params wheel's k, or a bound when no wheel is given).",
        ),
    ] = False,
) -> None:
    """Import Vicon exports as Parquet trials; a refused file does not stop the others (exit 2 if any)."""
    from rimless.analysis.report.batch import import_files

    kwargs = import_options(object_, markers, hub_offset_mm, slope_deg, leg_length_m, max_gap_ms, slopes, up_axis)
    if params is not None or rigid_legs:  # the wheel, for the legs' drift in the slope's interval only
        from rimless.analysis.api.runs import import_wheel

        kwargs["wheel"] = import_wheel(params, rigid_legs)
    rows = import_files(files, out, kwargs, json_out=json_out)
    if json_out:
        print_json([{k: v for k, v in r.items() if not k.startswith("_")} for r in rows])
        for r in rows:  # stderr, as without --json: a refused file says why on the error stream too
            if r["status"] != "imported":
                for e in r["errors"][:20]:
                    typer.echo(f"error: {e}", err=True)
    else:
        from rich.console import Console
        from rich.table import Table

        table = Table(title="Vicon import", show_edge=False)
        table.add_column("file", overflow="fold")  # the long name wraps; the numbers and headers never do
        for col in ("status", "slope°", "outcome", "steps"):
            table.add_column(
                col,
                no_wrap=True,
                min_width=max(len(col), 8 if col == "status" else 0),
                justify="left" if col in ("status", "outcome") else "right",
            )
        for r in rows:
            ok = r["status"] == "imported"
            table.add_row(
                Path(r["file"]).name,
                "[green]imported[/]" if ok else "[red]refused[/]",
                f"{r['slope_deg']:.3f}" if ok else "",
                str(r["outcome"] or ""),
                str(r["steps"] if ok else ""),
            )
        console = Console()
        console.print(table)
        if any(r["status"] == "imported" for r in rows):  # what the slope intervals held
            from rimless.analysis.report.batch import parameters_line

            typer.echo(parameters_line(rows[0]["parameters"]))
        for r in rows:
            name = Path(r["file"]).name
            if r["status"] == "imported":
                typer.echo(f"{name}: wrote {r['_trial']}; {r['_outcome_reason']}")
                ci = r.get("slope_ci_deg")
                typer.echo(
                    f"{name}: slope {r['slope_deg']:.3f} deg ({r.get('slope_source')}"
                    + (f", 95 % interval {ci[0]:.3f} to {ci[1]:.3f} deg)" if ci else ")")
                )
                if r["ramp_slope_deg"] is not None and r.get("_estimated_deg") is not None:
                    typer.echo(
                        f"{name}: ramp slope {r['ramp_slope_deg']:.3f} deg (static ramp), "
                        f"from the motion {r['_estimated_deg']:.3f} deg"
                    )
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
    from rimless.analysis.report.batch import shown_path

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
    for k in (
        "object",
        "markers",
        "frames",
        "rate_hz",
        "duration_s",
        "outcome",
        "window_s",
        "slope_deg",
        "slope_ci_deg",
        "slope_source",
        "slope_estimated_deg",
        "ramp_slope_deg",
        "hub_offset_mm",
        "gap_frames",
        "interpolated_frames",
        "max_gap_s",
        "step_method",
        "steps",
    ):
        v = s[k]
        if isinstance(v, float):
            v = f"{v:.6g}"
        elif isinstance(v, list) and v and isinstance(v[0], float):
            v = ", ".join(f"{x:.4g}" for x in v)
        meta.add_row(k, str(v))
    console = Console()
    console.print(meta)
    for k in (
        "file",
        "source",
        "outcome_reason",
        "hub_source",
        "slope_method",
        "ramp_source",
        "com_height_reference",
        "step_refused",
    ):
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
    mb: Annotated[
        float | None, typer.Option("--mb", min=0.01, help="Size of the synthetic file, MB (instead of --rows).")
    ] = None,
    json_out: Annotated[
        bool,
        typer.Option(
            "--json",
            help="Print the figures as one JSON object (times in s, memory in MB, load average before and after).",
        ),
    ] = False,
) -> None:
    """Time the import of a synthetic Tracker export against plain pandas.read_csv (prints, asserts nothing)."""
    from rimless.analysis.kinematics.bench_import import benchmark_figures, main, rows_for_mb

    if not json_out:
        main(["--mb", str(mb)] if mb is not None else [str(rows)])
        return
    print_json(benchmark_figures(rows_for_mb(mb) if mb is not None else rows))


# ------------------------------------------------------------------------------------- report and demo


def command_words(ctx: typer.Context) -> list[str]:
    """The running command as its words from ``rimless`` on (what the report's provenance shows): the command's
    path and every argument and option given on the command line (or by the environment), as parsed."""
    words = ["rimless", *ctx.command_path.split()[1:]]
    for p in ctx.command.params:
        source = ctx.get_parameter_source(p.name) if p.name else None
        if p.name is None or getattr(source, "name", None) not in ("COMMANDLINE", "ENVIRONMENT"):
            continue
        value = ctx.params.get(p.name)
        values = list(value) if isinstance(value, list | tuple) else [value]
        if p.param_type_name == "argument":
            words += [str(v) for v in values]
        elif getattr(p, "is_flag", False):
            if value:
                words.append(p.opts[0])
            elif getattr(p, "secondary_opts", None):
                words.append(p.secondary_opts[0])
        else:
            for v in values if getattr(p, "multiple", False) else [value]:
                words += [p.opts[0], str(v)]
    return words


_NAME_BREAK = re.compile(r"(?<=[_\- ])")


def wrap_name(name: str, width: int) -> str:
    """``name`` on lines of at most ``width`` characters, broken after ``_``, ``-`` or a space only (a number
    such as ``1.9`` in a name is never split); a piece longer than ``width`` stays whole on its line."""
    lines: list[str] = []
    for piece in _NAME_BREAK.split(name):
        if lines and len(lines[-1]) + len(piece) <= width:
            lines[-1] += piece
        else:
            lines.append(piece)
    return "\n".join(line.rstrip() for line in lines)


def _report_table(res: Any, model: str, width: int) -> Any:
    """The report's rich table at most ``width`` columns wide: numbers and headers never wrapped, the trial names
    broken after ``_`` or ``-`` only, as narrow as they need."""
    from rich.console import Console
    from rich.table import Table

    def f(v: Any, fmt: str) -> str:
        return "" if v is None or (isinstance(v, float) and v != v) else format(v, fmt)

    metrics = res.metrics()
    names, caption = names_shown(
        [
            Path(str(r["trial"]))
            .name.removesuffix(".parquet")
            .removesuffix(".trial")
            .removesuffix(".csv")
            .removesuffix(".c3d")
            for r in metrics
        ]
    )
    cells = [
        (
            "[green]ok[/]" if r["status"] == "ok" else f"[red]{r['status']}[/]",
            f(r["slope_deg"], ".3f"),
            f(r["steps"], "d"),
            f(r["rms_com_error_mm"], ".2f"),
            f(r["mean_abs_period_error_ms"], ".1f"),
            f(r["theta_dot_plus_rad_s"], ".3f"),
        )
        for r in metrics
    ]

    def build(name_width: int) -> Table:
        table = Table(
            title=f"{len(res.comparisons)} trial(s) vs the {model.upper()} simulation",
            caption=caption,
            show_edge=False,
            collapse_padding=True,
            pad_edge=False,
        )
        table.add_column("trial", no_wrap=True)  # broken by wrap_name, never inside a number
        for col in ("status", "slope\ndeg", "steps", "RMS\nmm", "|dT|\nms", "θ'+\nrad/s"):
            table.add_column(
                col,
                no_wrap=True,
                min_width=max(len(w) for w in col.split("\n")),
                justify="left" if col == "status" else "right",
            )
        for name, row in zip(names, cells):
            table.add_row(wrap_name(name, name_width), *row)
        return table

    probe = Console(width=10_000, color_system=None)
    longest = max((len(n) for n in names), default=5)
    for name_width in range(longest, 4, -1):  # the widest name column that fits
        table = build(name_width)
        if probe.measure(table).maximum <= width:
            return table
    return build(5)


def _print_report(res: Any, model: str, json_out: bool) -> None:
    """The table (or the JSON summary) of a `rimless.analysis.report.batch.run_report` result."""
    if json_out:
        print_json(res.summary())
        print_refused(r.reason for r in res.refused)  # stderr, as without --json
        for w in res.warnings:
            echo_text(f"warning: {w}", err=True)
        return
    from rich.console import Console

    from rimless.analysis.report.batch import shown_path

    console = Console()
    console.print(_report_table(res, model, console.width))
    echo_text("RMS: CoM-height RMS error; |dT|: mean |period error|; θ'+: fitted post-impact speed")
    for name, c in getattr(res, "clutch", {}).items():
        pairs = ", ".join(
            f"{'–' if r['measured_ms'] is None else format(r['measured_ms'], '.0f')}/"
            f"{'–' if r['simulated_ms'] is None else format(r['simulated_ms'], '.0f')}"
            for r in c["rows"]
        )
        mm, sm = c["measured_mean_ms"], c["simulated_mean_ms"]
        echo_text(
            f"{name}: clutched time per step, robot log / simulated (ms): {pairs or 'none'}; mean "
            f"{'–' if mm is None else format(mm, '.1f')} / {'–' if sm is None else format(sm, '.1f')} ms"
        )
        for w in c["warnings"]:
            echo_text(f"warning: {w}", err=True)
    print_refused(r.reason for r in res.refused)
    for w in res.warnings:  # a slope bin pooling trials on slopes that differ beyond their intervals
        echo_text(f"warning: {w}", err=True)
    demo = getattr(res, "shown", None)  # the demo names its bundled trials relative to the data folder
    for c in res.comparisons:
        if c.status != "ok":
            name, message = (demo(c.file), demo(c.message)) if demo else (shown_path(c.file), c.message)
            if message and "(see above)" in message and c.warnings:  # the comparison's warnings are not printed
                message = message.replace("(see above)", f"({'; '.join(c.warnings)})")
            echo_text(f"{'' if c.status == 'suspect' else 'not compared: '}{name}: {message}", err=True)
    echo_text(f"report: {shown_path(res.report_html)}")


@app.command("report")
@user_facing
def report_cmd(
    ctx: typer.Context,
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon exports.")],
    out: Annotated[
        Path, typer.Option("--out", help="Folder for report.html, the PNG figures and metrics.csv.", metavar="DIR")
    ],
    json_out: Annotated[bool, typer.Option("--json", help="Print a JSON summary (report path, metrics).")] = False,
    slope_deg: Annotated[
        float | None,
        typer.Option("--slope-deg", min=-45, max=45, help="Known slope for raw inputs, deg (default: estimated)."),
    ] = None,
    object_: Annotated[
        str | None, typer.Option("--object", help="Raw inputs: tracked object or markers' subject.", metavar="NAME")
    ] = None,
    markers: Annotated[
        str | None, typer.Option("--markers", help="Raw inputs: wheel marker names.", metavar="A,B,C,D")
    ] = None,
    hub_offset_mm: Annotated[
        str | None,
        typer.Option("--hub-offset-mm", help="Raw inputs: hub in the object frame X,Y,Z, mm.", metavar="X,Y,Z"),
    ] = None,
    max_gap_ms: Annotated[float, typer.Option("--max-gap-ms", min=0.0, help=GAP_HELP)] = DEFAULT_MAX_GAP_MS,
    leg_length_m: Annotated[
        float | None,
        typer.Option(
            "--leg-length-m", min=0.0, help="Raw inputs: CoM height from the slope plane (else from the impact line)."
        ),
    ] = None,
    model: Annotated[str, typer.Option("--model", help="Simulated model: er or ve.", metavar="er|ve")] = "er",
    slope_bin_deg: Annotated[
        float, typer.Option("--slope-bin-deg", min=0.01, help="Group trials by slope rounded to this, deg.")
    ] = 0.5,
    slopes: Annotated[Path | None, typer.Option("--slopes", help="Raw inputs: " + SLOPES_HELP, metavar="FILE")] = None,
    up_axis: Annotated[str | None, typer.Option("--up-axis", help=UP_AXIS_HELP, metavar="AXIS")] = None,
    robot_log: Annotated[
        list[str] | None,
        typer.Option(
            "--robot-log",
            metavar="[TRIAL=]FILE",
            help="The robot's trial log (JSON Lines) of a trial: its measured clutched time per step beside the "
            "simulated one. TRIAL= names the trial's input file (needed with several trials); repeatable.",
        ),
    ] = None,
    params: ParamsOpt = None,
) -> None:
    """Compare trials with the simulation and write an HTML report.

    Exit 2 if an input was refused, 1 if no trial could be compared (no report written) or every compared trial
    is suspect (the report is kept and named).
    """
    from rimless.analysis.report.batch import run_report, shown_path

    if model not in MODELS:
        raise ParameterError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    kwargs = import_options(object_, markers, hub_offset_mm, slope_deg, leg_length_m, max_gap_ms, slopes, up_axis)
    from rimless.analysis.inference.runs import no_fit_here, wheel_input
    from rimless.analysis.report.batch import robot_log_pairs

    logs = robot_log_pairs(robot_log or [], trials)
    win = wheel_input(params)
    no_fit_here(win, (), "trials report fits no parameter of a wheel file (it compares at the held values)")
    res = run_report(
        trials,
        out,
        json_out=json_out,
        import_kwargs=kwargs,
        model=model,
        slope_bin_deg=slope_bin_deg,
        robot_logs=logs,
        params=win.params,
        wheel_input=win,
        argv=command_words(ctx),
    )
    _print_report(res, model, json_out)
    if not json_out:
        for line in held_lines(res.critical.held_summary() if res.critical is not None else {}) or held_lines(
            {"parameters": res.parameters}
        ):
            echo_text(line)
    if res.refused:
        raise typer.Exit(EXIT_REFUSED)
    if not any(c.status == "ok" for c in res.comparisons):  # every compared trial suspect (run_report raised
        # when none could be compared): the report is kept, it shows the misfit and c calibrated on the trials
        fail(
            f"no trial agrees with the {model.upper()} simulation ({len(res.comparisons)} suspect or failed; reasons "
            f"above); the report is kept for the misfit: {shown_path(res.report_html)}"
        )


def demo_cmd(
    ctx: typer.Context,
    out: Annotated[Path, typer.Option("--out", help="Folder for the demo report.")] = Path("rimless-demo"),
    json_out: Annotated[bool, typer.Option("--json", help="Print a JSON summary instead of the table.")] = False,
    params: ParamsOpt = None,
    slope_bin_deg: Annotated[
        float | None,
        typer.Option(
            "--slope-bin-deg",
            min=0.01,
            help="Group the step periods by slope rounded to this, deg (default: per series, pool only trials "
            "whose slope intervals overlap).",
        ),
    ] = None,
) -> None:
    """Import the bundled SYNTHETIC example trials, compare them with the simulation, write an HTML report."""
    from rimless.analysis.inference.runs import no_fit_here, wheel_input
    from rimless.analysis.report.batch import demo_verdicts, run_demo

    win = wheel_input(params)
    no_fit_here(win, (), "rimless demo fits no parameter of a wheel file (its calibration of c is shown beside)")

    def starting(n: int) -> None:
        if not json_out:
            echo_text(f"{n} bundled SYNTHETIC trials -> {out}/ (a first run compiles the simulator)", err=True)

    res = run_demo(
        out, json_out=json_out, starting=starting, wheel_input=win, argv=command_words(ctx), slope_bin_deg=slope_bin_deg
    )
    _print_report(res, "er", json_out)
    if not json_out:
        for verdict in demo_verdicts(res):  # what the verdicts say about each bundled series
            echo_text(verdict["meaning"])
        echo_text(critical_lines(res))
        echo_text(f"open file://{res.report_html.resolve()}")


def register_top_level(root_app: typer.Typer) -> None:
    """Add the top-level ``rimless demo`` command to the root app."""
    root_app.command("demo")(user_facing(demo_cmd))


register_critical(app)
register_leg(app)
register_floquet(app)
register_slope(app)
register_adequacy(app)
