"""``rimless trials critical-slope`` and ``rimless trials calibrate``: parse, run
(`rimless.analysis.api.runs`, which calls the public API), print.

Only typer and the standard library at module level (``rimless --help`` stays fast). The rules come from
`rimless.cli_rules`, lists are parsed by `rimless.values`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, NoReturn

import typer

from rimless.analysis.cli.names import names_shown
from rimless.analysis.inference.sim_budget import DEFAULT_MAX_SIMULATIONS
from rimless.cli_rules import EXIT_FAILURE, EXIT_USER_ERROR, echo_text, print_json, user_facing
from rimless.errors import ParameterError
from rimless.values import parse_list

if TYPE_CHECKING:
    from rich.console import JustifyMethod

EXIT_REFUSED = EXIT_USER_ERROR
MODELS = ("er", "ve")


def _fmt(v: Any, fmt: str) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def _model_name(key: str) -> str:
    """``er`` -> ``ER``; ``er_calibrated`` -> ``ER calibrated (fitted on these trials, not a prediction)``."""
    if key.endswith("_calibrated"):
        return f"{key.removesuffix('_calibrated').upper()} calibrated (fitted on these trials, not a prediction)"
    return key.upper()


def register(app: typer.Typer) -> None:
    """Add ``critical-slope``, ``calibrate`` and ``coverage`` to the ``trials`` app."""
    app.command("critical-slope")(user_facing(critical_slope_cmd))
    app.command("calibrate")(user_facing(calibrate_cmd))
    app.command("coverage")(user_facing(coverage_cmd))


ParamsOpt = Annotated[
    Path | None,
    typer.Option(
        "--params",
        metavar="TOML",
        help="Wheel file (TOML, as `rimless sim`; `k = {value = 2700, sd = 300}` gives an uncertainty, a plain "
        'number is exact, `c = "fit"` fits it), default the paper\'s Table 1 with assumed uncertainties.',
    ),
]
SlopeOpt = Annotated[
    float | None,
    typer.Option(
        "--slope-deg", min=-45, max=45, metavar="DEG", help="Known slope for CSV inputs, deg (default: estimated)."
    ),
]
UpOpt = Annotated[
    str | None,
    typer.Option(
        "--up-axis",
        metavar="AXIS",
        help="Raw inputs: the lab's up axis (x, y, z, -x, -y, -z; default: found from the data).",
    ),
]
GapOpt = Annotated[
    float, typer.Option("--max-gap-ms", min=0.0, metavar="MS", help="CSV inputs: interpolate gaps up to this long, ms.")
]
ObjectOpt = Annotated[
    str | None,
    typer.Option(
        "--object",
        metavar="NAME",
        help="Raw inputs: the tracked object, or the markers' subject (default: what moves like the wheel).",
    ),
]
MarkersOpt = Annotated[
    str | None,
    typer.Option("--markers", metavar="A,B,C,D", help="Raw inputs: the wheel's marker names, comma-separated."),
]


def raw_import_options(
    slope_deg: float | None, max_gap_ms: float, up_axis: str | None, object_: str | None, markers: str | None
) -> dict[str, Any]:
    """`import_trial`'s keyword arguments from the raw-input options these commands share with ``trials import``
    (its refusals name ``--object``, ``--markers`` and ``--up-axis``: each command that imports takes them)."""
    return {
        "slope_deg": slope_deg,
        "max_gap_s": max_gap_ms / 1000.0,
        "up_axis": _up(up_axis),
        "object": object_,
        "markers": None if markers is None else parse_list(markers, "--markers"),
    }


def critical_slope_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon CSVs.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    model: Annotated[
        str,
        typer.Option(
            "--model", metavar="er|ve|er,ve", help="Model(s) whose critical slope is shown beside the trials'."
        ),
    ] = "er",
    calibrate_c: Annotated[
        bool,
        typer.Option(
            "--calibrated/--no-calibrated",
            help="Also calibrate c on the trials and give the model's critical slope with it (slower).",
        ),
    ] = False,
    params: ParamsOpt = None,
    slope_deg: SlopeOpt = None,
    max_gap_ms: GapOpt = 50.0,
    up_axis: UpOpt = None,
    object_: ObjectOpt = None,
    markers: MarkersOpt = None,
    group_tol_deg: Annotated[
        float,
        typer.Option(
            "--group-tol-deg", min=0.0, metavar="DEG", help="Trials whose slopes differ by less form one slope group."
        ),
    ] = 0.05,
) -> None:
    """Critical slope from trials (verdict per trial from its return map) beside the model's.

    Verdicts from the step-to-step return map of the step periods: sustained, decaying or undetermined.

    Estimates: the bracket, a logistic P(sustained), the slope where the fitted gaits reach the stall.

    e* is the fitted gait's squared angular speed over the stance foot, rad²/s² (0 = stall).
    """
    from rimless.analysis.api.runs import critical_slope_run

    models = parse_list(model, "--model", choices=MODELS, lower=True)
    run = critical_slope_run(
        trials,
        models=models,
        calibrate_c=calibrate_c,
        params_path=params,
        import_kwargs=raw_import_options(slope_deg, max_gap_ms, up_axis, object_, markers),
        group_tol_deg=group_tol_deg,
    )
    print_refused(run.loaded.refused)
    if run.result is None:
        exit_nothing_read(run.loaded.refused)
    if run.calibration_skipped is not None:
        typer.echo(f"calibration skipped: {run.calibration_skipped}", err=True)
    res, out = run.result, run.summary()
    if json_out:
        print_json(out)
    else:
        _print_critical(res, out)
    if run.loaded.refused:
        raise typer.Exit(EXIT_REFUSED)
    if res.chosen is None:
        typer.echo(f"error: no critical slope: {res.why}", err=True)
        raise typer.Exit(EXIT_FAILURE)


def _up(up_axis: str | None) -> str | None:
    """``--up-axis`` checked (one of x, y, z, -x, -y, -z), lower case; None stays None."""
    if up_axis is None:
        return None
    key = up_axis.strip().lower().lstrip("+")
    if key not in ("x", "y", "z", "-x", "-y", "-z"):
        raise ParameterError(f"--up-axis must be one of x, y, z, -x, -y, -z, got {up_axis!r}")
    return key


def print_refused(reasons: Iterable[str]) -> None:
    """One ``error:`` line on stderr per refused input (its reason names the file, line and column), as
    `trials import` prints it, with or without ``--json``; the `trials` commands that read exports share it."""
    for reason in reasons:
        echo_text(f"error: {reason}", err=True)


def exit_nothing_read(refused: list[str]) -> NoReturn:
    """No trial could be read: every input refused exits 2, their `print_refused` lines saying why (no summary
    line doubling them); no input at all says so and exits 1."""
    if not refused:
        typer.echo("error: no trial could be read", err=True)
    raise typer.Exit(EXIT_REFUSED if refused else EXIT_FAILURE)


def _print_critical(res: Any, out: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    con = Console()
    t = Table(title="verdict from the step-to-step return map (e*: fixed point, rad²/s²)", show_edge=False)
    t.add_column("trial", overflow="fold", min_width=12)  # a long name wraps; the numbers are never cut
    columns: tuple[tuple[str, JustifyMethod, int], ...] = (
        ("deg", "right", 6),
        ("steps", "right", 5),
        ("verdict", "left", 12),
        ("e* ± se", "right", 14),
    )
    for col, just, width in columns:
        t.add_column(col, justify=just, no_wrap=True, min_width=width)
    color = {"sustained": "green", "decaying": "red", "undetermined": "yellow"}
    shown, t.caption = names_shown([Path(r["file"]).stem for r in out["per_trial"]])
    for r, stem in zip(out["per_trial"], shown):
        t.add_row(
            stem,
            f"{r['slope_deg']:.3f}",
            str(r["steps"]),
            f"[{color[r['verdict']]}]{r['verdict']}[/]",
            f"{_fmt(r['fixed_point_e_rad2_s2'], '.3f')}±{_fmt(r['fixed_point_e_se_rad2_s2'], '.3f')}",
        )
    con.print(t)
    for r in out["per_trial"]:
        con.print(f"  {Path(r['file']).name}: {r['reason']}", markup=False, highlight=False)
    e = Table(title="critical slope", show_edge=False)
    for col in ("estimate", "deg", "95 % interval"):
        e.add_column(col, no_wrap=True)
    for est in res.estimates:
        e.add_row(est.method, f"{est.value_deg:.3f}", f"[{est.ci_deg[0]:.3f}, {est.ci_deg[1]:.3f}]")
    for m, v in out["model_critical_slope_deg"].items():
        e.add_row(f"model {m.upper().replace('_CALIBRATED', ' fitted on these trials')}", _fmt(v, ".3f"), "")
    con.print(e)
    if res.chosen is not None:
        lo, hi = res.chosen.ci_deg
        con.print(
            f"critical slope from the trials: {res.chosen.value_deg:.3f} deg, 95 % interval {lo:.3f}-{hi:.3f} "
            f"deg ({res.chosen.method}); {res.why}"
            + (f"; bracket {res.bracket_deg[0]:.3f}-{res.bracket_deg[1]:.3f} deg" if res.bracket_deg else "")
            + "; intervals include each trial's slope uncertainty (slope_sigma_deg in --json)",
            markup=False,
            highlight=False,
        )
    else:
        con.print(f"no critical slope: {res.why}", markup=False, highlight=False)
    for line in held_lines(out):
        con.print(line, markup=False, highlight=False)


def parameter_lines(parameters: list[dict[str, Any]] | None) -> list[str]:
    """The wheel's parameters as printed: value, 1 sigma, unit, source."""
    if not parameters:
        return []
    out = ["wheel parameters (1 sigma; source: basis):"]
    for p in parameters:
        sd = "exact" if p["sd"] == 0 else f"± {p['sd']:.3g}"
        out.append(f"  {p['symbol']} = {p['value']:.4g} {sd} {p['unit']}  ({p['source']}: {p['basis']})")
    return out


def _shift_text(d: dict[str, Any], parameters: list[dict[str, Any]] | None = None) -> str:
    """The interval's re-centring by the held parameters' mean shift (a parameter carried as its normal truncated
    at its bound 0: F_c = 0 +- 0.2 N, c = 8 +- 4 N s/m), when there is one: both numbers, why they differ, and
    each parameter's part (JSON ``critical_slope_with_held_deg``, ``held_shift_deg``, the rows' ``shift_deg``)."""
    shift = d.get("held_shift_deg") or 0.0
    if abs(shift) < 5e-4:
        return ""
    stated = {p["symbol"]: p for p in parameters or []}

    def part(r: dict[str, Any]) -> str:
        p = stated.get(r["symbol"])
        held = f"{r['symbol']} = {p['value']:.3g} ± {p['sd']:.3g} {p['unit']}" if p else str(r["symbol"])
        return f"{held} {r['shift_deg']:+.3f} deg"

    parts = [part(r) for r in d.get("contributions", []) if abs(r.get("shift_deg") or 0.0) >= 5e-4]
    return (
        f"; the interval is centred on {d['critical_slope_with_held_deg']:.3f} deg, not on "
        f"{d['critical_slope_deg']:.3f}: held parameters are carried as their normals truncated at their bound 0 "
        f"(a negative value is no wheel), whose means lie above the held values and shift the slope by "
        f"{shift:+.3f} deg" + (f" ({', '.join(parts)})" if parts else "")
    )


def _cut_text(d: dict[str, Any]) -> str:
    """The interval's cut at 0 deg (a critical slope is a slope the wheel walks down), when there is one."""
    if not d.get("ci_at_bound"):
        return ""
    return f"; cut at 0 deg (the linearised interval reached {d['ci_linear_deg'][0]:.3f} deg)"


def separation_is_new(sep: dict[str, Any] | None, notes: Iterable[str]) -> bool:
    """Whether the c-against-a-constant-loss note (``loss_separation``) is not already inside a parameter's note
    (the calibration puts it into c's note when c cannot be told from friction): printed once."""
    note = str((sep or {}).get("note") or "")
    return bool(note) and not any(note in (n or "") for n in notes)


def held_model_text(d: dict[str, Any], parameters: list[dict[str, Any]] | None = None) -> str:
    """A model's critical slope at the held values with its interval from the held parameters (one entry of
    JSON ``parameter_uncertainty.models``), and why that interval's centre differs (`_shift_text`)."""
    if d.get("critical_slope_deg") is None:
        return str(d.get("note", "no critical slope"))
    lo, hi = d["ci_deg"]
    big = sorted((r for r in d["contributions"] if r["contribution_deg"]), key=lambda r: -r["contribution_deg"])[:3]
    return (
        f"{d['critical_slope_deg']:.3f} deg at the held values, 95 % interval {lo:.3f}-{hi:.3f} deg from the held "
        "parameters (largest: "
        + ", ".join(f"{r['symbol']} ± {r['contribution_deg']:.3f}" for r in big)
        + ")"
        + _shift_text(d, parameters)
        + _cut_text(d)
        + ("" if d["complete"] else "; NOT every parameter could be propagated")
    )


def held_lines(out: dict[str, Any], *, models: bool = True) -> list[str]:
    """The parameters and the critical slopes' intervals with the held parameters' uncertainty (``models``
    False: without the models' lines, given by the caller with `held_model_text`)."""
    lines = parameter_lines(out.get("parameters"))
    inertia = out.get("inertia_from_trials")
    if inertia and not (inertia.get("estimated") and inertia.get("rigid_map_fits")):  # else in I_c's basis
        lines.append(f"inertia from the trials: {inertia['note']}")
    lines += [f"warning: {w}" for w in out.get("warnings", [])]
    held = out.get("parameter_uncertainty")
    if not held:
        return lines
    tr = held.get("trials")
    if tr:
        lo, hi = tr["ci_deg"]
        lines.append(
            f"critical slope from the trials with the held parameters' uncertainty: {tr['critical_slope_deg']:.3f} "
            f"deg, 95 % interval {lo:.3f}-{hi:.3f} deg (parameters: ± {tr['se_parameters_deg']:.3f} deg 1 sigma)"
            + _shift_text(tr, out.get("parameters"))
            + _cut_text(tr)
            + ("" if tr["complete"] else "; NOT every parameter could be propagated")
        )
    if models:
        for m, d in held.get("models", {}).items():
            sep = " critical slope " if d.get("critical_slope_deg") is not None else ": "
            lines.append(f"model {m.upper()}{sep}{held_model_text(d, out.get('parameters'))}")
    lines.append(f"propagation: {held['method']}")
    return lines


def calibrate_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon CSVs.")],
    fit: Annotated[
        str,
        typer.Option(
            "--fit", metavar="c[,k,m_H,m,I_c,L0,guide_friction_n]", help="Model parameters to fit, comma-separated."
        ),
    ] = "c",
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    model: Annotated[str, typer.Option("--model", metavar="er|ve", help="Simulated model.")] = "er",
    critical: Annotated[
        bool,
        typer.Option(
            "--critical/--no-critical", help="Also give the calibrated model's critical slope and the trials'."
        ),
    ] = True,
    params: ParamsOpt = None,
    slope_deg: SlopeOpt = None,
    max_gap_ms: GapOpt = 50.0,
    up_axis: UpOpt = None,
    object_: ObjectOpt = None,
    markers: MarkersOpt = None,
    prior: Annotated[
        Path | None,
        typer.Option(
            "--prior",
            metavar="JSON",
            help="Leg-test results (`trials leg-fit --json`) as priors: Gaussian penalties on "
            "the fitted k, c (removes the c-k ridge); unfitted ones fixed at them.",
            show_default=False,
        ),
    ] = None,
    max_simulations: Annotated[
        int,
        typer.Option(
            "--max-simulations",
            min=1,
            metavar="N",
            help="At most N simulations for the whole calibration; when spent, the remaining stages are stopped "
            "or skipped and the output says which (JSON budget).",
        ),
    ] = DEFAULT_MAX_SIMULATIONS,
) -> None:
    """Calibrate the model (c, optionally k ...) on the trials' step periods and CoM height.

    Least squares over all trials (a release speed and a time shift per trial), 1-sigma uncertainties.

    Also: correlations, identifiability, residuals against Table 1, the calibrated critical slope.
    """
    from rimless.analysis.api.runs import calibration_run
    from rimless.analysis.inference.calibrate import parse_fit

    names_fit = parse_fit(fit)
    models = parse_list(model, "--model", choices=MODELS, lower=True)
    if len(models) != 1:
        raise ParameterError(f"--model must be er or ve, got {model!r}")
    run = calibration_run(
        trials,
        names_fit,
        model=models[0],
        critical=critical,
        params_path=params,
        import_kwargs=raw_import_options(slope_deg, max_gap_ms, up_axis, object_, markers),
        prior_path=prior,
        max_simulations=max_simulations,
    )
    print_refused(run.loaded.refused)
    if not run.loaded.trials:
        exit_nothing_read(run.loaded.refused)
    if run.failure is not None:
        typer.echo(f"error: {run.failure}", err=True)
        raise typer.Exit(EXIT_FAILURE)
    out = run.summary()
    if json_out:
        print_json(out)
    else:
        _print_calibration(out)
    if run.loaded.refused:
        raise typer.Exit(EXIT_REFUSED)


def start_name(params: Iterable[Any]) -> str:
    """What the calibration started from and compares with: "Table 1" when every fitted parameter's start (JSON
    ``table1``, the wheel's stated value) is Table 1's, else "wheel" (a wheel file stating c = 12 was shown under
    "Table 1"). ``params``: the JSON ``params`` rows, or `ParamEstimate` objects."""
    from rimless.analysis.inference.calibrate import FIT_FIELDS
    from rimless.sim.model.params import WheelParams

    table1 = WheelParams()
    rows = [(p["name"], p["table1"]) if isinstance(p, dict) else (p.name, p.table1) for p in params]
    same = all(n in FIT_FIELDS and v == getattr(table1, FIT_FIELDS[n][0]) for n, v in rows)
    return "Table 1" if same else "wheel"


def _print_calibration(out: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    from rimless.sim.model.uncertain import SYMBOLS

    con = Console()
    start = start_name(out["params"])
    t = Table(title=f"calibration of the {out['model'].upper()} model", show_edge=False)
    for col in ("parameter", start, "fitted", "± 1 sigma", "95 % interval", "identifiable"):
        t.add_column(col, justify="left" if col == "parameter" else "right", no_wrap=True)
    for p in out["params"]:
        ci = p.get("ci95")
        t.add_row(
            f"{p['name']} ({p['unit']})",
            f"{p['table1']:.4g}",
            _fmt(p["estimate"], ".4g"),
            _fmt(p["se"], ".2g"),
            (f"{ci[0]:.4g}{'*' if p.get('ci_at_bound') else ''}-{ci[1]:.4g}" if ci else "–"),
            ("yes" if p["identifiable"] else ("conditional" if p.get("status") == "conditional" else "[red]NO[/]"))
            + (" (borderline)" if p["name"] == "c" and (out.get("loss_separation") or {}).get("borderline") else ""),
        )
    con.print(t)
    for p in out["params"]:
        if p.get("ci_at_bound") and p.get("ci95_linear"):
            con.print(
                f"  * {p['name']}: its 95 % interval is cut at its bound, {p['lower_bound']:g} {p['unit']} "
                f"(the linearised interval reached {p['ci95_linear'][0]:.4g}; no valid value lies below)",
                markup=False,
                highlight=False,
            )
    opt = out.get("optimizer", {})
    if opt:
        con.print(
            ("fit converged" if out.get("converged", True) else "fit did NOT converge")
            + f": {opt.get('message', '')} ({opt.get('nfev')} evaluations, {opt.get('starts')} start(s)); "
            "± 1 sigma is the larger of the model-based and the trial-clustered sandwich uncertainty"
            + (
                "; the data's alone: the held parameters' part is below"
                if any(p.get("se_held") for p in out["params"])
                else ""
            ),
            markup=False,
            highlight=False,
        )
    for line in optimizer_lines(opt):
        con.print(line, markup=False, highlight=False)
    budget = out.get("budget")
    if budget and budget.get("stopped_in"):
        con.print("SIMULATION BUDGET: " + budget["statement"], markup=False, highlight=False)
    if out.get("slope_passes"):
        con.print("slopes: " + out["slope_passes"]["statement"], markup=False, highlight=False)
    for p in out["params"]:
        cih = p.get("ci95_with_held")
        if cih:
            parts = sorted(p["held_contributions"].items(), key=lambda kv: -kv[1])[:3]
            con.print(
                f"  {p['name']}: ± {p['se_held']:.2g} {p['unit']} from the held parameters (refits with each at ± 1 "
                f"sd, in quadrature; largest: "
                + ", ".join(f"{SYMBOLS.get(n, n)} {v:.2g}" for n, v in parts)
                + (
                    f"; re-centred by {p['held_shift']:+.2g} {p['unit']}, their expected shift: "
                    + ", ".join(SYMBOLS.get(n, n) for n in p.get("held_shifts", {}))
                    + " held at its bound can only be above it"
                    if p.get("held_shift")
                    else ""
                )
                + f"); 95 % interval with them {cih[0]:.4g}-{cih[1]:.4g}"
                + (f" (cut at its bound {p['lower_bound']:g})" if p.get("ci_with_held_at_bound") else ""),
                markup=False,
                highlight=False,
            )
    for p in out["params"]:
        if p["note"]:
            con.print(f"  {p['name']}: {p['note']}", markup=False, highlight=False)
    sep = out.get("loss_separation")
    if sep and separation_is_new(sep, (p["note"] for p in out["params"])):
        con.print(
            f"  c against a constant loss per step (guide friction): {sep['note']}", markup=False, highlight=False
        )
    names = out["correlation"]["names"]
    if len(names) > 1:
        con.print(
            "correlation: "
            + "; ".join(
                f"{names[i]}-{names[j]} {_fmt(out['correlation']['matrix'][i][j], '+.2f')}"
                for i in range(len(names))
                for j in range(i + 1, len(names))
            ),
            markup=False,
            highlight=False,
        )
    if out.get("friction_vs_damping"):
        con.print(
            "guide friction vs damping told apart: " + out["friction_vs_damping"]["statement"],
            markup=False,
            highlight=False,
        )
    for name, row in (out.get("model_choice") or {}).items():
        con.print(f"model choice, {name} ({row['why_extra']}): {row['statement']}", markup=False, highlight=False)
    adequacy = out.get("adequacy") or {}
    per_trial = {row["trial"]: row for row in adequacy.get("per_trial", [])}
    r = Table(title=f"RMS residuals, {start} model -> calibrated", show_edge=False)
    r.add_column("trial", overflow="fold", min_width=12)  # a long name wraps; the numbers are never cut
    for col, width in (("deg", 5), ("dT ms", 6), ("-> ms", 6), ("CoM mm", 6), ("-> mm", 6)):
        r.add_column(col, justify="right", no_wrap=True, min_width=width)
    shown, r.caption = names_shown([Path(row["trial"]).stem for row in out["residuals"]])
    for row, stem in zip(out["residuals"], shown):
        r.add_row(
            stem,
            f"{row['slope_deg']:.2f}",
            _fmt(row["table1_rms_period_ms"], ".1f"),
            _fmt(row["calibrated_rms_period_ms"], ".1f"),
            _fmt(row["table1_rms_com_mm"], ".2f"),
            _fmt(row["calibrated_rms_com_mm"], ".2f"),
        )
    con.print(r)
    con.print(
        "dT: step period error over the steps the simulation reached; CoM: CoM height error; a release "
        "speed and a time shift are fitted per trial in both; –: none (why below).",
        markup=False,
        highlight=False,
    )
    for row, stem in zip(out["residuals"], shown):
        for line in _residual_notes(row, start):
            con.print(f"  {stem}: {line}", markup=False, highlight=False)
    if adequacy:
        from rimless.analysis.inference.adequacy import timing_noise_phrase

        noise = adequacy.get("noise", {})
        o = adequacy["overall"]
        con.print(
            f"model adequacy: {adequacy['statement']}; overall chi2/dof {_fmt(o['total']['ratio'], '.3g')} "
            f"(p = {_fmt(o['total']['p_value'], '.2g')}) against the noise measured from the recordings: CoM "
            f"{_fmt(noise.get('com_mm'), '.3f')} mm, impact times {_fmt(noise.get('impact_time_ms'), '.2f')} ms "
            f"({timing_noise_phrase(noise)}; chi2/dof 1: residuals as large as the noise)",
            markup=False,
            highlight=False,
        )
        for row in out["residuals"]:
            con.print(
                f"  {Path(row['trial']).stem}: chi2/dof CoM, periods {_adequacy_cell(per_trial.get(row['trial']))}",
                markup=False,
                highlight=False,
            )
    con.print(
        f"all trials: RMS period error {_fmt(out['rms_period_ms']['table1'], '.1f')} -> "
        f"{_fmt(out['rms_period_ms']['calibrated'], '.1f')} ms, RMS CoM error "
        f"{_fmt(out['rms_com_mm']['table1'], '.2f')} -> {_fmt(out['rms_com_mm']['calibrated'], '.2f')} mm "
        f"({out['simulations']} simulations)",
        markup=False,
        highlight=False,
    )
    if "critical_slope_deg" in out:
        c = out["critical_slope_deg"]
        parts = [f"trials {_fmt(c['trials'], '.3f')} deg ({c['trials_method']})"]
        parts += [
            f"model {_model_name(k.removeprefix('model_'))} {_fmt(v, '.3f')} deg"
            for k, v in c.items()
            if k.startswith("model_")
        ]
        con.print("critical slope: " + ", ".join(parts), markup=False, highlight=False)
    for _name, why in out["failed"].items():
        con.print(f"not calibrated: {why}", markup=False, highlight=False)
    if "prior" in out:
        _print_prior(con, out["prior"])
    for line in parameter_lines(out.get("parameters")):
        con.print(line, markup=False, highlight=False)
    tc = out.get("critical_slope_deg", {}).get("trials_ci_with_parameters_deg")
    if tc:
        cut = out["critical_slope_deg"].get("trials_ci_with_parameters_at_bound")
        con.print(
            f"critical slope from the trials, 95 % interval with the held parameters' uncertainty: "
            f"{tc[0]:.3f}-{tc[1]:.3f} deg" + (" (cut at 0 deg: its linearised lower end was below)" if cut else ""),
            markup=False,
            highlight=False,
        )


def _residual_notes(row: dict[str, Any], start: str = "Table 1") -> list[str]:
    """Why a residual row shows "–": its notes at the start (`start_name`) and calibrated (one line when they
    agree)."""
    a, b = row.get("table1_note"), row.get("calibrated_note")
    if a and a == b:
        return [f"{start} and calibrated: {a}"]
    return [f"{who}: {n}" for who, n in ((start, a), ("calibrated", b)) if n]


def _adequacy_cell(row: dict[str, Any] | None) -> str:
    """``1.02, 0.87`` (CoM, periods chi2/dof), and ``: does NOT fit`` when the trial does not."""
    if row is None:
        return "–"
    return f"{_fmt(row['com']['ratio'], '.3g')}, {_fmt(row['periods']['ratio'], '.3g')}" + (
        "" if row["fits"] else ": does NOT fit"
    )


def optimizer_lines(opt: dict[str, Any]) -> list[str]:
    """Where the starts ended (JSON ``optimizer.minima``): several minima of similar cost, starts that stopped on
    their budget."""
    minima = opt.get("minima") or []
    if not minima:
        return []
    names = list(minima[0]["values"])

    def where(m: dict[str, Any]) -> str:
        return ", ".join(f"{n} {m['values'][n]:.4g}" for n in names)

    out = [
        f"starts: {len(minima)} ({', '.join(m['start'] for m in minima)}); kept the lowest cost, from "
        f"{opt.get('best_start', '?')}"
        + (
            " (one parameter: its profile on the step periods, 0.5-2 times Table 1, has one valley)"
            if opt.get("profile_one_valley")
            else ""
        )
    ]
    lower = opt.get("lower_than_kept") or {}
    if lower:
        out[0] = out[0].replace("kept the lowest cost, from", "kept the lowest cost on the starts' sigmas, from")
        out.append(
            "  on the solution's sigmas lower than the kept one: "
            + "; ".join(
                f"{where(m)} (chi2 {lower[m['start']]:.3g} lower, from {m['start']})"
                for m in minima
                if m["start"] in lower
            )
        )
    if opt.get("several_minima"):
        similar = [m for m in minima if m["similar"]]
        out.append(
            "  several minima of similar cost (the noise cannot tell them apart; the intervals span them): "
            + "; ".join(f"{where(m)} (delta chi2 {m['delta_chi2']:.2g}, from {m['start']})" for m in similar)
        )
    budget = [
        m["start"] + (" (left after one round, far above the best)" if m.get("abandoned") else "")
        for m in minima
        if m.get("stopped_on_budget")
    ]
    if budget:
        out.append("  stopped on its budget (not converged) from: " + ", ".join(budget))
    return out


def _print_prior(con: Any, prior: dict[str, Any]) -> None:
    """Which parameters came from the leg test (`--prior`) and which from the walks."""
    con.print(f"leg-test priors from {prior['file']}:", markup=False, highlight=False)
    for row in prior["parameters"]:
        lo, hi = row["leg_test_ci"]
        share = row.get("leg_test_share")
        extra = (
            f", {100 * share:.0f} % of the information from the leg test"
            if share is not None and math.isfinite(share)
            else ""
        )
        con.print(
            f"  {row['key']}: leg test {row['leg_test']:.4g} (95 %: {lo:.4g} to {hi:.4g}) {row['unit']}: "
            f"{row['source']}{extra}",
            markup=False,
            highlight=False,
        )
        if "conflict" in row:
            con.print(f"    warning: {row['conflict']}", markup=False, highlight=False)
    if prior["from_walks_only"]:
        con.print("  from the walks only: " + ", ".join(prior["from_walks_only"]), markup=False, highlight=False)


def critical_lines(res: Any) -> str:
    """What `rimless demo` prints about the critical slope and the calibration of a report result."""
    cr, cal = res.critical, res.calibration
    if cr is None:
        return "critical slope: no trial with steps"
    lines = []
    if cr.chosen is not None:
        lines.append(
            f"critical slope from the trials: {cr.chosen.value_deg:.3f} deg ({cr.chosen.method}, 95 % "
            f"interval {cr.chosen.ci_deg[0]:.3f}-{cr.chosen.ci_deg[1]:.3f} deg"
            + (f"; bracket {cr.bracket_deg[0]:.3f}-{cr.bracket_deg[1]:.3f} deg)" if cr.bracket_deg else ")")
        )
    else:
        lines.append(f"critical slope from the trials: none ({cr.why})")
    summary = cr.held_summary()
    carried = (summary.get("parameter_uncertainty") or {}).get("models", {})
    for m, v in cr.model.get("critical_slope_deg", {}).items():
        label = m.upper().replace("_CALIBRATED", " with c calibrated on these trials (fitted, not a prediction)")
        text = held_model_text(carried[m], summary.get("parameters")) if m in carried else f"{_fmt(v, '.3f')} deg"
        lines.append(f"model critical slope, {label}: {text}")  # once, with its interval and centre
    if cal is not None:
        for p in cal.params:
            lines.append(
                f"calibrated {p.name}: {p.value:.3f} ± {p.se:.3f} {p.unit} ({start_name([p])}: {p.table1:g})"
                + ("" if p.identifiable else f" NOT identifiable: {p.note}")
            )
        sep = getattr(cal, "loss_separation", None)
        if sep and separation_is_new(sep, (p.note for p in cal.params)):
            lines.append(f"c against a constant loss per step (guide friction): {sep['note']}")
    lines += held_lines(summary, models=False)
    lines += [
        f"model critical slope, {m.upper()}: {held_model_text(d)}"
        for m, d in carried.items()
        if m not in cr.model.get("critical_slope_deg", {})
    ]
    return "\n".join(lines)


def coverage_cmd(
    series: Annotated[
        int | None,
        typer.Option(
            "--series",
            min=1,
            max=10000,
            metavar="N",
            help="Series to generate (12 trials each; default 4 through the importer, 60 with --truth pendulum).",
        ),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed (the same seed gives the same figures).")] = 0,
    truth: Annotated[
        str,
        typer.Option(
            "--truth",
            metavar="importer|pendulum",
            help="importer: truth trials written as Vicon exports and imported (default); pendulum: the fast model "
            "of the verdict process, handed the true parameters, no importer.",
        ),
    ] = "importer",
    inputs: Annotated[
        str | None,
        typer.Option(
            "--inputs",
            metavar="table1,truth",
            help="With --truth importer: the wheel inputs to check (table1: Table 1 with its default uncertainties; "
            "truth: the truth's parameters with an uncertainty; default both). --of calibrate also takes exact: the "
            "truth's held parameters, exact (its default); with table1 or truth its truths' held parameters are "
            "drawn from Table 1's stated uncertainties.",
            show_default=False,
        ),
    ] = None,
    of: Annotated[
        str,
        typer.Option(
            "--of",
            metavar="critical-slope|calibrate",
            help="The method checked: the critical slope (default) or `trials calibrate --fit c,k` (per parameter; "
            "through the importer, an ER wheel truth (`--truth-model`), k and c drawn).",
        ),
    ] = "critical-slope",
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    truth_model: Annotated[
        str | None,
        typer.Option(
            "--truth-model",
            metavar="independent|simulator",
            help="With --of calibrate: the ER wheel that walks the truth trials: independent (default; "
            "er_truth, written apart from the simulator) or simulator (the calibration's own model).",
            show_default=False,
        ),
    ] = None,
    friction_n: Annotated[
        str | None,
        typer.Option(
            "--friction-n",
            metavar="LO,HI",
            help="With --of calibrate: draw each truth's guide friction F_c uniform in LO-HI N (default: none, "
            "F_c = 0, or drawn half-normal with table1/truth); exact states it, truth states it +- 0.2 N, table1 "
            "states 0 +- 0.2 N.",
            show_default=False,
        ),
    ] = None,
    wheels: Annotated[
        str | None,
        typer.Option(
            "--wheels",
            metavar="table1|away",
            help="With --of calibrate: the truths' held parameters: table1 (default; Table 1's, or drawn from its "
            "stated sd with --inputs table1/truth) or away (m_H, m, L0 and the inertia ratio 0.3-3 drawn away "
            "from Table 1, redrawn where the truth has no gait; --inputs exact and truth only).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """How often the critical slope's 95 % interval contains the truth, on truth series.

    importer (default): rigid wheels away from Table 1 (inertia ratio 0.3-3, guide friction 0-0.6 N) in drawn labs.

    Each series: 12 trials on 6 slopes around the wheel's own critical slope, written as Vicon exports and imported.

    They go to `rimless.analysis.critical_slope` with each wheel input of --inputs; a few seconds a series.

    pendulum: the fast model of the verdict process (true parameters, 1 ms timing noise, no importer); ~1 s a series.

    --of calibrate: `trials calibrate --fit c,k` per parameter, on ER wheels with k and c drawn, through the importer.

    --of calibrate --inputs: exact (default), the held parameters the truth's; table1, drawn from Table 1's sd.

    --of calibrate --wheels away: the truths' masses, L0 and inertia ratio (0.3-3) drawn away from Table 1.
    """
    from rimless.progress import progress_bar

    mode = truth.strip().lower()
    if mode not in ("importer", "pendulum"):
        raise ParameterError(f"--truth must be importer or pendulum, got {truth!r}")
    n = series if series is not None else (4 if mode == "importer" else 60)
    method = of.strip().lower()
    if method not in ("critical-slope", "calibrate"):
        raise ParameterError(f"--of must be critical-slope or calibrate, got {of!r}")
    if method != "calibrate" and (truth_model is not None or friction_n is not None or wheels is not None):
        raise ParameterError("--truth-model, --friction-n and --wheels go with --of calibrate")
    if method == "calibrate":
        if mode != "importer":
            raise ParameterError("--of calibrate runs through the importer only (not with --truth pendulum)")
        _calibrate_coverage(n, seed, json_out, inputs, truth_model, friction_n, wheels)
        return
    if mode == "pendulum":
        from rimless.analysis.validation.coverage import run_coverage

        with progress_bar("coverage", total=n, json_out=json_out) as bar:
            res = run_coverage(n, seed, progress=lambda i: bar.update(completed=i, description=f"series {i}/{n}"))
        out = res.summary()
        if json_out:
            print_json({"truth": "pendulum", **out})
            return
        typer.echo("truth: the pendulum model of the verdict process (the true parameters, no importer)")
        _print_coverage(out, seed)
        return
    from rimless.analysis import critical_slope
    from rimless.analysis.validation.importer_coverage import INPUTS, TRUTH_MODEL, run_importer_coverage

    chosen = parse_list(inputs or ",".join(INPUTS), "--inputs", str, choices=INPUTS, unique=True, lower=True)
    with progress_bar("coverage", total=n, json_out=json_out) as bar:
        study = run_importer_coverage(
            n,
            seed,
            critical_slope,
            inputs=chosen,
            progress=lambda i, what: bar.update(completed=i, description=f"series {min(i + 1, n)}/{n}: {what}"),
        )
    out = study.summary()
    if json_out:
        print_json(out)
        return
    typer.echo(f"truth: {TRUTH_MODEL}")
    imp = out["imports"]
    typer.echo(
        f"{out['series']} series, {imp['trials']} trials ({out['labs']['y_up']} series in Y-up labs, "
        f"{out['labs']['markers']} with markers), {imp['refused']} imports refused"
        + ("".join(f"; {k}: {v}" for k, v in imp["reasons"].items()))
        + f"; {out['wall_s']:.0f} s wall, {out['cpu_s']:.0f} s CPU"
    )
    labels = {"table1": "wheel input: Table 1 with its default uncertainties", "truth": "wheel input: the truth's"}
    for name, d in out["inputs"].items():
        typer.echo(labels.get(name, name) + " parameters" * (name == "truth"))
        _print_coverage(d, seed)
        if d.get("coverage_with_parameters") is not None:
            lo, hi = d["coverage_with_parameters_ci95"]
            typer.echo(
                f"  with the held parameters' uncertainty: {d['covered_with_parameters']} of {d['estimated']} = "
                f"{d['coverage_with_parameters']:.1%} ({lo:.1%}-{hi:.1%}), median width "
                f"{_fmt(d['median_ci_with_parameters_width_deg'], '.4f')} deg"
            )
        for why, k in d["not_estimated"].items():
            typer.echo(f"  no estimate in {k} series: {why}")
        ir = d.get("inertia_ratio_from_trials")
        if ir and ir["of"]:
            lo, hi = ir["coverage_ci95"]
            held = ir["at_held_leg_length"]
            typer.echo(
                f"  inertia ratio from trials: 95 % interval holds the truth's in {ir['covered']} of {ir['of']} = "
                f"{ir['coverage']:.1%} ({lo:.1%}-{hi:.1%}; goal 90-98 %), median error "
                f"{_fmt(ir['median_error_pct'], '+.2f')} % (largest |error| {_fmt(ir['max_abs_error_pct'], '.1f')} %), "
                f"median se {_fmt(ir['median_se_pct'], '.2f')} %; at the held L0: {held['covered']} of {held['of']}"
            )


def _print_coverage(out: dict[str, Any], seed: int) -> None:
    """The lines of one coverage summary (the pendulum study's keys)."""
    lo, hi = out["coverage_ci95"] or (math.nan, math.nan)
    typer.echo(f"{out['estimated']} of {out['series']} series gave a critical slope (seed {seed})")
    typer.echo(
        f"95 % interval contains the truth in {out['covered']} of {out['estimated']}: "
        f"{_fmt(out['coverage'], '.1%')} (binomial 95 % interval {_fmt(lo, '.1%')}-{_fmt(hi, '.1%')}; "
        f"goal 90-98 %)"
    )
    typer.echo(
        f"median error {_fmt(out['median_error_deg'], '+.4f')} deg, median |error| "
        f"{_fmt(out['median_abs_error_deg'], '.4f')} deg, median interval width "
        f"{_fmt(out['median_ci_width_deg'], '.4f')} deg"
    )
    for m, d in out["per_method"].items():
        share = ""
        if d.get("coverage_ci95"):  # the importer study also gives each estimator's share and median error
            lo_m, hi_m = d["coverage_ci95"]
            share = (
                f" = {d['coverage']:.1%} ({lo_m:.1%}-{hi_m:.1%}), median error "
                f"{_fmt(d.get('median_error_deg'), '+.4f')} deg"
            )
        typer.echo(
            f"  {m}: covers {d['covered']}/{d['series']}{share}"
            + (f", reported in {d['chosen']}" if d["chosen"] else "")
        )


def _calibrate_coverage(
    n: int,
    seed: int,
    json_out: bool,
    inputs: str | None = None,
    truth_model: str | None = None,
    friction_n: str | None = None,
    wheels: str | None = None,
) -> None:
    """``trials coverage --of calibrate``: run the study, print its per-parameter coverage per wheel input."""
    from rimless.analysis import calibrate
    from rimless.analysis.validation.calibrate_coverage import INPUTS, TRUTHS, WHEELS, away_line, run_calibrate_coverage
    from rimless.progress import progress_bar

    chosen = parse_list(inputs or "exact", "--inputs", str, choices=INPUTS, unique=True, lower=True)
    model = parse_list(truth_model or TRUTHS[0], "--truth-model", choices=TRUTHS, count=1, lower=True)[0]
    fr: tuple[float, float] | None = None
    if friction_n is not None:
        lo_hi = parse_list(friction_n, "--friction-n", float, count=2)
        if len(lo_hi) != 2 or not (0.0 <= lo_hi[0] <= lo_hi[1] <= 5.0):
            raise ParameterError(f"--friction-n takes LO,HI with 0 <= LO <= HI <= 5 N, got {friction_n!r}")
        fr = (lo_hi[0], lo_hi[1])
    drawn = parse_list(wheels or WHEELS[0], "--wheels", choices=WHEELS, count=1, lower=True)[0]
    if drawn == "away" and "table1" in chosen:
        raise ParameterError("--wheels away goes with --inputs exact,truth (table1 states Table 1's wheel)")
    with progress_bar("coverage", total=n, json_out=json_out) as bar:
        out = run_calibrate_coverage(
            n,
            seed,
            calibrate,
            inputs=chosen,
            truth=model,
            friction_n=fr,
            wheels=drawn,
            progress=lambda i, what: bar.update(completed=i, description=f"series {min(i + 1, n)}/{n}: {what}"),
        )
    if json_out:
        print_json(out)
        return
    typer.echo(f"truth: {out['truth_model']}")
    typer.echo(
        f"{out['series']} series, {out['imports']['trials']} trials, {out['imports']['refused']} refused; "
        f"{out['wall_s']:.0f} s wall, {out['cpu_s']:.0f} s CPU" + away_line(out.get("draws") or {})
    )
    for name, res in out["inputs"].items():
        typer.echo(
            f"wheel input {name}: {res['wheel']}; {res['fitted']} of {out['series']} series fitted "
            f"({res['converged']} converged)"
        )
        for pname, d in res["parameters"].items():
            _print_calibrate_parameter(pname, d)
        for why, k in res["failed"].items():
            typer.echo(f"  failed in {k} series: {why}")


def _print_calibrate_parameter(name: str, d: dict[str, Any]) -> None:
    """The lines of one parameter of one input of ``trials coverage --of calibrate``."""
    if not d["fitted"]:
        typer.echo(f"  {name}: never fitted")
        return
    lo, hi = d["coverage_ci95"]
    held = " (with the held parameters' part)" if d["held_carried"] else ""
    typer.echo(
        f"  {name}: 95 % interval{held} holds the truth in {d['covered']} of {d['fitted']} = {d['coverage']:.1%} "
        f"({lo:.1%}-{hi:.1%}; goal 90-98 %), median relative error {d['median_relative_error']:+.2%}, "
        f"median half width {_fmt(d['median_relative_half_width'], '.2%')}, identifiable in {d['identifiable']}"
    )
    if d["held_carried"]:
        lo_d, hi_d = d["coverage_data_only_ci95"]
        typer.echo(
            f"    the data's interval alone: {d['covered_data_only']} of {d['fitted']} = "
            f"{d['coverage_data_only']:.1%} ({lo_d:.1%}-{hi_d:.1%}), rms z {_fmt(d.get('rms_z_data_only'), '.2f')}"
        )
    parts = d.get("median_relative_se") or {}
    typer.echo(
        f"    rms (estimate - truth) / se {_fmt(d.get('rms_z'), '.2f')} (1 when the se is honest); median se: "
        f"data {_fmt(parts.get('se_model'), '.2%')}, sandwich over trials {_fmt(parts.get('se_sandwich'), '.2%')}, "
        f"the trials' slopes {_fmt(parts.get('se_slope'), '.2%')}, held parameters {_fmt(parts.get('se_held'), '.2%')}"
        f"; effective only in {d.get('effective_only')}"
    )
    contrib = d.get("median_relative_held_contributions") or {}
    if contrib:
        from rimless.sim.model.uncertain import SYMBOLS

        typer.echo(
            "    median held parts: "
            + ", ".join(
                f"{SYMBOLS.get(h, h)} {_fmt(v, '.2%')}"
                for h, v in sorted(contrib.items(), key=lambda kv: -(kv[1] or 0))
            )
        )
