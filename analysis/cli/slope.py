"""``rimless trials slope-coverage``: how often the importer's slope interval holds the true slope.

Parses, calls `rimless.analysis.validation.slope_coverage` (truth walks recorded as Vicon exports and imported),
prints. Only typer and the standard library at module level.
"""

from __future__ import annotations

from typing import Annotated, Any

import typer

from rimless.cli_rules import EXIT_FAILURE, print_json, user_facing


def register(app: typer.Typer) -> None:
    """Add ``slope-coverage`` to the ``trials`` app."""
    app.command("slope-coverage")(user_facing(slope_coverage_cmd))


HEADER = f"    {'':<18}{'held':>8}{'%':>7}{'95 % CI':>12}{'rms z':>7}{'error':>8}{'|error|':>8}{'half':>7}"


def _line(label: str, g: dict[str, Any]) -> str:
    """One row: coverage (Wilson 95 % interval), rms z, median error, |error| and half width (deg)."""
    if not g["n"]:
        return f"    {label:<18}{'none':>8}"
    lo, hi = g["coverage_ci95"]
    return (
        f"    {label:<18}{g['covered']:>4}/{g['n']:<3}{100 * g['coverage']:>7.1f}{f'{100 * lo:.0f}-{100 * hi:.0f}':>12}"
        f"{g['rms_z']:>7.2f}{g['median_error_deg']:>+8.4f}{g['median_abs_error_deg']:>8.4f}"
        f"{g['median_half_width_deg']:>7.4f}"
    )


def slope_coverage_cmd(
    series: Annotated[
        int, typer.Option("--series", min=1, max=100000, metavar="N", help="Walks to draw of each truth (rigid, ER).")
    ] = 3,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed (the same seed gives the same figures).")] = 0,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    truth_model: Annotated[
        str,
        typer.Option(
            "--truth-model",
            metavar="independent|simulator",
            help="The model that walks the ER truth: independent (er_truth, written apart from the simulator; "
            "about 10 s of CPU a walk) or simulator (the simulator's own ER wheel).",
        ),
    ] = "independent",
) -> None:
    """How often the importer's 95 % slope interval holds the true slope, per evidence and per lab.

    Each walk: a rigid wheel with guide friction or a compliant ER wheel (--truth-model), away from Table 1, on a
    drawn slope, recorded in a drawn lab (Z-up or Y-up, any heading, a Tracker object or 4 markers, some with the
    middle of most stances hidden) and imported with no slope given. Per evidence (contacts, impact line, path,
    and the slope used: slope_ci_rad): coverage with its binomial 95 % interval, rms of error / sd (1 when
    honest), median error and half width; each walk imported without the wheel (the importer bounds the legs'
    drift) and with it (wheel_given: rigid legs, or the ER wheel's k).
    """
    from rimless.analysis.validation.slope_coverage import ER_TRUTH_MODELS, KINDS, TRUTHS, run_slope_coverage
    from rimless.errors import ParameterError
    from rimless.progress import progress_bar

    model = truth_model.strip().lower()
    if model not in ER_TRUTH_MODELS:
        raise ParameterError(f"--truth-model must be {' or '.join(ER_TRUTH_MODELS)}, got {truth_model!r}")
    total = series * len(TRUTHS)
    with progress_bar("slope coverage", total=total, json_out=json_out) as bar:
        res = run_slope_coverage(
            series,
            seed,
            progress=lambda i, what: bar.update(completed=i, description=f"{what} ({i}/{total})"),
            truth_model=model,
        )
    out = res.summary()
    if json_out:
        print_json(out)
        return
    typer.echo(
        f"{out['draws']} walks ({series} of each truth, seed {seed}), {out['refused']} refused; goal 90-98 %; "
        f"CPU {out['cpu_s']:.1f} s"
    )
    typer.echo("z = error / sd, sd = half width / 1.96 (rms z 1 when honest); medians in deg")
    said = {"independent": "er_truth, written apart from the simulator", "simulator": "the simulator's ER wheel"}
    typer.echo(f"ER truth model: {model} ({said[model]})")
    er_name = "of the simulator" if model == "simulator" else "of er_truth"
    names = {"rigid": "rigid wheel with guide friction", "er": f"compliant ER wheel {er_name}"}
    for truth, d in out["truths"].items():
        told = out["wheel_given"]["truths"][truth]
        typer.echo(f"{names[truth]}, the wheel not given:")
        typer.echo(HEADER)
        typer.echo("  per evidence:")
        for kind in KINDS:
            typer.echo(_line("slope used" if kind == "used" else kind, d["evidence"][kind]))
        typer.echo("  slope used, per lab:")
        for lab, g in d["labs"].items():
            typer.echo(_line(lab, g))
        typer.echo(f"  the wheel given ({'rigid legs' if truth == 'rigid' else 'its k +- 10 %'}), per evidence:")
        for kind in KINDS:
            typer.echo(_line("slope used" if kind == "used" else kind, told["evidence"][kind]))
    for reason in out["refused_reasons"]:
        typer.echo(f"refused: {reason}")
    if not out["used"]["n"]:
        raise typer.Exit(EXIT_FAILURE)
