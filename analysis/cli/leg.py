"""``rimless trials leg-fit``: fit a leg's k, c and guide friction to `rimless robot leg-test` logs
(`rimless.analysis.inference.leg_fit`), print.

Only typer and the standard library at module level (``rimless --help`` stays fast).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from rimless.cli_rules import print_json, user_facing

#: `rimless.analysis.inference.leg_fit.DEFAULT_MOVING_MASS_KG` (here so that ``--help`` needs no numpy)
DEFAULT_MOVING_MASS_KG = 0.0378


def register(app: typer.Typer) -> None:
    """Add ``leg-fit`` to the ``trials`` app."""
    app.command("leg-fit")(user_facing(leg_fit_cmd))


def leg_fit_cmd(
    logs: Annotated[list[Path], typer.Argument(help="Logs of `rimless robot leg-test` (one leg; "
                                               "several releases fit together).")],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    plot: Annotated[Optional[Path], typer.Option("--plot", metavar="FILE", help="Figure of the fit and its "
                                                 "residuals (PNG, PDF, SVG).", show_default=False)] = None,
    moving_mass_kg: Annotated[float, typer.Option(
        "--moving-mass-kg", min=1e-6, max=100.0, metavar="KG",
        help="The leg's moving mass (default: Table 1's leg mass m, all at the foot in the wheel model); k and "
             "c scale with it.")] = DEFAULT_MOVING_MASS_KG,
    moving_mass_sd_kg: Annotated[float, typer.Option(
        "--moving-mass-sd-kg", min=0.0, max=100.0, metavar="KG",
        help="Its uncertainty (1 sigma), carried into the intervals of k, c and F_c.")] = 0.0,
    counts_per_m: Annotated[Optional[float], typer.Option(
        "--counts-per-m", min=1.0, max=1e9, metavar="N",
        help="Sensor scale at 1600 cpi (default: each log's); only the friction depends on it.",
        show_default=False)] = None,
) -> None:
    """Fit a leg's stiffness k, damping c and Coulomb guide friction F_c to its free motion.

    The model: a spring-damper with Coulomb friction and stiction, released at rest (piecewise closed form),
    least squares over the released segment of every log. 95 % intervals.

    k and c come from the natural frequency and the decay: they do not depend on the sensor's counts per
    metre. F_c does. Bad logs: one line naming the file, line and field (exit 2).
    """
    from rimless.analysis.inference.leg_fit import fake_truth, run_leg_fit

    fit = run_leg_fit(logs, moving_mass_kg=moving_mass_kg, moving_mass_sd_kg=moving_mass_sd_kg,
                      counts_per_m=counts_per_m, plot=plot)
    out = fit.summary()
    truth = fake_truth(fit)
    if truth is not None:
        out["fake_truth"] = truth
    if json_out:
        print_json(out)
        return
    _print(out, plot)


def _print(out: dict[str, Any], plot: Optional[Path]) -> None:
    def ci(key: str, fmt: str) -> str:
        lo, hi = out[key + "_ci"]
        return f"{out[key]:{fmt}} (95 %: {lo:{fmt}} to {hi:{fmt}})"

    n = sum(p["samples"] for p in out["per_log"])
    typer.echo(f"leg {out['leg']}, {len(out['per_log'])} log(s), {n} samples fitted: natural frequency "
               f"{ci('natural_frequency_hz', '.2f')} Hz, damping ratio {ci('damping_ratio', '.3f')}")
    typer.echo(f"k   = {ci('k_n_per_m', '.0f')} N/m")
    typer.echo(f"c   = {ci('c_n_s_per_m', '.3f')} N s/m")
    typer.echo(f"F_c = {ci('guide_friction_n', '.3f')} N (guide friction)")
    typer.echo(f"moving mass {out['moving_mass_kg']:g} kg (--moving-mass-kg): k and c scale with it; "
               + out["intervals"].removeprefix("95 %: "))
    cpms = sorted({round(p["counts_per_m"], 1) for p in out["per_log"]})
    typer.echo("k and c come from frequency and decay and do not depend on the sensor's counts per metre; F_c "
               f"does (it scales with it: {', '.join(f'{c:g}' for c in cpms)} counts/m)")
    for p in out["per_log"]:
        typer.echo(f"  {p['file']}: {p['samples']} samples, {p['half_cycles']} half cycles, release delay "
                   f"{p['release_delay_ms']:.1f} ms, residual RMS {p['residual_rms_counts']:.2f} counts")
    opt = out["optimizer"]
    typer.echo(("fit converged" if out["converged"] else "fit did NOT converge (stopped on its budget)")
               + f": {opt['message']} ({opt['nfev']} evaluations); residual RMS {out['residual_rms_counts']:.2f} "
               f"counts, lag-1 autocorrelation {out['residual_lag1_autocorrelation']:.2f}")
    if "fake_truth" in out:
        t = out["fake_truth"]
        typer.echo(f"fake leg's truth: k = {t['k_n_per_m']:g} N/m, c = {t['c_n_s_per_m']:g} N s/m, F_c = "
                   f"{t['guide_friction_n']:g} N, moving mass {t['moving_mass_kg']:g} kg")
    if plot is not None:
        typer.echo(f"figure: {plot}")
