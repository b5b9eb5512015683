"""``rimless trials adequacy-coverage``: how often the calibration's adequacy check and model choice are right.

Parses, runs `rimless.analysis.validation.adequacy_coverage` with the public `rimless.analysis.calibrate`, prints.
Only typer and the standard library at module level.
"""

from __future__ import annotations

from typing import Annotated, Any

import typer

from rimless.cli_rules import EXIT_FAILURE, print_json, user_facing
from rimless.values import parse_list

SCENARIO_NAMES = ("adequate", "adequate-true-slope", "held-k", "friction-misfit", "choice-null", "choice-friction")


def register(app: typer.Typer) -> None:
    """Add ``adequacy-coverage`` to the ``trials`` app."""
    app.command("adequacy-coverage")(user_facing(adequacy_coverage_cmd))


def adequacy_coverage_cmd(
    series: Annotated[
        int, typer.Option("--series", min=1, max=100000, metavar="N", help="Series to simulate per scenario.")
    ] = 1,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed (the same seed gives the same figures).")] = 0,
    scenario: Annotated[
        str,
        typer.Option(
            "--scenario",
            metavar="NAMES",
            help="Comma-separated, among adequate, adequate-true-slope, held-k, friction-misfit, choice-null, "
            "choice-friction; or all.",
        ),
    ] = "all",
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    truth_model: Annotated[
        str,
        typer.Option(
            "--truth-model",
            metavar="independent|simulator",
            help="The ER wheel that walks the truth trials: independent (er_truth, written apart from the "
            "simulator) or simulator (the calibration's own model).",
        ),
    ] = "independent",
) -> None:
    """How often `trials calibrate` says "does not fit" or claims guide friction, on ER truths via the importer.

    Each series: an ER wheel with k 1500-4000 N/m, c 2-20 N s/m (F_c 0.1-0.6 N in the friction scenarios).

    Four trials at 2-3.5 deg in a drawn lab, written as Vicon exports, imported and calibrated (seconds a series).

    adequate: fit c,k on the model's own truth (a "does not fit" is a false alarm). held-k: fit c, k held 25 % off.

    friction-misfit: friction in the truth, fit c,k. choice-null, choice-friction: fit c,guide_friction_n.
    """
    from rimless.analysis import calibrate
    from rimless.analysis.validation.adequacy_coverage import run_adequacy_coverage
    from rimless.analysis.validation.calibrate_coverage import TRUTHS
    from rimless.errors import ParameterError
    from rimless.progress import progress_bar

    model = truth_model.strip().lower()
    if model not in TRUTHS:
        raise ParameterError(f"--truth-model must be {' or '.join(TRUTHS)}, got {truth_model!r}")
    chosen = (
        list(SCENARIO_NAMES)
        if scenario.strip().lower() == "all"
        else parse_list(scenario, "--scenario", str, choices=list(SCENARIO_NAMES), unique=True, lower=True)
    )
    total = series * len(chosen)
    with progress_bar("adequacy coverage", total=total, json_out=json_out) as bar:
        out = run_adequacy_coverage(
            series,
            seed,
            calibrate,
            scenarios=chosen,
            progress=lambda i, what: bar.update(completed=i, description=what),
            truth=model,
        )
    if json_out:
        print_json(out)
    else:
        _print(out)
    if not any(s["calibrated"] for s in out["scenarios"].values()):
        typer.echo("error: no series was calibrated (see the failures above)", err=True)
        raise typer.Exit(EXIT_FAILURE)


def _pct(r: dict[str, Any]) -> str:
    if not r["of"]:
        return "none calibrated"
    lo, hi = r["ci95"]
    return f"{r['count']} of {r['of']} = {r['rate']:.1%} ({lo:.1%}-{hi:.1%})"


def _print(out: dict[str, Any]) -> None:
    th = out["thresholds"]
    typer.echo(f"truth: {out['truth_model']}")
    typer.echo(
        f"thresholds: does not fit when p < {th['adequacy_p']:g} and chi^2/dof > {th['adequacy_ratio']:g}; "
        f"friction claimed when the likelihood-ratio p < {th['model_choice_p']:g}; "
        f"{out['series_per_scenario']} series per scenario (seed {out['seed']}), {out['cpu_s']:.0f} s CPU, "
        f"{out['wall_s']:.0f} s wall"
    )
    for name, s in out["scenarios"].items():
        verdict = s[s["verdict"]]
        label = "does not fit" if s["verdict"] == "does_not_fit" else "friction claimed"
        right = {
            ("does_not_fit", False): "false alarms",
            ("does_not_fit", True): "misfits detected",
            ("friction_claimed", False): "false claims",
            ("friction_claimed", True): "friction found",
        }[(s["verdict"], s["right_verdict"])]
        nominal = f"; nominal {s['nominal_rate']:.1%}" if s["nominal_rate"] is not None else ""
        typer.echo(f"{name} ({s['what']}): {label} in {_pct(verdict)} ({right}{nominal})")
        com, per = s["com_figure"], s["periods_figure"]
        if s["calibrated"]:
            typer.echo(
                f"  median chi^2/dof CoM {com['median_ratio']:.3g}, periods {per['median_ratio']:.3g}; "
                f"p < 0.05 in CoM {com['p_below_0.05']['count']}, periods {per['p_below_0.05']['count']} of "
                f"{s['calibrated']}"
                + (
                    f"; likelihood-ratio p < 0.05 in {s['model_choice_p']['p_below_0.05']['count']}"
                    if "model_choice_p" in s
                    else ""
                )
            )
        for key in ("by_friction_n", "k_held_high", "k_held_low"):
            if key in s:
                parts = s[key].items() if key == "by_friction_n" else [("", s[key])]
                for sub, r in parts:
                    head = " ".join([key.replace("_", " "), sub]).strip()
                    typer.echo(f"  {head}: {label} in {_pct(r)}" if r["of"] else f"  {head}: no series")
        for why, k in s["failed"].items():
            typer.echo(f"  failed in {k} series: {why}")
