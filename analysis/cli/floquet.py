"""``rimless trials floquet``: the trials' step-to-step multiplier beside the model's eigenvalue.

Parses, calls `rimless.analysis.floquet` (the public API; the inputs are read first so that a refused file
does not stop the others), prints. Only typer and the standard library at module level.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import typer

from rimless.analysis.cli.critical import (
    GapOpt,
    MarkersOpt,
    ObjectOpt,
    ParamsOpt,
    SlopeOpt,
    UpOpt,
    exit_nothing_read,
    parameter_lines,
    print_refused,
    raw_import_options,
)
from rimless.cli_rules import EXIT_FAILURE, EXIT_USER_ERROR, print_json, user_facing
from rimless.errors import ParameterError

MODELS = ("er", "ve")


def register(app: typer.Typer) -> None:
    """Add ``floquet`` to the ``trials`` app."""
    app.command("floquet")(user_facing(floquet_cmd))
    app.command("floquet-coverage")(user_facing(floquet_coverage_cmd))


def _fmt(v: Any, fmt: str) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def floquet_cmd(
    trials: Annotated[list[Path], typer.Argument(help="Parquet trials (from `trials import`) or raw Vicon CSVs.")],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    model: Annotated[
        str, typer.Option("--model", metavar="er|ve", help="Model whose eigenvalue is shown beside the trials'.")
    ] = "er",
    calibrate_c: Annotated[
        bool,
        typer.Option(
            "--calibrated/--no-calibrated",
            help="Calibrate the model's c on the trials first (as `trials calibrate --fit c`; slower).",
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
    """Step-to-step return map of the post-impact angular speed: its multiplier per slope, beside the model's.

    The regression's noise bias is corrected with the noise measured from the recording (95 % t interval);
    a lagged-covariance estimate (x_{k-1} as the instrument) is the check.

    Trials too short or transient-only are flagged with the reason. Exit 1 when no slope gives an estimate.
    """
    from rimless.analysis import floquet
    from rimless.analysis.api.runs import import_wheel
    from rimless.analysis.inference.runs import load_trials
    from rimless.progress import progress_bar
    from rimless.sim import Wheel

    key = model.strip().lower()
    if key not in MODELS:
        raise ParameterError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    raw = raw_import_options(slope_deg, max_gap_ms, up_axis, object_, markers)
    if params is not None and not params.is_file():
        raise ParameterError(f"--params {params}: no such file")
    which: Literal["er", "ve"] = "er" if key == "er" else "ve"
    wheel = Wheel(params, which) if params is not None else Wheel(model=which)
    extra = [n for n in wheel.input.fit if n != "damping_ns_per_m"]
    if extra:
        raise ParameterError(
            f'{params}: a parameter marked "fit": trials floquet fits only c (--calibrated); give a value (and sd)'
        )
    with progress_bar("importing", json_out=json_out) as bar:
        # the importer gets the --params wheel (as `trials import --params`): its legs' k bounds the slope's drift
        legs = import_wheel(params, rigid_legs=False)
        opts = {**raw, "wheel": legs}
        loaded = load_trials(trials, opts)
        print_refused(loaded.refused)
        if not loaded.trials:
            exit_nothing_read(loaded.refused)
        res = floquet(
            loaded.trials,
            wheel,
            group_tol_deg=group_tol_deg,
            calibrate_c=calibrate_c or bool(wheel.input.fit),
            progress=lambda s: bar.update(description=s),
        )
    res.refused = list(loaded.refused)
    out = res.to_dict()
    if json_out:
        print_json(out)
    else:
        _print(out)
    if loaded.refused:
        raise typer.Exit(EXIT_USER_ERROR)
    if not res.estimated:
        why = "; ".join(f"{g['slope_deg']:.2f} deg: {g['reason']}" for g in out["groups"])
        typer.echo(f"error: no multiplier from the trials: {why}", err=True)
        raise typer.Exit(EXIT_FAILURE)


def _print(out: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    con = Console()
    model = out["model"].upper()
    t = Table(title=f"multiplier of the post-impact speed: trials, {model} model", show_edge=False)
    for col, width in (
        ("deg", 5),
        ("pairs", 5),
        ("trials", 6),
        ("95 %", 11),
        ("OLS", 5),
        ("lag", 5),
        (model, 5),
        ("95 %", 11),
    ):
        t.add_column(col, justify="right", no_wrap=True, min_width=width)
    for g in out["groups"]:
        m = g.get("model") or {}
        mci = m.get("ci95")
        if g["status"] == "estimated":
            lo, hi = g["ci95"]
            t.add_row(
                f"{g['slope_deg']:.3f}",
                str(g["pairs"]),
                f"{g['multiplier']:.3f}",
                f"{lo:.3f}-{hi:.3f}",
                _fmt(g["ols_multiplier"], ".3f"),
                _fmt(g["lagged_multiplier"], ".3f"),
                _fmt(m.get("eigenvalue"), ".3f"),
                f"{mci[0]:.3f}-{mci[1]:.3f}" if mci else "–",
            )
        else:
            t.add_row(
                f"{g['slope_deg']:.3f}",
                str(g.get("pairs", 0)),
                "–",
                "–",
                "–",
                "–",
                _fmt(m.get("eigenvalue"), ".3f"),
                f"{mci[0]:.3f}-{mci[1]:.3f}" if mci else "–",
            )
    con.print(t)
    _lines(con, out)


def _lines(con: Any, out: dict[str, Any]) -> None:
    model = out["model"].upper()
    say = lambda s: con.print(s, markup=False, highlight=False)  # noqa: E731
    say(
        "trials: the corrected multiplier (noise bias removed) and its 95 % interval; OLS: the plain regression "
        "(biased toward 0 by the noise); lagged: x_{k-1} as the instrument (a check); "
        f"model {model}: the dominant eigenvalue of the model's map at that slope, its interval from the held "
        "parameters and the slope's uncertainty"
    )
    for g in out["groups"]:
        if g["status"] == "estimated":
            inside = g.get("model_inside_ci95")
            say(
                f"{g['slope_deg']:.3f} deg: {len(g['used_trials'])} trial(s), {g['pairs']} pairs, noise "
                f"{g['noise_sd_rad_s']:.3g} rad/s against a wander of {g['wander_sd_rad_s']:.3g} rad/s "
                f"(reliability {g['reliability']:.2f}), gait x* {g['fixed_point_rad_s']:.3f} rad/s"
                + ("" if inside is None else f"; the model's eigenvalue is {'inside' if inside else 'OUTSIDE'}")
            )
        else:
            say(f"{g['slope_deg']:.3f} deg: no estimate: {g['reason']}")
        note = (g.get("model") or {}).get("note")
        if note:
            say(f"  model: {note}")
    for r in out["trials"]:
        if r["status"] != "used":
            say(f"{Path(r['file']).name}: {r['status']}: {r['reason']}")
    cal = out.get("calibration")
    if cal:
        say(
            f"c calibrated on these trials: {cal['c_ns_per_m']:.3g} ± {cal['se_ns_per_m']:.2g} N s/m (the model's "
            "column uses it: fitted, not a prediction)"
            if cal["calibrated"]
            else f"c not calibrated: {cal['note']}"
        )
    say(f"section: {out['section']}")
    for line in parameter_lines(out.get("parameters")):
        say(line)


def floquet_coverage_cmd(
    kind: Annotated[
        str,
        typer.Option("--kind", metavar="rigid|er", help="Truth wheel: the rigid wheel or the simulator's ER wheel."),
    ] = "rigid",
    series: Annotated[int, typer.Option("--series", min=1, max=100000, metavar="N", help="Series to simulate.")] = 3,
    trials: Annotated[int, typer.Option("--trials", min=1, max=100, metavar="N", help="Trials per series.")] = 3,
    steps: Annotated[int, typer.Option("--steps", min=3, max=1000, metavar="N", help="Impacts per trial.")] = 15,
    slope_sd_deg: Annotated[
        float | None,
        typer.Option(
            "--slope-sd-deg", min=0.0, max=5.0, metavar="DEG", help="Per-step slope sd (default rigid 0.8, er 0.6)."
        ),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed (the same seed gives the same figures).")] = 0,
    labs: Annotated[
        str,
        typer.Option(
            "--labs",
            metavar="fixed|drawn",
            help="fixed: Z-up, ramp heading 25 deg, a Tracker object; drawn: per series Z-up or Y-up, any heading, "
            "an object or 4 markers.",
        ),
    ] = "fixed",
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    truth_model: Annotated[
        str,
        typer.Option(
            "--truth-model",
            metavar="independent|simulator",
            help="The ER wheel that walks the er truth's trials and gives its multiplier: independent (er_truth, "
            "written apart from the simulator) or simulator (the model's own).",
        ),
    ] = "independent",
) -> None:
    """How often `trials floquet`'s 95 % interval holds the truth's multiplier, on truth trials through the importer.

    rigid: M 2.6 kg, I_hub 0.05 kg m^2, L 0.21 m at 4.5 deg; its multiplier beta^2 (closed form).

    er: an ER wheel, k = 2000 N/m, c = 14 N s/m at 2.5 deg, walked by --truth-model; that wheel's dominant
    eigenvalue (independent: er_truth's own, about 12 s of CPU a series; simulator: the model's).

    Each step's slope is drawn; each trial is written as a Vicon export, imported and estimated as `trials floquet` does.
    """
    from rimless.analysis.validation.floquet_coverage import run
    from rimless.progress import progress_bar

    key = kind.strip().lower()
    if key not in ("rigid", "er"):
        raise ParameterError(f"--kind must be rigid or er, got {kind!r}")
    lab_mode = labs.strip().lower()
    if lab_mode not in ("fixed", "drawn"):
        raise ParameterError(f"--labs must be fixed or drawn, got {labs!r}")
    from rimless.analysis.validation.floquet_coverage import TRUTHS

    model = truth_model.strip().lower()
    if model not in TRUTHS:
        raise ParameterError(f"--truth-model must be {' or '.join(TRUTHS)}, got {truth_model!r}")
    sd = slope_sd_deg if slope_sd_deg is not None else (0.8 if key == "rigid" else 0.6)
    with progress_bar("floquet coverage", total=series, json_out=json_out) as bar:
        out = run(
            key,
            series,
            trials,
            steps,
            sd,
            seed,
            progress=lambda i: bar.update(completed=i, description=f"series {i}/{series}"),
            labs=lab_mode,
            truth=model,
        )
    if json_out:
        print_json(out)
        return
    typer.echo(
        f"truth: {key} wheel at {out['slope_deg']:g} deg, slope sd {sd:g} deg per step, multiplier "
        f"{out['truth_multiplier']:.4f}; {series} series of {trials} trials x {steps} impacts (seed {seed})"
    )
    drawn = out["drawn_labs"]
    typer.echo(
        f"{out['estimated']} of {series} series gave an estimate; CPU {out['cpu_s']:.1f} s; labs: "
        + (
            f"drawn ({drawn['y_up']} Y-up, {drawn['markers']} with markers)"
            if drawn
            else "Z-up, heading 25 deg, object"
        )
    )
    typer.echo(f"truth model: {out['truth_model']}")
    typer.echo(f"the importer is told the wheel, for its legs' drift: {out['import_legs']}")
    for name, label in (("corrected", "corrected (the estimate)"), ("ols", "OLS (plain)"), ("lagged", "lagged")):
        d = out[name]
        if not d["of"]:
            typer.echo(f"  {label}: no estimate")
            continue
        lo, hi = d["coverage_ci95"]
        wlo, whi = d["coverage_wilson95"]
        typer.echo(
            f"  {label}: 95 % interval holds the truth in {d['covered']} of {d['of']} = {d['coverage']:.1%} "
            f"(binomial 95 % interval {lo:.1%}-{hi:.1%}, Wilson {wlo:.1%}-{whi:.1%}); rms z {d['rms_z']:.2f}; "
            f"median error {d['median_error']:+.3f}, median width {d['median_ci_width']:.3f}"
        )
    for what, counts in (("flagged trials", out["flagged_trials"]), ("not estimated", out["not_estimated"])):
        if counts:
            typer.echo(f"{what}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if not out["estimated"]:
        raise typer.Exit(EXIT_FAILURE)
