"""Benchmark of the held parameters carried into a model's critical slope: ``python -m
rimless.analysis.bench.carry``.

Runs the carry of `rimless.analysis.inference.held.carry_critical` (the model's part: forward differences by
default, ``--central`` both sides as ``trials critical-slope``, the report and ``rimless demo`` take them; default
Table 1 with its default uncertainties, ``--params`` a wheel file) twice in one run: the straightforward runs
(``warm=False``: `model_critical_slope` at each perturbed wheel) and the warm-started ones (`held.WarmCritical`). Prints the CPU and wall seconds of each, the ratio of the
CPU seconds, how many runs were warm, and the largest difference of a perturbed critical slope between the two
against the root-location tolerance (`held.REFINE_TOL_RAD`).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any


def compare(win: Any, model: str = "er", *, central: bool = False) -> dict[str, Any]:
    """Both carries of ``win``'s held parameters into ``model``'s critical slope; the figures printed."""
    from rimless.analysis.inference.critical_slope import CriticalSlopeResult, model_critical_slope
    from rimless.analysis.inference.held import REFINE_TOL_RAD, WarmCritical, carry_critical

    nominal = model_critical_slope(win.params, model)["critical_slope_deg"]
    out: dict[str, Any] = {"model": model, "critical_slope_deg": nominal, "tolerance_deg": math.degrees(REFINE_TOL_RAD)}
    rows = {}
    for warm in (False, True):
        res = CriticalSlopeResult([], None, [], None, "the model's part only")
        res.model = {"critical_slope_deg": {model: nominal}, "detail": {}}
        cpu, wall = time.process_time(), time.perf_counter()
        held = carry_critical(res, [], [], win, models=(model,), central_models=central, warm=warm)
        key = "warm" if warm else "straightforward"
        out[f"{key}_cpu_s"] = time.process_time() - cpu
        out[f"{key}_wall_s"] = time.perf_counter() - wall
        rows[key] = held["models"][model]
    diffs = [
        abs(a[k] - b[k])
        for a, b in zip(rows["warm"]["contributions"], rows["straightforward"]["contributions"])
        for k in ("plus_deg", "minus_deg")
        if a.get(k) is not None and b.get(k) is not None
    ]
    probe = WarmCritical(win.params, model, nominal)
    out["warm_start_deg"] = math.degrees(probe.start[0]) if probe.start is not None else None
    out["max_difference_deg"] = max(diffs, default=0.0)
    out["se_parameters_deg"] = (rows["straightforward"]["se_parameters_deg"], rows["warm"]["se_parameters_deg"])
    out["ratio_cpu"] = out["straightforward_cpu_s"] / out["warm_cpu_s"]
    return out


def main(argv: list[str] | None = None) -> None:
    from rimless.analysis.inference.runs import wheel_input

    ap = argparse.ArgumentParser(prog="python -m rimless.analysis.bench.carry", description=__doc__)
    ap.add_argument("--params", type=Path, default=None, help="wheel file (default Table 1, default sds)")
    ap.add_argument("--model", default="er", choices=("er", "ve"))
    ap.add_argument(
        "--central", action="store_true", help="both sides (trials critical-slope, the report, the demo), not forward"
    )
    a = ap.parse_args(argv)
    r = compare(wheel_input(a.params), a.model, central=a.central)
    start = "none (every run straightforward)" if r["warm_start_deg"] is None else f"{r['warm_start_deg']:.4f} deg"
    print(f"model {r['model']}: critical slope {r['critical_slope_deg']:.6f} deg; warm start {start}")
    for key in ("straightforward", "warm"):
        print(f"{key:>15}: {r[f'{key}_cpu_s']:.2f} s CPU, {r[f'{key}_wall_s']:.2f} s wall")
    print(f"ratio (CPU): {r['ratio_cpu']:.2f}x")
    print(
        f"largest difference of a perturbed critical slope: {r['max_difference_deg']:.2e} deg "
        f"(root location {r['tolerance_deg']:.2e} deg); se {r['se_parameters_deg'][0]:.6f} / "
        f"{r['se_parameters_deg'][1]:.6f} deg"
    )


if __name__ == "__main__":
    main()
