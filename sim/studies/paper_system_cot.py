"""`rimless paper`'s system cost of transport: per k, every stable, valid branch's least system CoT at the given
electrical power, and the break-even clutch holding power (and, for a bistable clutch with no holding power, the
break-even switching energy) below which ER's least system CoT beats the VE branches' least (and each VE
branch's); the figure: least system CoT against holding power per branch at FIGURE_K.

Branches: rimless.sim.continuation.branches.trace_gait_branches from params.slope_rad (the start slope) down;
minima and break-evens: rimless.sim.studies.system_cot. Powers W, energies J, slopes deg, k N/m.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rimless.sim.model.electrical import ClutchPower
from rimless.sim.model.params import WheelParams
from rimless.sim.studies.system_cot import HOLD_POWER_FIGURE_W, BranchCot, break_even, gait_branch_cot

FIGURE_K = 2500.0
TABLE_CSV = "table7_system_cot.csv"
BRANCH_CSV = "table7_system_cot_branches.csv"
FIGURE_PNG = "fig_system_cot_hold_power.png"
FIGURE_CSV = "fig_system_cot_hold_power.csv"


def branches_at_k(params: WheelParams, k: float, backend: str, rtol: float) -> dict[str, list[BranchCot]]:
    """The stable, valid ER and VE branches at stiffness k (N/m), from params.slope_rad down."""
    from rimless.sim.continuation.branches import trace_gait_branches

    q = params.replace(stiffness_n_per_m=float(k))
    out: dict[str, list[BranchCot]] = {}
    for model in ("er", "ve"):
        gbs = trace_gait_branches(q, model, backend=backend, rtol=rtol, start_slope_rad=params.slope_rad)
        out[model] = [b for b in (gait_branch_cot(g, backend, rtol) for g in gbs) if b is not None]
    return out


def _fmt(x: float | None, unit: str) -> str:
    return "none" if x is None else f"{x:.4g} {unit}"


def k_rows(
    k: float, brs: dict[str, list[BranchCot]], power: ClutchPower
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """One table row for k (break-evens against the least VE and against each VE branch) and one row per branch."""
    branch_rows = []
    for model, items in brs.items():
        for b in items:
            r = b.minimise(power)
            branch_rows.append(
                {
                    "k": k,
                    "model": model.upper(),
                    "branch_label": b.label,
                    "critical_slope_deg": math.degrees(b.lo_rad),
                    "mechanical_cot_min": math.tan(b.lo_rad),
                    **{key: v for key, v in r.items() if key != "slope_range_rad"},
                }
            )
    hold = break_even(brs["er"], brs["ve"], power, "hold_power_w")
    switch = break_even(brs["er"], brs["ve"], power, "switch_energy_j")
    row: dict[str, Any] = {
        "k": k,
        **power.as_dict(),
        "er_mechanical_cot_min": min((math.tan(b.lo_rad) for b in brs["er"]), default=math.nan),
        "ve_mechanical_cot_min": min((math.tan(b.lo_rad) for b in brs["ve"]), default=math.nan),
        "ve_least_branch": hold["ve_branch"],
        "break_even_hold_power_w": hold["value"],
        "break_even_hold_power_reason": hold["reason"],
        "break_even_switch_energy_j": switch["value"],
        "break_even_switch_energy_reason": switch["reason"],
        "break_even_resolved": hold.get("resolved"),
    }
    for ve in brs["ve"]:
        h = break_even(brs["er"], [ve], power, "hold_power_w")
        s = break_even(brs["er"], [ve], power, "switch_energy_j")
        row[f"break_even_hold_power_w_vs_ve_{ve.label}"] = h["value"]
        row[f"break_even_switch_energy_j_vs_ve_{ve.label}"] = s["value"]
    return row, branch_rows


def figure_series(
    brs: dict[str, list[BranchCot]], power: ClutchPower, holds_w: tuple[float, ...] = HOLD_POWER_FIGURE_W
) -> list[dict[str, Any]]:
    """Least system CoT of each branch against the ER clutch's holding power (the other powers as given)."""
    rows = []
    for model, items in brs.items():
        for b in items:
            for p_w in holds_w:
                r = b.minimise(power.replace(hold_power_w=p_w))
                rows.append(
                    {
                        "model": model.upper(),
                        "branch_label": b.label,
                        "hold_power_w": p_w,
                        "min_system_cot": r["min_system_cot"],
                        "min_system_cot_slope_deg": r["min_system_cot_slope_deg"],
                        "min_system_cot_at_bound": r["min_system_cot_at_bound"],
                    }
                )
    return rows


def figure_system_cot(
    series: list[dict[str, Any]],
    k: float,
    break_even_w: float | None,
    out: Path,
    per_branch_w: dict[str, float | None] | None = None,
) -> list[Path]:
    """Least system CoT against holding power (symmetric-log axis, linear below 0.01 W), one line per branch; a
    hollow marker where the least lies on the bound of the followed slope range (the start slope: the true least
    may be higher up); dashed: the break-even against the least VE, dotted: against each VE branch."""
    import pandas as pd

    from rimless.sim.studies.paper_figures import pyplot, write_csv

    frame = pd.DataFrame(series)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    for (model, label), g in frame.groupby(["model", "branch_label"], sort=False):
        name = "ER" if model == "ER" else f"VE {label}"
        (line,) = ax.plot(g["hold_power_w"], g["min_system_cot"], marker="o", label=name)
        b = g[g["min_system_cot_at_bound"] == "start-slope"]
        if len(b):
            ax.plot(b["hold_power_w"], b["min_system_cot"], "o", mfc="white", color=line.get_color())
    if break_even_w is not None:
        ax.axvline(break_even_w, color="grey", ls="--", lw=1)
        ax.text(break_even_w, ax.get_ylim()[1], f" break-even {break_even_w:.3g} W", va="top", fontsize=8)
    for i, (label, w) in enumerate((per_branch_w or {}).items()):
        if w is not None and w != break_even_w:
            ax.axvline(w, color="grey", ls=":", lw=1)
            ax.text(w, ax.get_ylim()[1] * (0.93 - 0.06 * i), f" vs VE {label}: {w:.3g} W", va="top", fontsize=8)
    ax.set_xscale("symlog", linthresh=0.01)
    ax.set_xlim(left=0.0)
    ax.set_xlabel("ER clutch holding power (W, linear below 0.01)")
    ax.set_ylabel("least system CoT along the branch")
    ax.set_title(f"system cost of transport, k = {k:g} N/m (hollow: least at the start slope)")
    ax.legend(fontsize=8)
    png = out / FIGURE_PNG
    tmp = png.with_name(f".{png.name}.tmp.png")
    fig.savefig(tmp, dpi=150)
    plt.close(fig)
    tmp.replace(png)
    return [png, write_csv(frame, out / FIGURE_CSV)]


def system_cot_paper(
    out: Path,
    params: WheelParams,
    ks: tuple[float, ...],
    power: ClutchPower,
    *,
    backend: str,
    rtol: float,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Write the system-CoT table (CSV per k and per branch) and figure; return rows, files and headline lines."""
    import pandas as pd

    from rimless.sim.studies.paper_figures import write_csv

    say = progress or (lambda msg: None)
    rows, branch_rows, files = [], [], []
    fig_brs = None
    for i, k in enumerate(sorted(set(ks) | {FIGURE_K})):
        say(f"system cost of transport: k = {k:g} ({i + 1}/{len(set(ks) | {FIGURE_K})})")
        brs = branches_at_k(params, k, backend, rtol)
        row, br_rows = k_rows(k, brs, power)
        rows.append(row)
        branch_rows += br_rows
        if k == FIGURE_K:
            fig_brs = brs
    files.append(write_csv(pd.DataFrame(rows), out / TABLE_CSV))
    files.append(write_csv(pd.DataFrame(branch_rows), out / BRANCH_CSV))
    at = next(r for r in rows if r["k"] == FIGURE_K)
    if fig_brs is not None:
        per = {
            key.rsplit("_vs_ve_", 1)[1]: v for key, v in at.items() if key.startswith("break_even_hold_power_w_vs_ve_")
        }
        files += figure_system_cot(figure_series(fig_brs, power), FIGURE_K, at["break_even_hold_power_w"], out, per)
    vs = "; ".join(
        f"vs VE {key.rsplit('_vs_ve_', 1)[1]} {_fmt(v, 'W')}"
        for key, v in at.items()
        if key.startswith("break_even_hold_power_w_vs_ve_")
    )
    vs_sw = "; ".join(
        f"vs VE {key.rsplit('_vs_ve_', 1)[1]} {_fmt(v, 'J')}"
        for key, v in at.items()
        if key.startswith("break_even_switch_energy_j_vs_ve_")
    )
    headline = [
        {
            "quantity": f"break-even clutch holding power at k = {FIGURE_K:g} (W)",
            "paper": "- (not evaluated)",
            "ours": f"vs the least VE ({at['ve_least_branch']}): {_fmt(at['break_even_hold_power_w'], 'W')}; {vs}",
            "note": "ER's least system CoT beats VE's below it; " + at["break_even_hold_power_reason"],
        },
        {
            "quantity": f"break-even switching energy, bistable clutch, k = {FIGURE_K:g} (J)",
            "paper": "-",
            "ours": f"vs the least VE: {_fmt(at['break_even_switch_energy_j'], 'J')}; {vs_sw}",
            "note": "no holding power, two switchings per step; " + at["break_even_switch_energy_reason"],
        },
    ]
    return {"rows": rows, "branch_rows": branch_rows, "files": files, "headline": headline}
