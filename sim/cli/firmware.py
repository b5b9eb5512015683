"""`rimless sim gait --clutch firmware`: the gait, fixed point and energy under the robot's own controller,
and its benchmark (`--bench`). Called from rimless.sim.cli; the work is in rimless.sim.in_the_loop.loop."""

from __future__ import annotations

import math
import time
from collections import Counter
from typing import Any

import numpy as np

from rimless.errors import ParameterError


def build_config(*, rate_hz: float | None, clutch_delay_ms: float, release_delay_ms: float | None,
                 noise_counts: float, jitter_ms: float, holding_force_n: float, seed: int,
                 robot_config: Any = None) -> Any:
    """FirmwareLoopConfig from the CLI options; errors name the option.

    robot_config: a robot.toml (read by the firmware's own loader) supplying the detector parameters, the
    first sensor's resolution, calibration and health limits, the clutch timeout, whether there is one sensor
    or one per leg, and the sampling rate unless --rate-hz is given."""
    from rimless.firmware.control.faults import HealthLimits
    from rimless.sim.in_the_loop.loop import FirmwareLoopConfig

    extra: dict[str, Any] = {}
    if robot_config is not None:
        from rimless.firmware.service.config import load_config

        robot = load_config(robot_config)
        sensor = robot.sensors[0]
        if len(robot.sensors) == 1:
            sensors = "one"
        elif len(robot.sensors) == 8 and sorted(leg for s in robot.sensors for leg in s.legs) == list(range(8)) \
                and all(len(s.legs) == 1 for s in robot.sensors):
            sensors = "per-leg"
        else:
            raise ParameterError(f"--robot-config {robot_config}: the loop models one sensor counting the legs or "
                                 f"one sensor per leg (legs 0..7), not {len(robot.sensors)} sensors on "
                                 f"{[list(s.legs) for s in robot.sensors]}")
        cpm_1600 = sensor.counts_per_m * (1.0 if sensor.resolution_cpi == 1600 else 4.0)
        extra = {"detector": robot.detector, "cpi": sensor.resolution_cpi, "counts_per_m_1600": cpm_1600,
                 "health": HealthLimits(sensor.squal_min, sensor.squal_low_s, sensor.saturated_samples_max),
                 "max_hold_s": robot.clutch.max_hold_s, "sensors": sensors}
        if rate_hz is None:
            rate_hz = robot.sampling.rate_hz
    if rate_hz is None:
        rate_hz = 300.0

    checks = [
        ("--rate-hz", rate_hz, 1.0 <= rate_hz <= 1e6, "a sampling rate in [1, 1e6] Hz"),
        ("--clutch-delay-ms", clutch_delay_ms, 0.0 <= clutch_delay_ms <= 1000.0, "a delay in [0, 1000] ms"),
        ("--noise-counts", noise_counts, 0.0 <= noise_counts <= 1000.0, "a noise level in [0, 1000] counts"),
        ("--jitter-ms", jitter_ms, 0.0 <= jitter_ms <= 100.0, "a jitter in [0, 100] ms"),
        ("--holding-force-n", holding_force_n, holding_force_n > 0.0, "a force > 0 N (inf: a rigid clutch)"),
    ]
    if release_delay_ms is not None:
        checks.append(("--release-delay-ms", release_delay_ms, 0.0 <= release_delay_ms <= 1000.0,
                       "a delay in [0, 1000] ms"))
    for flag, value, ok, what in checks:
        if value != value or not ok:
            raise ParameterError(f"{flag} must be {what}, got {value}")
    release = clutch_delay_ms if release_delay_ms is None else release_delay_ms
    return FirmwareLoopConfig(rate_hz=rate_hz, jitter_s=jitter_ms * 1e-3, noise_counts=noise_counts,
                              engage_delay_s=clutch_delay_ms * 1e-3, release_delay_s=release * 1e-3,
                              holding_force_N=holding_force_n, seed=seed, **extra).validated()


def ideal_fixed_point(params: Any, *, backend: str, rtol: float) -> Any:
    """The ideal-clutch ER fixed point (the start of every firmware walk)."""
    from rimless.sim.integrate.backend import jacobian_factory, make_map
    from rimless.sim.step.poincare import default_guess, solve_fixed_point

    pmap = make_map(params, "er", backend=backend, rtol=rtol)
    jf = jacobian_factory(backend)
    return solve_fixed_point(pmap, default_guess(params, "er"), jacobian=jf(pmap) if jf else None)


def _f(x: Any) -> Any:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def firmware_summary(params: Any, config: Any, ideal: Any, fp: Any) -> dict[str, Any]:
    """JSON-able summary of a firmware walk and its fixed point against the ideal clutch."""
    walk = fp.walk
    ideal_stored = 0.5 * params.k * (params.leg_length_m - float(ideal.step.y_minus[3])) ** 2
    steps = walk.steps
    classes = Counter(s.lock_class for s in steps)
    late = [s.release_lateness_s for s in steps if s.release_lateness_s is not None]
    faults = [f.get("fault") for _, name, f in walk.events if name == "fault"]
    return {
        "clutch": "firmware",
        "model": "er",
        "slope_rad": params.slope_rad,
        "rate_hz": config.rate_hz,
        "engage_delay_ms": config.engage_delay_s * 1e3,
        "release_delay_ms": config.release_delay_s * 1e3,
        "noise_counts": config.noise_counts,
        "jitter_ms": config.jitter_s * 1e3,
        "holding_force_N": config.holding_force_N if math.isfinite(config.holding_force_N) else None,
        "cpi": config.cpi,
        "sensors": config.sensors,
        "seed": config.seed,
        "steps_done": len(steps),
        "ideal": {
            "theta_plus_rad": float(ideal.z[0]), "theta_dot_plus_rad_s": float(ideal.z[1]),
            "step_period_s": float(ideal.step.period_s), "stored_energy_J": ideal_stored,
            "max_abs_eigenvalue": float(np.max(np.abs(ideal.eigenvalues))),
        },
        "fixed_point": {
            "method": "linear fit z_{k+1} = A z_k + c to the walk's section points, z* = (I - A)^-1 c",
            "theta_plus_rad": _f(fp.z[0]), "theta_dot_plus_rad_s": _f(fp.z[1]),
            "mean_last_rad_rad_s": [_f(v) for v in fp.z_mean], "std_last_rad_rad_s": [_f(v) for v in fp.z_std],
            "n_average": fp.n_average,
            "eigenvalues_fitted": [[_f(e.real), _f(e.imag)] for e in fp.eigenvalues],
            "stable_fitted": fp.stable,
            "fit_residual": _f(fp.fit_residual),
            "step_period_s": fp.period_s, "step_period_std_s": fp.period_std_s,
            "stored_energy_J": fp.stored_energy_J,
            "stored_energy_ratio_to_ideal": fp.stored_energy_J / ideal_stored if ideal_stored > 0 else None,
        },
        "lock_classes": dict(classes),
        "release_lateness_mean_ms": float(np.mean(late)) * 1e3 if late else None,
        "energy_per_step_mean_J": {
            key: float(np.mean([getattr(s, key) for s in steps])) if steps else None
            for key in ("stored_energy_J", "damper_J", "clutch_loss_J", "recontact_loss_J", "impact_loss_J")
        },
        "energy_residual_max_J": max((abs(s.energy_residual_J) for s in steps), default=None),
        "firmware_faults": faults,
        "failure": None if walk.failure is None else {"reason": walk.failure.reason.value,
                                                      "message": str(walk.failure)},
        "steps": [s.to_dict() for s in steps],
    }


def run_gait(params: Any, config: Any, *, steps: int, backend: str, rtol: float, json_out: bool,
             out_json: Any = None) -> int:
    """The `--clutch firmware` gait command; returns the exit code."""
    from rich.progress import Progress

    from rimless.cli import print_json
    from rimless.sim.cli import _console, _err_console, _table
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.in_the_loop.loop import firmware_fixed_point
    from rimless.sim.step.poincare import NoFixedPoint

    try:
        ideal = ideal_fixed_point(params, backend=backend, rtol=rtol)
    except (StepFailure, NoFixedPoint) as err:
        import typer

        typer.echo(f"error: no ideal-clutch ER gait to start the firmware walk from at {params.slope_deg:.4f} deg: "
                   f"{err}", err=True)
        return 1
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task(f"firmware in the loop at {config.rate_hz:g} Hz", total=steps)
        try:
            fp = firmware_fixed_point(params, config, ideal.z, steps=steps, n_average=min(4, steps),
                                      progress=lambda k: prog.update(task, completed=k))
        except StepFailure as err:
            import typer

            typer.echo(f"error: the walk under the firmware failed within its first steps: {err}", err=True)
            return 1
    out = firmware_summary(params, config, ideal, fp)
    if json_out:
        print_json(out)
        return 0
    i, f = out["ideal"], out["fixed_point"]
    eig = ", ".join(f"{abs(complex(re, im)):.3f}" for re, im in f["eigenvalues_fitted"] if re is not None) or "-"
    e = out["energy_per_step_mean_J"]

    def num(v: Any, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    rows = [
        ("sampling / delays", f"{config.rate_hz:g} Hz, engage {out['engage_delay_ms']:g} ms, release "
                              f"{out['release_delay_ms']:g} ms"),
        ("sensor noise / jitter", f"{config.noise_counts:g} counts, {out['jitter_ms']:g} ms"),
        ("clutch holding force (N)", num(out["holding_force_N"], "g") if out["holding_force_N"] else "rigid"),
        ("steps", f"{len(fp.walk.steps)} of {steps}"),
        ("theta+ ideal / firmware (rad)", f"{i['theta_plus_rad']:.5f} / {num(f['theta_plus_rad'], '.5f')}"),
        ("theta'+ ideal / firmware (rad/s)", f"{i['theta_dot_plus_rad_s']:.4f} / "
                                             f"{num(f['theta_dot_plus_rad_s'], '.4f')}"),
        ("step period ideal / firmware (s)", f"{i['step_period_s']:.4f} / {f['step_period_s']:.4f} "
                                             f"(sd {f['step_period_std_s']:.1e})"),
        ("|eigenvalues| ideal / fitted", f"{i['max_abs_eigenvalue']:.3f} / {eig}"),
        ("stored energy ideal / firmware (J)", f"{i['stored_energy_J']:.4f} / {f['stored_energy_J']:.4f}"),
        ("locks (class: steps)", ", ".join(f"{k}: {v}" for k, v in out["lock_classes"].items()) or "-"),
        ("release after touchdown (ms)", num(out["release_lateness_mean_ms"], ".3f")),
        ("losses/step damper, clutch, foot-a, impact (J)",
         ", ".join(num(e[k], ".4f") for k in ("damper_J", "clutch_loss_J", "recontact_loss_J", "impact_loss_J"))),
        ("energy budget residual max (J)", num(out["energy_residual_max_J"], ".1e")),
        ("firmware faults", ", ".join(out["firmware_faults"]) or "none"),
    ]
    con = _console()
    con.print(_table("ER gait, firmware in the loop", rows))
    con.print("fixed point: fitted to the walk (z_{k+1} = A z_k + c, z* = (I - A)^-1 c); eigenvalues are those "
              "of A. Stored energy: the stance spring's energy held at touchdown.", soft_wrap=True)
    if fp.walk.failure is not None:
        con.print(f"[yellow]the walk ended early: {fp.walk.failure}[/yellow]")
    return 0


def run_bench(params: Any, *, rates_hz: tuple[float, ...] = (300.0, 1000.0), steps: int = 3, json_out: bool = False
              ) -> dict[str, Any]:
    """Simulated steps per second with the firmware in the loop, beside the ideal clutch on the reference
    path (same start, same integrator family), and the difference of their section points."""
    from rimless.cli import print_json
    from rimless.sim.in_the_loop.loop import FirmwareLoop, FirmwareLoopConfig
    from rimless.sim.step.hybrid import simulate_step
    from rimless.sim.integrate.reference import ScipyIntegrator
    from rimless.sim.model.mechanics import Mechanics
    from rimless.sim.model.section import state_from_section

    ideal = ideal_fixed_point(params, backend="reference", rtol=1e-9)
    mech = Mechanics.of(params)
    t = time.perf_counter()
    y = state_from_section(mech, ideal.z)
    for _ in range(steps):
        y = simulate_step(mech, "er", y, ScipyIntegrator(rtol=1e-9, atol=1e-11)).y_plus
    ref_s = (time.perf_counter() - t) / steps
    rows = []
    for rate, sensors in [(r, "one") for r in rates_hz] + [(rates_hz[0], "per-leg")]:
        loop = FirmwareLoop(params, FirmwareLoopConfig(rate_hz=rate, sensors=sensors))
        t = time.perf_counter()
        walk = loop.walk(ideal.z, steps)
        el = time.perf_counter() - t
        loop.close()
        done = max(len(walk.steps), 1)
        per_step = el / (done + 1)  # the priming step is simulated and sampled as well
        z_err = float(np.max(np.abs(walk.steps[0].z_end - ideal.z))) if walk.steps else float("nan")
        rows.append({"rate_hz": rate, "sensors": sensors, "steps": len(walk.steps), "steps_per_s": 1.0 / per_step,
                     "samples_per_step": walk.samples / (done + 1),
                     "reference_ideal_steps_per_s": 1.0 / ref_s, "slowdown_vs_ideal": per_step / ref_s,
                     "first_step_section_difference": z_err})
    import os

    out = {"benchmark": "firmware-in-the-loop", "steps": steps, "rows": rows, "load_average": list(os.getloadavg())}
    if json_out:
        print_json(out)
    else:
        print(f"{'rate_hz':>7} {'sensors':>7} {'steps/s':>7} {'samples/step':>12} {'ideal steps/s':>13} "
              f"{'slowdown':>8} {'|dz| step 1':>11}")
        for r in rows:
            print(f"{r['rate_hz']:>7g} {r['sensors']:>7} {r['steps_per_s']:>7.2f} {r['samples_per_step']:>12.0f} "
                  f"{r['reference_ideal_steps_per_s']:>13.2f} {r['slowdown_vs_ideal']:>8.1f} "
                  f"{r['first_step_section_difference']:>11.2e}")
        print("firmware: Controller + LegDetector + Adns3080 driver over the FakeAdns3080 bus, defaults "
              "(5 ms delays, 1 count noise; sensors: one counting the legs, or one per leg); ideal: reference "
              "path (scipy DOP853, rtol 1e-9), same start.")
        import os

        print(f"load average {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return out


def run_critical(params: Any, config: Any, *, steps: int, low_deg: float, tol_deg: float, json_out: bool) -> int:
    """`--critical-slope`: the lowest slope at which the firmware keeps the wheel walking; returns the exit code."""
    import typer
    from rich.progress import Progress

    from rimless.cli import print_json
    from rimless.sim.cli import _console, _err_console, _table
    from rimless.sim.in_the_loop.loop import firmware_boundaries

    if not (math.isfinite(low_deg) and 0.0 <= low_deg < params.slope_deg):
        raise ParameterError(f"--critical-low-deg must be in [0, the slope {params.slope_deg:g} deg), got {low_deg}")
    n_max = 2 * (2 + max(1, math.ceil(math.log2(max((params.slope_deg - low_deg) / tol_deg, 1.0)))))
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task("bisecting the slope (a walk per slope)", total=n_max)
        try:
            res = firmware_boundaries(params, config, low_rad=math.radians(low_deg), steps=steps,
                                      tol_rad=math.radians(tol_deg), progress=lambda k: prog.update(task, completed=k))
        except ValueError as err:
            typer.echo(f"error: {err}", err=True)
            return 1
    out = critical_summary(res, config, steps=steps, tol_deg=tol_deg)
    if json_out:
        print_json(out)
        return 0
    mech = out["mechanical_critical_slope_deg"]
    con = _console()
    con.print(_table("critical slope, firmware in the loop", [
        ("sampling / delays", f"{config.rate_hz:g} Hz, engage {out['engage_delay_ms']:g} ms, release "
                              f"{out['release_delay_ms']:g} ms"),
        ("critical slope, as configured (deg)", f"{out['critical_slope_deg']:.3f}"),
        ("fails at (deg)", f"{out['failing_slope_deg']:.3f}"),
        ("limited by", out["limited_by"]),
        ("mechanical boundary (deg)", "-" if mech is None else f"{mech:.3f}"),
        ("walk length (steps)", str(steps)),
    ]))
    con.print(f"definition: {out['definition']}", soft_wrap=True)
    con.print(f"what limits it: {out['limit_detail']}", soft_wrap=True)
    if out["mechanical"] is not None:
        con.print(f"mechanical boundary: {out['mechanical']['definition']}", soft_wrap=True)
    return 0


def critical_summary(res: Any, config: Any, *, steps: int, tol_deg: float) -> dict[str, Any]:
    """JSON-able summary of `firmware_boundaries`: both boundaries and which one limits the wheel."""
    from rimless.sim.in_the_loop.loop import MECHANICAL_WALK_FACTOR

    fw, mech = res.firmware, res.mechanical

    def evals(r: Any) -> list[dict[str, Any]]:
        return [{"slope_deg": math.degrees(s), "walks": ok, "reason": why} for s, ok, why in r.evaluations]

    mech_deg = math.degrees(res.mechanical_slope_rad)
    return {
        "clutch": "firmware", "rate_hz": config.rate_hz, "engage_delay_ms": config.engage_delay_s * 1e3,
        "release_delay_ms": config.release_delay_s * 1e3, "noise_counts": config.noise_counts,
        "definition": f"lowest slope at which a walk of {steps} steps from the ideal-clutch gait completes with no "
                      "failed step and no firmware fault (bisection; one boundary assumed)",
        "critical_slope_deg": math.degrees(fw.critical_slope_rad),
        "failing_slope_deg": math.degrees(fw.failing_slope_rad),
        "tolerance_deg": tol_deg,
        "reason_below": fw.reason_below,
        "limited_by": res.limited_by,
        "limit_detail": res.detail,
        "firmware_fault_below": fw.limited_by == "firmware",
        "mechanical_critical_slope_deg": mech_deg if math.isfinite(mech_deg) else None,
        "mechanical": None if mech is None else {
            "definition": f"the firmware's step-timing fail-safes relaxed (max_step_s 10 s, step_period_tolerance "
                          f"0.9, max_hold_s 60 s) so that a walk ends only by the mechanics, walks "
                          f"{MECHANICAL_WALK_FACTOR * steps} steps long: first at the failing slope, then bisected "
                          "below it if the wheel walks there",
            "critical_slope_deg": mech_deg if math.isfinite(mech_deg) else None,
            "failing_slope_deg": math.degrees(mech.failing_slope_rad),
            "reason_below": mech.reason_below, "evaluations": evals(mech)},
        "evaluations": evals(fw),
    }


def run_sweep_command(params: Any, *, rate_hz: str | None, clutch_delay_ms: str | None, noise_counts: float | None,
                      steps: int, seed: int, critical_slope: bool, critical_low_deg: float, out: Any,
                      scheduler: str, workers: int | None, cache_dir: Any, plot: Any, json_out: bool) -> None:
    """`rimless sim sweep --clutch firmware`: the firmware in the loop over rate x delay, on Dask with the
    sweep's cache, written as STEM.parquet/.csv, with the designer's figure (`plot_firmware_sweep`)."""
    from rich.progress import Progress

    from rimless.cli import print_json
    from rimless.output import check_output_folder, writable_dir
    from rimless.sim.cli import _console, _err_console
    from rimless.sim.in_the_loop.sweep import FirmwareSweepOptions, plot_firmware_sweep, run_firmware_grid
    from rimless.sim.studies.sweep import parse_range, write_table

    rates = parse_range(rate_hz or "300,1000", "--rate-hz")
    delays = parse_range(clutch_delay_ms or "0:10:2.5", "--clutch-delay-ms")
    if any(not 1.0 <= r <= 1e6 for r in rates):
        raise ParameterError(f"--rate-hz must be rates in [1, 1e6] Hz, got {rate_hz!r}")
    if any(not 0.0 <= d <= 1000.0 for d in delays):
        raise ParameterError(f"--clutch-delay-ms must be delays in [0, 1000] ms, got {clutch_delay_ms!r}")
    noise = 1.0 if noise_counts is None else noise_counts
    if not (noise == noise and 0.0 <= noise <= 1000.0):
        raise ParameterError(f"--noise-counts must be a noise level in [0, 1000] counts, got {noise}")
    if not (math.isfinite(critical_low_deg) and 0.0 <= critical_low_deg < params.slope_deg):
        raise ParameterError(f"--critical-low-deg must be in [0, the slope {params.slope_deg:g} deg), "
                             f"got {critical_low_deg}")
    check_output_folder(out.parent if str(out.parent) else ".", option="--out")
    if cache_dir is not None:
        writable_dir(cache_dir, option="--cache-dir")
    options = FirmwareSweepOptions(steps=steps, noise_counts=noise, seed=seed, critical_slope=critical_slope,
                                   critical_low_deg=critical_low_deg)
    n = len(rates) * len(delays) + (2 if critical_slope else 0)
    with Progress(transient=True, console=_err_console()) as prog:
        task = prog.add_task(f"firmware sweep: {n} grid points", total=n)
        try:
            res = run_firmware_grid(params, rates, delays, options, scheduler=scheduler, workers=workers,
                                    cache_dir=cache_dir, progress=lambda i, t: prog.update(task, completed=i, total=t))
        except ConnectionError as err:
            raise ParameterError(f"--scheduler: {err}") from None
    meta = {"clutch": "firmware", "grid": {"rate_hz": rates, "delay_ms": delays}, "options": options.__dict__,
            "base_params": params.to_dict(), "scheduler": scheduler, "ideal": res["ideal"]}
    paths = write_table(res["rows"], out, meta)
    res["plot"] = str(plot_firmware_sweep(res, plot)) if plot is not None else None
    summary = {"clutch": "firmware", "rows": res["rows"], "ideal": res["ideal"], "references": res["references"],
               "files": [str(p) for p in paths], "plot": res["plot"], "seconds": res["seconds"],
               "computed": res["computed"], "cached": res["cached"], "scheduler": scheduler,
               "workers": res["workers"], "grid": meta["grid"]}
    if json_out:
        print_json(summary)
        return
    print_firmware_rows(res)
    con = _console()
    for p in paths + ([res["plot"]] if res["plot"] else []):
        con.print(f"wrote {p}", soft_wrap=True)
    con.print(f"{n} grid points ({res['computed']} computed, {res['cached']} from the cache) in "
              f"{res['seconds']:.1f} s on {res['workers']} worker(s), scheduler {scheduler}", soft_wrap=True)


def print_firmware_rows(out: dict[str, Any]) -> None:
    """The firmware sweep's table (80 columns); references and reasons under it."""
    i = out["ideal"]
    print(f"ideal clutch: theta'+ {i['theta_dot_plus_rad_s']:.4f} rad/s, period {i['step_period_s']:.4f} s, "
          f"stored {i['stored_energy_J']:.4f} J, max |eig| {i.get('max_abs_eigenvalue', float('nan')):.3f}")
    for name, r in (out.get("references") or {}).items():
        crit = r.get("critical_slope_deg")
        print(f"{'ideal ER' if name == 'er_ideal' else 'VE, ' + str(r.get('branch_label')) + ' gait'}: critical slope "
              f"{'-' if crit is None else f'{crit:.3f}'} deg, CoT {r.get('cot') or float('nan'):.4f}")
    refs = out.get("references") or {}
    if refs and refs["er_ideal"].get("cot_saving_vs_ve") is not None and refs["er_ideal"]["cot_saving_vs_ve"] <= 1e-3:
        print(f"the ideal ER wheel saves {100 * refs['er_ideal']['cot_saving_vs_ve']:.2f} % CoT over this VE gait: "
              "no advantage to keep a share of (ER adv '-'); the paper's comparison is the VE fast gait (--k 2500)")
    crit_cols = any("critical_slope_deg" in r for r in out["rows"] if r.get("clutch") == "firmware")
    head = (f"{'rate_hz':>7} {'delay_ms':>8} {'walks':>5} {'period_s':>8} {'speed':>6} {'stored':>6} {'|eig|':>6}")
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
            line = (f"{r['rate_hz']:>7g} {r['delay_ms']:>8g} {'yes' if r['walks'] else 'no':>5} "
                    f"{r['step_period_s']:>8.4f} {r['speed_ratio']:>6.3f} {r['stored_energy_ratio']:>6.3f} "
                    f"{'-' if eig is None else f'{eig:.3f}':>6}")
            if not r["walks"]:
                notes.append(f"{r['rate_hz']:g} Hz, {r['delay_ms']:g} ms: {r.get('failure')} {r.get('detail') or ''}")
        if crit_cols:
            crit, adv = r.get("critical_slope_deg"), r.get("er_advantage_remaining")
            line += (f" {'-' if crit is None else f'{crit:.3f}':>9} {'-' if adv is None else f'{adv:.2f}':>6} "
                     f"{str(r.get('limited_by', '-'))[:9]:>9}")
            mech = r.get("mechanical_critical_slope_deg")
            if r.get("limited_by") == "firmware":
                notes.append(f"{r['rate_hz']:g} Hz, {r['delay_ms']:g} ms: the firmware's fault limits the slope; "
                             f"mechanical boundary {'-' if mech is None else f'{mech:.3f}'} deg")
        print(line)
    print("speed, stored: fractions of the ideal clutch's walking speed and stored energy (spring energy held at "
          "touchdown); |eig|: fitted to the walk. ER adv: share of the ideal ER's CoT saving over VE kept.")
    for n in notes:
        print(n)
