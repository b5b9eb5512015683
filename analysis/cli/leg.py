"""``rimless trials leg-fit``: fit a leg's k, c and guide friction to `rimless robot leg-test` logs
(`rimless.analysis.inference.leg_fit`), print; ``rimless trials leg-fit-coverage``: how often its intervals hold
the truth of simulated leg tests (`rimless.analysis.validation.leg_fit_coverage`).

Only typer and the standard library at module level (``rimless --help`` stays fast).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from rimless.cli_rules import print_json, user_facing

#: `rimless.analysis.inference.leg_fit.DEFAULT_MOVING_MASS_KG` (here so that ``--help`` needs no numpy)
DEFAULT_MOVING_MASS_KG = 0.0378


def register(app: typer.Typer) -> None:
    """Add ``leg-fit`` and ``leg-fit-coverage`` to the ``trials`` app."""
    app.command("leg-fit")(user_facing(leg_fit_cmd))
    app.command("leg-fit-coverage")(user_facing(leg_fit_coverage_cmd))


def leg_fit_cmd(
    logs: Annotated[
        list[Path], typer.Argument(help="Logs of `rimless robot leg-test` (one leg; several releases fit together).")
    ],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot", metavar="FILE", help="Figure of the fit and its residuals (PNG, PDF, SVG).", show_default=False
        ),
    ] = None,
    moving_mass_kg: Annotated[
        float,
        typer.Option(
            "--moving-mass-kg",
            min=1e-6,
            max=100.0,
            metavar="KG",
            help="The leg's moving mass (default: Table 1's leg mass m, all at the foot in the wheel model); k and "
            "c scale with it.",
        ),
    ] = DEFAULT_MOVING_MASS_KG,
    moving_mass_sd_kg: Annotated[
        float,
        typer.Option(
            "--moving-mass-sd-kg",
            min=0.0,
            max=100.0,
            metavar="KG",
            help="Its uncertainty (1 sigma), carried into the intervals of k, c and F_c.",
        ),
    ] = 0.0,
    counts_per_m: Annotated[
        float | None,
        typer.Option(
            "--counts-per-m",
            min=1.0,
            max=1e9,
            metavar="N",
            help="Sensor scale at 1600 cpi (default: each log's); only the friction depends on it.",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Fit a leg's stiffness k, damping c and Coulomb guide friction F_c to its free motion.

    The model: a spring-damper with Coulomb friction and stiction, released at rest (piecewise closed form),
    least squares over the released segment of every log. 95 % intervals.

    k and c come from the natural frequency and the decay: they do not depend on the sensor's counts per
    metre. F_c does. Bad logs: one line naming the file, line and field (exit 2).
    """
    from rimless.analysis import leg_fit

    fit = leg_fit(
        logs, moving_mass_kg=moving_mass_kg, moving_mass_sd_kg=moving_mass_sd_kg, counts_per_m=counts_per_m, plot=plot
    )
    out = fit.to_dict()
    if json_out:
        print_json(out)
        return
    _print(out, plot)


def _print(out: dict[str, Any], plot: Path | None) -> None:
    def ci(key: str, fmt: str) -> str:
        lo, hi = out[key + "_ci"]
        return f"{out[key]:{fmt}} (95 %: {lo:{fmt}} to {hi:{fmt}})"

    n = sum(p["samples"] for p in out["per_log"])
    typer.echo(
        f"leg {out['leg']}, {len(out['per_log'])} log(s), {n} samples fitted: natural frequency "
        f"{ci('natural_frequency_hz', '.2f')} Hz, damping ratio {ci('damping_ratio', '.3f')}"
    )
    typer.echo(f"k   = {ci('k_n_per_m', '.0f')} N/m")
    typer.echo(f"c   = {ci('c_n_s_per_m', '.3f')} N s/m")
    if out.get("friction_resolved", True):
        typer.echo(f"F_c = {ci('guide_friction_n', '.3f')} N (guide friction)")
    else:
        ft = out["friction_test"]
        typer.echo(
            f"F_c < {out['guide_friction_n_upper_95']:.3g} N (95 % upper bound; guide friction not resolved: the "
            f"frictionless model fits within delta chi2 {ft['delta_chi2_without_friction']:.1f}, or the interval "
            "reaches zero)"
        )
    typer.echo(
        f"moving mass {out['moving_mass_kg']:g} kg (--moving-mass-kg): k and c scale with it; "
        + out["intervals"].removeprefix("95 %: ")
    )
    cpms = sorted({round(p["counts_per_m"], 1) for p in out["per_log"]})
    typer.echo(
        "k and c come from frequency and decay and do not depend on the sensor's counts per metre; F_c "
        f"does (it scales with it: {', '.join(f'{c:g}' for c in cpms)} counts/m)"
    )
    for p in out["per_log"]:
        typer.echo(
            f"  {p['file']}: {p['samples']} samples, {p['half_cycles']} half cycles, release delay "
            f"{p['release_delay_ms']:.1f} ms, residual RMS {p['residual_rms_counts']:.2f} counts"
        )
    seg = out["segmentation"]
    others = [c for c in seg["candidates"] if c["half_cycles"] != seg["chosen"]]
    typer.echo(
        f"half cycles chosen by the data: {', '.join(map(str, seg['chosen']))} (per log)"
        + (
            "; also tried: "
            + ", ".join(
                f"{'/'.join(map(str, c['half_cycles']))} (delta chi2 {c['delta_chi2']:.1f}, "
                f"{'plausible: the intervals span it' if c['plausible'] else 'rejected'})"
                for c in others
            )
            if others
            else ""
        )
    )
    if "one_release" in out:
        typer.echo(out["one_release"])
    g = out["goal"]

    def width(key: str, name: str) -> str:
        pp = g["per_parameter"][key]
        if pp["rel_half_width"] is None:
            return f"{name} consistent with zero (< {pp['upper_95']:.3g})"
        return f"{name} ±{pp['rel_half_width']:.1%}"

    widths = ", ".join(
        width(key, name) for key, name in (("k_n_per_m", "k"), ("c_n_s_per_m", "c"), ("guide_friction_n", "F_c"))
    )
    n = g["releases"]
    if g["met"]:
        typer.echo(f"precision goal (95 %: k and c within 2 %, F_c within 10 %) met with {n} release(s): {widths}")
    else:
        short = [
            name
            for key, name in (("k_n_per_m", "k"), ("c_n_s_per_m", "c"), ("guide_friction_n", "F_c"))
            if g["per_parameter"][key]["met"] is False
        ]
        more = (
            f"; about {g['releases_needed']} releases like these would reach it (fewer if they differ in compression)"
            if g["releases_needed"] is not None
            else ""
        )
        typer.echo(
            f"warning: precision goal (95 %: k and c within 2 %, F_c within 10 %) NOT met by "
            f"{', '.join(short)} with {n} release(s): {widths}{more}"
        )
    opt = out["optimizer"]
    typer.echo(
        ("fit converged" if out["converged"] else "fit did NOT converge (stopped on its budget)")
        + f": {opt['message']} ({opt['nfev']} evaluations); residual RMS {out['residual_rms_counts']:.2f} "
        f"counts, lag-1 autocorrelation {out['residual_lag1_autocorrelation']:.2f}; count drift "
        f"{out['count_drift_counts_per_sqrt_s']:.2f} counts/sqrt(s) (where the leg is still)"
    )
    if "fake_truth" in out:
        t = out["fake_truth"]
        typer.echo(
            f"fake leg's truth: k = {t['k_n_per_m']:g} N/m, c = {t['c_n_s_per_m']:g} N s/m, F_c = "
            f"{t['guide_friction_n']:g} N, moving mass {t['moving_mass_kg']:g} kg"
        )
    if plot is not None:
        typer.echo(f"figure: {plot}")


def leg_fit_coverage_cmd(
    tests: Annotated[
        int,
        typer.Option("--tests", min=1, max=100000, metavar="N", help="Simulated leg tests to fit (a random leg each)."),
    ] = 100,
    releases: Annotated[
        int,
        typer.Option(
            "--releases",
            min=1,
            max=20,
            metavar="N",
            help="Releases per leg test (compressions spread over 1.5-2.5 mm).",
        ),
    ] = 3,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Random seed (the same seed gives the same figures).")] = 0,
    noise_counts: Annotated[
        float,
        typer.Option(
            "--noise-counts",
            min=0.0,
            max=100.0,
            metavar="COUNTS",
            help="Position noise of the sensor (1 sigma, before rounding).",
        ),
    ] = 0.3,
    drift_counts_per_sqrt_s: Annotated[
        float,
        typer.Option(
            "--drift-counts-per-sqrt-s",
            min=0.0,
            max=100.0,
            metavar="RATE",
            help="Random-walk drift of the count (its sd after 1 s).",
        ),
    ] = 0.5,
    mass_sd_rel: Annotated[
        float,
        typer.Option(
            "--mass-sd-rel",
            min=0.0,
            max=0.5,
            metavar="SHARE",
            help="How well the leg's moving mass is known: the fit is told the truth off by this share (1 sigma) "
            "with this uncertainty (0: the true mass, a study of the fit alone).",
        ),
    ] = 0.005,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """How often the 95 % intervals of `trials leg-fit` contain the truth, on simulated leg tests.

    Each test: k, c, guide friction and moving mass drawn at random (2000-3500 N/m, 4-10 N s/m, 0.1-0.5 N,
    30-46 g; the fit is told the mass as weighed, --mass-sd-rel off, never the truth), released
    --releases times and recorded by an independent truth model (stiction, noise, count drift, rounding, read
    jitter and late reads, unknown release delay), then fitted like a robot's logs; about a second a test.
    """
    from rimless.analysis.validation.leg_fit_coverage import run_leg_fit_coverage
    from rimless.progress import progress_bar

    with progress_bar("leg-fit coverage", total=tests, json_out=json_out) as bar:
        res = run_leg_fit_coverage(
            tests,
            releases=releases,
            seed=seed,
            noise_counts=noise_counts,
            drift_counts_per_sqrt_s=drift_counts_per_sqrt_s,
            mass_rel_sd=mass_sd_rel,
            progress=lambda i: bar.update(completed=i, description=f"test {i}/{tests}"),
        )
    out = res.summary()
    if json_out:
        print_json(out)
        return
    typer.echo(
        f"{out['fitted']} of {out['tests']} simulated leg tests fitted ({out['releases']} release(s) each, "
        f"seed {out['seed']}; noise {noise_counts:g} counts, drift {drift_counts_per_sqrt_s:g} counts/sqrt(s))"
    )
    typer.echo(f"moving mass 30-46 g, told to the fit as {out['truth_model']['stated_moving_mass']}")
    for key, label in (("k_n_per_m", "k  "), ("c_n_s_per_m", "c  "), ("guide_friction_n", "F_c")):
        d = out["per_parameter"][key]
        if not d["fitted"]:
            continue
        lo, hi = d["coverage_ci95"]
        typer.echo(
            f"{label}: 95 % interval holds the truth in {d['covered']}/{d['fitted']} = {d['coverage']:.1%} "
            f"(binomial 95 %: {lo:.1%}-{hi:.1%}; goal 90-98 %); error median {d['median_abs_rel_error']:.2%}, "
            f"RMS {d['rms_rel_error']:.2%}; half width median {d['median_rel_half_width']:.2%}; "
            f"sd of error/se {d['z_sd']:.2f}"
        )
    g = out["goal"]
    typer.echo(
        f"precision goal (95 % half width: k and c 2 %, F_c 10 %) met in {g['tests_meeting_goal']} of "
        f"{out['fitted']} tests"
    )
    if out["failures"]:
        typer.echo(f"{out['failures']} test(s) gave no fit (classified failures), e.g.: {out['failure_messages'][0]}")
