"""The robot's clutch timing beside the simulation's, for the trials report: the measured clutched time per step
from a robot trial log (`rimless.analysis.io.robot_log`) and the simulated one of the trial's comparison
(`rimless.analysis.inference.compare.TrialComparison.sim_clutched_s`); the dictionary and its HTML section.
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["clutch_comparison", "clutch_html"]


def num(v: Any, fmt: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


def clutch_comparison(log: Any, comp: Any) -> dict[str, Any]:
    """The robot log's measured clutched time per step (lock to release of the same leg, in lock order) beside
    the simulated one of the trial's comparison (``sim_clutched_s``, one per measured period). The k-th released
    lock of the log is put beside the k-th compared step: the log and the Vicon recording share no clock, so the
    pairing is by order, and the means are the robust comparison. Times in ms in the result."""
    measured = log.complete()
    sim = np.asarray(comp.sim_clutched_s, float) if comp is not None else np.zeros(0)
    sim = sim[np.isfinite(sim)]
    n = max(measured.size, sim.size)
    rows = [
        {
            "step": k + 1,
            "measured_ms": float(measured[k]) * 1e3 if k < measured.size else None,
            "simulated_ms": float(sim[k]) * 1e3 if k < sim.size else None,
        }
        for k in range(n)
    ]
    mean_m = float(np.mean(measured)) * 1e3 if measured.size else None
    mean_s = float(np.mean(sim)) * 1e3 if sim.size else None
    return {
        "robot_log": log.path,
        "rows": rows,
        "measured_mean_ms": mean_m,
        "simulated_mean_ms": mean_s,
        "difference_ms": (mean_m - mean_s) if mean_m is not None and mean_s is not None else None,
        "locks": int(log.lock_s.size),
        "unreleased_locks": int(log.lock_s.size - measured.size),
        "compared": comp is not None and comp.status in ("ok", "suspect"),
        "warnings": list(log.warnings),
    }


def clutch_html(clutch: dict[str, dict[str, Any]]) -> str:
    e = html.escape
    out = ['<h2 id="clutch-time">Clutched time per step: robot log vs simulation</h2>']
    for name, c in clutch.items():
        out.append(
            f'<p class="small">{e(name)} with the robot log {e(Path(c["robot_log"]).name)}: '
            f"{c['locks']} locks ({c['unreleased_locks']} not released in the log); mean measured "
            f"{num(c['measured_mean_ms'], '.1f')} ms, simulated {num(c['simulated_mean_ms'], '.1f')} ms "
            "(the k-th lock beside the k-th compared step: the two recordings share no clock).</p>"
        )
        out.append(
            '<table class="clutch"><thead><tr><th>step</th><th>measured clutched, ms</th>'
            "<th>simulated, ms</th></tr></thead><tbody>"
        )
        for r in c["rows"]:
            out.append(
                f'<tr><td class="n">{r["step"]}</td><td class="n">{num(r["measured_ms"], ".1f")}</td>'
                f'<td class="n">{num(r["simulated_ms"], ".1f")}</td></tr>'
            )
        out.append("</tbody></table>")
    return "\n".join(out)
