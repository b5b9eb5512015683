"""What `rimless sim gait --clutch firmware` (its `--bench` and `--critical-slope`) and `rimless sim sweep
--clutch firmware` print. The work is in rimless.sim.in_the_loop (firmware_gait, sweep)."""

import os
from pathlib import Path
from typing import Any

from rimless.cli_rules import print_json
from rimless.progress import progress_bar
from rimless.sim.cli.output import console, table

# kept importable from here for scripts written against the former module
from rimless.sim.in_the_loop.config import build_config  # noqa: F401
from rimless.sim.in_the_loop.ideal import ideal_fixed_point  # noqa: F401


def run_gait(params: Any, config: Any, *, steps: int, backend: str, rtol: float, json_out: bool) -> None:
    """The `--clutch firmware` gait: walk, fitted fixed point and energy against the ideal clutch."""
    from rimless.sim.in_the_loop.firmware_gait import firmware_gait

    with progress_bar(f"firmware in the loop at {config.rate_hz:g} Hz", steps, json_out=json_out) as bar:
        out = firmware_gait(params, config, steps=steps, backend=backend, rtol=rtol, progress=bar.update)
    if json_out:
        print_json(out)
        return
    steps_done = out["steps_done"]
    i, f = out["ideal"], out["fixed_point"]
    eig = ", ".join(f"{abs(complex(re, im)):.3f}" for re, im in f["eigenvalues_fitted"] if re is not None) or "-"
    e = out["energy_per_step_mean_J"]

    def num(v: Any, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    rows = [
        (
            "sampling / delays",
            f"{config.rate_hz:g} Hz, engage {out['engage_delay_ms']:g} ms, release {out['release_delay_ms']:g} ms",
        ),
        ("sensor noise / jitter", f"{config.noise_counts:g} counts, {out['jitter_ms']:g} ms"),
        ("clutch holding force (N)", num(out["holding_force_N"], "g") if out["holding_force_N"] else "rigid"),
        ("steps", f"{steps_done} of {steps}"),
        ("theta+ ideal / firmware (rad)", f"{i['theta_plus_rad']:.5f} / {num(f['theta_plus_rad'], '.5f')}"),
        (
            "theta'+ ideal / firmware (rad/s)",
            f"{i['theta_dot_plus_rad_s']:.4f} / {num(f['theta_dot_plus_rad_s'], '.4f')}",
        ),
        (
            "step period ideal / firmware (s)",
            f"{i['step_period_s']:.4f} / {f['step_period_s']:.4f} (sd {f['step_period_std_s']:.1e})",
        ),
        ("|eigenvalues| ideal / fitted", f"{i['max_abs_eigenvalue']:.3f} / {eig}"),
        ("stored energy ideal / firmware (J)", f"{i['stored_energy_J']:.4f} / {f['stored_energy_J']:.4f}"),
        ("locks (class: steps)", ", ".join(f"{k}: {v}" for k, v in out["lock_classes"].items()) or "-"),
        ("release after touchdown (ms)", num(out["release_lateness_mean_ms"], ".3f")),
        (
            "losses/step damper, clutch, foot-a, impact (J)",
            ", ".join(num(e[k], ".4f") for k in ("damper_J", "clutch_loss_J", "recontact_loss_J", "impact_loss_J")),
        ),
        ("energy budget residual max (J)", num(out["energy_residual_max_J"], ".1e")),
        ("firmware faults", ", ".join(out["firmware_faults"]) or "none"),
    ]
    con = console()
    con.print(table("ER gait, firmware in the loop", rows))
    if not (f["eigenvalues_fitted"] and f["eigenvalues_fitted"][0][0] is None):
        con.print(
            "fixed point: fitted to the walk (z_{k+1} = A z_k + c, z* = (I - A)^-1 c); eigenvalues are those "
            "of A. Stored energy: the stance spring's energy held at touchdown."
        )
    else:
        why = (
            f"the walk of {steps_done} steps is too short to fit the map (it takes 6 steps or more)"
            if steps_done < 6
            else "the map could not be fitted to the walk"
        )
        con.print(
            f"{why}: the fixed point is the mean of the last {f['n_average']} section points, the eigenvalues "
            "are not fitted"
        )
    if out["failure"] is not None:
        con.print(f"[yellow]the walk ended early: {out['failure']['message']}[/yellow]")


def run_bench(
    params: Any, *, rates_hz: tuple[float, ...] = (300.0, 1000.0), steps: int = 3, json_out: bool = False
) -> dict[str, Any]:
    """`--bench`: simulated steps per second with the firmware in the loop beside the ideal clutch."""
    from rimless.sim.in_the_loop.firmware_gait import firmware_bench

    out = firmware_bench(params, rates_hz=rates_hz, steps=steps)
    rows = out["rows"]
    if json_out:
        print_json(out)
    else:
        print(
            f"{'rate_hz':>7} {'sensors':>7} {'steps/s':>7} {'samples/step':>12} {'ideal steps/s':>13} "
            f"{'slowdown':>8} {'|dz| step 1':>11}"
        )
        for r in rows:
            print(
                f"{r['rate_hz']:>7g} {r['sensors']:>7} {r['steps_per_s']:>7.2f} {r['samples_per_step']:>12.0f} "
                f"{r['reference_ideal_steps_per_s']:>13.2f} {r['slowdown_vs_ideal']:>8.1f} "
                f"{r['first_step_section_difference']:>11.2e}"
            )
        print(
            "firmware: Controller + LegDetector + Adns3080 driver over the FakeAdns3080 bus, defaults "
            "(5 ms delays, 1 count noise; sensors: one counting the legs, or one per leg); ideal: reference "
            "path (scipy DOP853, rtol 1e-9), same start."
        )
        print(f"load average {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return out


def run_critical(params: Any, config: Any, *, steps: int, low_deg: float, tol_deg: float, json_out: bool) -> None:
    """`--critical-slope`: the lowest slope at which the firmware keeps the wheel walking."""
    from rimless.sim.in_the_loop.firmware_gait import critical_bisections, firmware_critical

    total = critical_bisections(params, low_deg, tol_deg) if low_deg < params.slope_deg else None
    with progress_bar("bisecting the slope (a walk per slope)", total, json_out=json_out) as bar:
        out = firmware_critical(params, config, steps=steps, low_deg=low_deg, tol_deg=tol_deg, progress=bar.update)
    if json_out:
        print_json(out)
        return
    mech = out["mechanical_critical_slope_deg"]
    con = console()
    con.print(
        table(
            "critical slope, firmware in the loop",
            [
                (
                    "sampling / delays",
                    f"{config.rate_hz:g} Hz, engage {out['engage_delay_ms']:g} ms, release "
                    f"{out['release_delay_ms']:g} ms",
                ),
                ("critical slope, as configured (deg)", f"{out['critical_slope_deg']:.3f}"),
                ("fails at (deg)", f"{out['failing_slope_deg']:.3f}"),
                ("limited by", out["limited_by"]),
                ("mechanical boundary (deg)", "-" if mech is None else f"{mech:.3f}"),
                ("walk length (steps)", str(steps)),
            ],
        )
    )
    con.print(f"definition: {out['definition']}")
    con.print(f"what limits it: {out['limit_detail']}")
    if out["mechanical"] is not None:
        con.print(f"mechanical boundary: {out['mechanical']['definition']}")


def run_sweep_command(params: Any, *, out: Path, scheduler: str, json_out: bool, **options: Any) -> None:
    """`rimless sim sweep --clutch firmware`: the grid (rimless.sim.in_the_loop.sweep.firmware_sweep_table)
    and its table, the files written and the run's counts."""
    from rimless.sim.in_the_loop.sweep import firmware_sweep_table

    with progress_bar("firmware sweep", json_out=json_out) as bar:
        summary = firmware_sweep_table(
            params, out=out, scheduler=scheduler, progress=lambda i, t: bar.update(i, t), **options
        )
    if json_out:
        print_json(summary)
        return
    print_firmware_rows(summary)
    grid = summary["grid"]
    n = len(grid["rate_hz"]) * len(grid["delay_ms"]) + (2 if options.get("critical_slope") else 0)
    con = console()
    for p in summary["files"] + ([summary["plot"]] if summary["plot"] else []):
        con.print(f"wrote {p}", soft_wrap=True)
    con.print(
        f"{n} grid points ({summary['computed']} computed, {summary['cached']} from the cache) in "
        f"{summary['seconds']:.1f} s on {summary['workers']} worker(s), scheduler {scheduler}"
    )


def print_firmware_rows(out: dict[str, Any]) -> None:
    """The firmware sweep's table (80 columns); references and reasons under it."""
    i = out["ideal"]
    print(
        f"ideal clutch: theta'+ {i['theta_dot_plus_rad_s']:.4f} rad/s, period {i['step_period_s']:.4f} s, "
        f"stored {i['stored_energy_J']:.4f} J, max |eig| {i.get('max_abs_eigenvalue', float('nan')):.3f}"
    )
    for name, r in (out.get("references") or {}).items():
        crit = r.get("critical_slope_deg")
        print(
            f"{'ideal ER' if name == 'er_ideal' else 'VE, ' + str(r.get('branch_label')) + ' gait'}: critical slope "
            f"{'-' if crit is None else f'{crit:.3f}'} deg, CoT {r.get('cot') or float('nan'):.4f}"
        )
    refs = out.get("references") or {}
    if refs and refs["er_ideal"].get("cot_saving_vs_ve") is not None and refs["er_ideal"]["cot_saving_vs_ve"] <= 1e-3:
        print(
            f"the ideal ER wheel saves {100 * refs['er_ideal']['cot_saving_vs_ve']:.2f} % CoT over this VE gait: "
            "no advantage to keep a share of (ER adv '-'); the paper's comparison is the VE fast gait (--k 2500)"
        )
    crit_cols = any("critical_slope_deg" in r for r in out["rows"] if r.get("clutch") == "firmware")
    head = f"{'rate_hz':>7} {'delay_ms':>8} {'walks':>5} {'period_s':>8} {'speed':>6} {'stored':>6} {'|eig|':>6}"
    print(head + (f" {'phi_c deg':>9} {'ER adv':>6} {'limit':>9}" if crit_cols else ""))
    notes = []
    for r in out["rows"]:
        if r.get("clutch") != "firmware":
            continue
        if not r.get("steps_done"):
            line = f"{r['rate_hz']:>7g} {r['delay_ms']:>8g} {'no':>5} {'-':>8} {'-':>6} {'-':>6} {'-':>6}"
            notes.append(f"{r['rate_hz']:g} Hz, {r['delay_ms']:g} ms: {r.get('failure')}: {r.get('detail')}")
        else:
            eig = r.get("max_abs_eigenvalue_fitted")
            line = (
                f"{r['rate_hz']:>7g} {r['delay_ms']:>8g} {'yes' if r['walks'] else 'no':>5} "
                f"{r['step_period_s']:>8.4f} {r['speed_ratio']:>6.3f} {r['stored_energy_ratio']:>6.3f} "
                f"{'-' if eig is None else f'{eig:.3f}':>6}"
            )
            if not r["walks"]:
                notes.append(f"{r['rate_hz']:g} Hz, {r['delay_ms']:g} ms: {r.get('failure')} {r.get('detail') or ''}")
        if crit_cols:
            crit, adv = r.get("critical_slope_deg"), r.get("er_advantage_remaining")
            line += (
                f" {'-' if crit is None else f'{crit:.3f}':>9} {'-' if adv is None else f'{adv:.2f}':>6} "
                f"{str(r.get('limited_by', '-'))[:9]:>9}"
            )
            mech = r.get("mechanical_critical_slope_deg")
            if r.get("limited_by") == "firmware":
                notes.append(
                    f"{r['rate_hz']:g} Hz, {r['delay_ms']:g} ms: the firmware's fault limits the slope; "
                    f"mechanical boundary {'-' if mech is None else f'{mech:.3f}'} deg"
                )
        print(line)
    print(
        "speed, stored: fractions of the ideal clutch's walking speed and stored energy (spring energy held at "
        "touchdown); |eig|: fitted to the walk. ER adv: share of the ideal ER's CoT saving over VE kept."
    )
    for n in notes:
        print(n)
