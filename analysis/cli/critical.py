"""``rimless trials critical-slope`` and ``rimless trials calibrate``.

Only typer and the standard library at module level (``rimless --help`` stays fast).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from rimless.errors import InputFileError, ParameterError

EXIT_FAILURE = 1
EXIT_REFUSED = 2
_MODELS = ("er", "ve")


def _user_facing(func: Any) -> Any:
    from rimless.analysis.cli import user_facing

    return user_facing(func)


def _print_json(obj: Any) -> None:
    from rimless.analysis.cli import print_json

    print_json(obj)


def _load(files: list[Path], import_kwargs: dict[str, Any]) -> tuple[list[Any], list[str], list[str]]:
    """(trials, their file names, refusal reasons); a missing file stops before any work (exit 2)."""
    from rimless.analysis.report.html import load_input

    missing = [str(p) for p in files if not p.is_file()]
    if missing:
        raise InputFileError(f"{', '.join(missing)}: no such file")
    trials, names, refused = [], [], []
    for p in files:
        row = load_input(p, import_kwargs)
        if row.trial is None:
            refused.append(row.reason or f"{p}: refused")
        else:
            trials.append(row.trial)
            names.append(_rel(p))
    return trials, names, refused


def _rel(p: Path) -> str:
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


def _models(text: str) -> list[str]:
    out = [m.strip().lower() for m in text.split(",") if m.strip()]
    bad = [m for m in out if m not in _MODELS]
    if not out or bad:
        raise ParameterError(f"--model must be er, ve or er,ve; got {text!r}")
    return out


def _params(path: Optional[Path]) -> Any:
    from rimless.sim.model.params import WheelParams, load_params

    if path is None:
        return WheelParams()
    if not path.is_file():
        raise InputFileError(f"--params {path}: no such file")
    return load_params(path)


def _fmt(v: Any, fmt: str) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def register(app: typer.Typer) -> None:
    """Add ``critical-slope`` and ``calibrate`` to the ``trials`` app."""
    app.command("critical-slope")(_user_facing(critical_slope_cmd))
    app.command("calibrate")(_user_facing(calibrate_cmd))


ParamsOpt = Annotated[Optional[Path], typer.Option(
    "--params", metavar="TOML", help="Wheel parameters (TOML, as `rimless sim`), default the paper's Table 1.")]
SlopeOpt = Annotated[Optional[float], typer.Option(
    "--slope-deg", min=-45, max=45, metavar="DEG", help="Known slope for CSV inputs, deg (default: estimated).")]
GapOpt = Annotated[float, typer.Option("--max-gap-ms", min=0.0, metavar="MS",
                                       help="CSV inputs: interpolate gaps up to this long, ms.")]


def critical_slope_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon CSVs.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    model: Annotated[str, typer.Option("--model", metavar="er|ve|er,ve",
                                       help="Model(s) whose critical slope is shown beside the trials'.")] = "er",
    calibrate_c: Annotated[bool, typer.Option(
        "--calibrated/--no-calibrated", help="Also calibrate c on the trials and give the model's critical slope "
                                             "with it (slower).")] = False,
    params: ParamsOpt = None,
    slope_deg: SlopeOpt = None,
    max_gap_ms: GapOpt = 50.0,
    group_tol_deg: Annotated[float, typer.Option(
        "--group-tol-deg", min=0.0, metavar="DEG", help="Trials whose slopes differ by less form one slope group.")] = 0.05,
) -> None:
    """Critical slope from trials (verdict per trial from its return map) beside the model's.

    Verdicts from the step-to-step return map of the step periods: sustained, decaying or undetermined.

    Estimates: the bracket, a logistic P(sustained), the slope where the fitted gaits reach the stall.

    e* is the fitted gait's squared angular speed over the stance foot, rad²/s² (0 = stall).
    """
    from rich.console import Console
    from rich.progress import Progress

    from rimless.analysis.inference.critical_slope import run_critical_slope

    models = _models(model)
    wheel = _params(params)
    kwargs: dict[str, Any] = {"slope_deg": slope_deg, "max_gap_s": max_gap_ms / 1000.0}
    err = Console(stderr=True)
    with Progress(console=err, transient=True) as prog:
        task = prog.add_task("importing", total=None)
        trials_, names, refused = _load(trials, kwargs)
        for r in refused:
            err.print(f"refused: {r}", markup=False, highlight=False)
        if not trials_:
            typer.echo("error: no trial could be read (see the refusals above)", err=True)
            raise typer.Exit(EXIT_REFUSED if refused else EXIT_FAILURE)
        calibrated = None
        cal = None
        if calibrate_c:
            from rimless.analysis.inference.calibrate import NoTrialCalibrated, calibrate

            prog.update(task, description="calibrating c")
            try:
                cal = calibrate(trials_, names, ["c"], params=wheel, model=models[0],
                                progress=lambda n: prog.update(task, description=f"calibrating c ({n} simulations)"))
                calibrated = cal.calibrated_params
            except NoTrialCalibrated as e:
                err.print(f"calibration skipped: {e}", markup=False, highlight=False)
        res = run_critical_slope(trials_, names, wheel, models=models, calibrated=calibrated, group_tol_deg=group_tol_deg,
                                 progress=lambda s: prog.update(task, description=s))
    out = res.summary()
    out["refused"] = refused
    if cal is not None:
        out["calibration"] = cal.summary()
    if json_out:
        _print_json(out)
    else:
        _print_critical(res, out)
    if refused:
        raise typer.Exit(EXIT_REFUSED)
    if res.chosen is None:
        typer.echo(f"no critical slope: {res.why}", err=True)
        raise typer.Exit(EXIT_FAILURE)


def _print_critical(res: Any, out: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    con = Console()
    t = Table(title="verdict from the step-to-step return map (e*: fixed point, rad²/s²)", show_edge=False)
    for col, just, width in (("trial", "left", 28), ("deg", "right", 6), ("steps", "right", 5),
                             ("verdict", "left", 12), ("e* ± se", "right", 14)):
        t.add_column(col, justify=just, no_wrap=True, min_width=width, max_width=width, overflow="ellipsis")
    color = {"sustained": "green", "decaying": "red", "undetermined": "yellow"}
    stems = [Path(r["file"]).stem for r in out["per_trial"]]
    common = os.path.commonprefix(stems) if len(stems) > 1 else ""
    if len(common) >= 6:
        t.caption = f"trial: the file name after {common!r}"
    for r, stem in zip(out["per_trial"], stems):
        t.add_row(stem[len(common):] if len(common) >= 6 else stem, f"{r['slope_deg']:.3f}", str(r["steps"]),
                  f"[{color[r['verdict']]}]{r['verdict']}[/]",
                  f"{_fmt(r['fixed_point_e_rad2_s2'], '.3f')}±{_fmt(r['fixed_point_e_se_rad2_s2'], '.3f')}")
    con.print(t)
    for r in out["per_trial"]:
        con.print(f"  {Path(r['file']).name}: {r['reason']}", markup=False, highlight=False)
    e = Table(title="critical slope", show_edge=False)
    for col in ("estimate", "deg", "95 % interval / bracket"):
        e.add_column(col, no_wrap=True)
    for est in res.estimates:
        e.add_row(est.method, f"{est.value_deg:.3f}", f"[{est.ci_deg[0]:.3f}, {est.ci_deg[1]:.3f}]")
    for m, v in out["model_critical_slope_deg"].items():
        e.add_row(f"model {m.upper().replace('_CALIBRATED', ' (calibrated)')}", _fmt(v, ".3f"), "")
    con.print(e)
    if res.chosen is not None:
        con.print(f"critical slope from the trials: {res.chosen.value_deg:.3f} deg ({res.chosen.method}); {res.why}",
                  markup=False, highlight=False)
    else:
        con.print(f"no critical slope: {res.why}", markup=False, highlight=False)


def calibrate_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon CSVs.")],
    fit: Annotated[str, typer.Option("--fit", metavar="c[,k,m_H,m,I_c,L0]",
                                     help="Model parameters to fit, comma-separated.")] = "c",
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    model: Annotated[str, typer.Option("--model", metavar="er|ve", help="Simulated model.")] = "er",
    critical: Annotated[bool, typer.Option("--critical/--no-critical",
                                           help="Also give the calibrated model's critical slope and the trials'.")] = True,
    params: ParamsOpt = None,
    slope_deg: SlopeOpt = None,
    max_gap_ms: GapOpt = 50.0,
) -> None:
    """Calibrate the model (c, optionally k ...) on the trials' step periods and CoM height.

    Least squares over all trials (a release speed and a time shift per trial), 1-sigma uncertainties.

    Also: correlations, identifiability, residuals against Table 1, the calibrated critical slope.
    """
    from rich.console import Console
    from rich.progress import Progress

    from rimless.analysis.inference.calibrate import NoTrialCalibrated, calibrate, parse_fit

    names_fit = parse_fit(fit)
    models = _models(model)
    if len(models) != 1:
        raise ParameterError(f"--model must be er or ve, got {model!r}")
    wheel = _params(params)
    err = Console(stderr=True)
    with Progress(console=err, transient=True) as prog:
        task = prog.add_task("importing", total=None)
        trials_, names, refused = _load(trials, {"slope_deg": slope_deg, "max_gap_s": max_gap_ms / 1000.0})
        for r in refused:
            err.print(f"refused: {r}", markup=False, highlight=False)
        if not trials_:
            typer.echo("error: no trial could be read (see the refusals above)", err=True)
            raise typer.Exit(EXIT_REFUSED if refused else EXIT_FAILURE)
        try:
            cal = calibrate(trials_, names, names_fit, params=wheel, model=models[0],
                            progress=lambda n: prog.update(task, description=f"calibrating ({n} simulations)"))
        except NoTrialCalibrated as e:
            typer.echo(str(e), err=True)
            raise typer.Exit(EXIT_FAILURE) from None
        crit = None
        if critical:
            from rimless.analysis.inference.critical_slope import run_critical_slope

            crit = run_critical_slope(trials_, names, wheel, models=models, calibrated=cal.calibrated_params,
                                      progress=lambda s: prog.update(task, description=s))
    out = cal.summary()
    out["refused"] = refused
    if crit is not None:
        out["critical_slope_deg"] = {"trials": crit.critical_slope_deg,
                                     "trials_method": crit.chosen.method if crit.chosen else None,
                                     "trials_ci_deg": list(crit.chosen.ci_deg) if crit.chosen else None,
                                     **{f"model_{k}": v for k, v in crit.model["critical_slope_deg"].items()}}
    if json_out:
        _print_json(out)
    else:
        _print_calibration(out)
    if refused:
        raise typer.Exit(EXIT_REFUSED)


def _print_calibration(out: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    con = Console()
    t = Table(title=f"calibration of the {out['model'].upper()} model", show_edge=False)
    for col in ("parameter", "Table 1", "fitted", "± 1 sigma", "identifiable"):
        t.add_column(col, justify="left" if col == "parameter" else "right", no_wrap=True)
    for p in out["params"]:
        t.add_row(f"{p['name']} ({p['unit']})", f"{p['table1']:.4g}",
                  _fmt(p["estimate"], ".4g"), _fmt(p["se"], ".2g"), "yes" if p["identifiable"] else "[red]NO[/]")
    con.print(t)
    for p in out["params"]:
        if p["note"]:
            con.print(f"  {p['name']}: {p['note']}", markup=False, highlight=False)
    names = out["correlation"]["names"]
    if len(names) > 1:
        con.print("correlation: " + "; ".join(
            f"{names[i]}-{names[j]} {_fmt(out['correlation']['matrix'][i][j], '+.2f')}"
            for i in range(len(names)) for j in range(i + 1, len(names))), markup=False, highlight=False)
    r = Table(title="RMS residuals, Table 1 model -> calibrated", show_edge=False)
    for col, width in (("trial", 30), ("deg", 5), ("dT ms", 6), ("-> ms", 6), ("CoM mm", 6), ("-> mm", 6)):
        r.add_column(col, justify="left" if col == "trial" else "right", no_wrap=True, min_width=width,
                     max_width=width, overflow="ellipsis")
    for row in out["residuals"]:
        r.add_row(Path(row["trial"]).stem, f"{row['slope_deg']:.2f}", _fmt(row["table1_rms_period_ms"], ".1f"),
                  _fmt(row["calibrated_rms_period_ms"], ".1f"), _fmt(row["table1_rms_com_mm"], ".2f"),
                  _fmt(row["calibrated_rms_com_mm"], ".2f"))
    con.print(r)
    con.print("dT: step period error over the steps the simulation reached; CoM: CoM height error; a release "
              "speed and a time shift are fitted per trial in both.", markup=False, highlight=False)
    con.print(f"all trials: RMS period error {_fmt(out['rms_period_ms']['table1'], '.1f')} -> "
              f"{_fmt(out['rms_period_ms']['calibrated'], '.1f')} ms, RMS CoM error "
              f"{_fmt(out['rms_com_mm']['table1'], '.2f')} -> {_fmt(out['rms_com_mm']['calibrated'], '.2f')} mm "
              f"({out['simulations']} simulations)", markup=False, highlight=False)
    if "critical_slope_deg" in out:
        c = out["critical_slope_deg"]
        parts = [f"trials {_fmt(c['trials'], '.3f')} deg ({c['trials_method']})"]
        parts += [f"{k.removeprefix('model_').replace('_', ' ')} {_fmt(v, '.3f')} deg" for k, v in c.items()
                  if k.startswith("model_")]
        con.print("critical slope: " + ", ".join(parts), markup=False, highlight=False)
    for name, why in out["failed"].items():
        con.print(f"not calibrated: {why}", markup=False, highlight=False)


def critical_lines(res: Any) -> str:
    """What `rimless demo` prints about the critical slope and the calibration of a report result."""
    cr, cal = res.critical, res.calibration
    if cr is None:
        return "critical slope: no trial with steps"
    lines = []
    if cr.chosen is not None:
        lines.append(f"critical slope from the trials: {cr.chosen.value_deg:.3f} deg ({cr.chosen.method}, 95 % "
                     f"interval {cr.chosen.ci_deg[0]:.3f}-{cr.chosen.ci_deg[1]:.3f} deg"
                     + (f"; bracket {cr.bracket_deg[0]:.3f}-{cr.bracket_deg[1]:.3f} deg)" if cr.bracket_deg else ")"))
    else:
        lines.append(f"critical slope from the trials: none ({cr.why})")
    for m, v in cr.model.get("critical_slope_deg", {}).items():
        label = m.upper().replace("_CALIBRATED", " with calibrated c")
        lines.append(f"model critical slope, {label}: {_fmt(v, '.3f')} deg")
    if cal is not None:
        for p in cal.params:
            lines.append(f"calibrated {p.name}: {p.value:.3f} ± {p.se:.3f} {p.unit} (Table 1: {p.table1:g})"
                         + ("" if p.identifiable else f" NOT identifiable: {p.note}"))
    return "\n".join(lines)
