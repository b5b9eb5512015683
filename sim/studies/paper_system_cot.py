"""`rimless paper`'s system cost of transport: per k, every stable, valid branch's least system CoT at the given
electrical power, and the break-even clutch holding power (and, for a bistable clutch with no holding power, the
break-even switching energy) below which ER's least system CoT beats the VE branches' least (and each VE
branch's); the figure: least system CoT against holding power per branch at FIGURE_K.

Branches: every stable, contact-valid branch the paper's sweep found (rimless.sim.studies.sweep: gaits searched at
the start slope params.slope_rad and at the lower search slopes, each followed down to the end of its stable, valid
part), so a gait that walks below the other wheel's critical slope is never left out; minima and break-evens:
rimless.sim.studies.system_cot (a tie where the two least CoTs differ by no more than they are located).
FIGURE_K: the figure's and the headline's k, the wheel's own (Table 1: 2700 N/m). Powers W, energies J, slopes
deg, k N/m.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rimless.sim.model.electrical import ClutchPower
from rimless.sim.model.params import WheelParams
from rimless.sim.studies.system_cot import HOLD_POWER_FIGURE_W, BranchCot, break_even, gait_branch_cot

FIGURE_K = 2700.0  # Table 1's k: the default; system_cot_paper takes the wheel's own k (params.k)
TABLE_CSV = "table7_system_cot.csv"
BRANCH_CSV = "table7_system_cot_branches.csv"
FIGURE_PNG = "fig_system_cot_hold_power.png"
FIGURE_CSV = "fig_system_cot_hold_power.csv"


def branches_at_k(params: WheelParams, k: float, backend: str, rtol: float) -> dict[str, list[BranchCot]]:
    """The stable, valid ER and VE branches at stiffness k (N/m): gaits at params.slope_rad and at the lower
    search slopes (rimless.sim.continuation.branches.search_slopes), each followed down."""
    from rimless.sim.continuation.branches import search_slopes, trace_gait_branches

    q = params.replace(stiffness_n_per_m=float(k))
    out: dict[str, list[BranchCot]] = {}
    for model in ("er", "ve"):
        gbs = trace_gait_branches(
            q,
            model,
            backend=backend,
            rtol=rtol,
            start_slope_rad=params.slope_rad,
            search_slopes_rad=search_slopes(params.slope_rad),
        )
        out[model] = [b for b in (gait_branch_cot(g, backend, rtol) for g in gbs) if b is not None]
    return out


def branches_from_sweep(
    rows: list[dict[str, Any]], points: list[dict[str, Any]], k: float, backend: str, rtol: float
) -> dict[str, list[BranchCot]]:
    """The stable, valid ER and VE branches at stiffness k (N/m) from the sweep's rows and branch points
    (rimless.sim.studies.sweep.compute_point): each from its recorded points above its critical slope down to
    the located end. Two branches of one label are told apart by the slope they were found at."""
    from rimless.sim.model.params import WheelParams
    from rimless.sim.studies.system_cot import branch_factory

    out: dict[str, list[BranchCot]] = {"er": [], "ve": []}
    seen: set[str] = set()
    for r in rows:
        model = str(r.get("model", "")).lower()
        crit = r.get("critical_slope_rad", math.nan)
        if model not in out or abs(float(r["k"]) - k) > 1e-9 or not r.get("branch") or not crit == crit:
            continue
        end = (r.get("end_theta_plus_rad", math.nan), r.get("end_theta_dot_plus_rad_s", math.nan))
        pts = []
        for pt in points:  # in the order traced, up to the end: past a fold the branch climbs again, unstable
            if pt["model"] != r["model"] or pt["branch"] != r["branch"] or abs(pt["k"] - k) > 1e-9:
                continue
            if pt["slope_rad"] <= crit or not pt["stable"] or pt.get("contact_valid") is False:
                break
            pts.append((pt["slope_rad"], np.array([pt["theta_plus_rad"], pt["theta_dot_plus_rad_s"]])))
        pts = [q for q in pts if q[0] > crit]
        pts.append((r["start_slope_rad"], np.array([r["theta_plus_rad"], r["theta_dot_plus_rad_s"]])))
        guessed: frozenset[float] = frozenset()
        if end[0] == end[0]:
            pts.append((crit, np.array(end, dtype=float)))
        else:  # an older row without its end state: solved on use from the nearest point
            pts.append((crit, min(pts, key=lambda q: abs(q[0] - crit))[1]))
            guessed = frozenset({float(crit)})
        params = WheelParams(
            hub_mass_kg=r["hub_mass_kg"],
            leg_mass_kg=r["leg_mass_kg"],
            stiffness_n_per_m=r["k"],
            damping_ns_per_m=r["c"],
            mass_model=r["mass_model"],
            slope_rad=r["start_slope_rad"],
        )
        factory, jac = branch_factory(model, backend, rtol)
        label = str(r["branch_label"])
        if label in seen:
            label = f"{label}@{math.degrees(r['start_slope_rad']):.3f}deg"
        seen.add(label)
        tol = r.get("critical_slope_tol_rad", r.get("end_location_tol_rad", 0.0))
        out[model].append(
            BranchCot(
                model,
                params,
                pts,
                factory,
                jac,
                label=label,
                lo_tol_rad=float(tol) if tol == tol else 0.0,
                guessed=guessed,
            )
        )
    return out


def _fmt(x: float | None, unit: str) -> str:
    return "none" if x is None else f"{x:.4g} {unit}"


def k_rows(
    k: float, brs: dict[str, list[BranchCot]], power: ClutchPower
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """One table row for k (break-evens against the least VE and against each VE branch, a tie where the least
    CoTs differ by no more than they are located) and one row per branch."""
    branch_rows = []
    for model, items in brs.items():
        for b in items:
            r = b.minimise(power)
            branch_rows.append(
                {
                    "k": k,
                    "model": model.upper(),
                    "branch_label": b.label,
                    "found_at_slope_deg": math.degrees(b.params.slope_rad),
                    "critical_slope_deg": math.degrees(b.lo_rad),
                    "critical_slope_rad": b.lo_rad,
                    "critical_slope_tol_rad": b.lo_tol_rad,
                    "mechanical_cot_min": math.tan(b.lo_rad),
                    **{key: v for key, v in r.items() if key != "slope_range_rad"},
                }
            )
    hold = break_even(brs["er"], brs["ve"], power, "hold_power_w", interval=True)
    switch = break_even(brs["er"], brs["ve"], power, "switch_energy_j")
    er_min = min((math.tan(b.lo_rad) for b in brs["er"]), default=math.nan)
    ve_min = min((math.tan(b.lo_rad) for b in brs["ve"]), default=math.nan)
    row: dict[str, Any] = {
        "k": k,
        **power.as_dict(),
        "er_mechanical_cot_min": er_min,
        "ve_mechanical_cot_min": ve_min,
        "er_vs_ve_mechanical_cot_pct": 100.0 * (er_min / ve_min - 1.0)
        if er_min == er_min and ve_min == ve_min
        else math.nan,
        "ve_least_branch": hold["ve_branch"],
        "ve_least_found_at_slope_deg": next(
            (math.degrees(b.params.slope_rad) for b in brs["ve"] if b.label == hold["ve_branch"]), math.nan
        ),
        "break_even_hold_power_w": hold["value"],
        "break_even_hold_power_interval_w": hold.get("interval"),
        "break_even_hold_power_reason": hold["reason"],
        "break_even_switch_energy_j": switch["value"],
        "break_even_switch_energy_reason": switch["reason"],
        "break_even_resolved": hold.get("resolved"),
        "break_even_tie": bool(hold.get("tie")),
        "break_even_cot_resolution": hold.get("cot_resolution", math.nan),
        "er_minus_ve_least_cot_at_zero_power": hold.get("cot_difference_at_zero", math.nan),
    }
    for ve in brs["ve"]:
        h = break_even(brs["er"], [ve], power, "hold_power_w", interval=True)
        s = break_even(brs["er"], [ve], power, "switch_energy_j")
        row[f"break_even_hold_power_w_vs_ve_{ve.label}"] = h["value"]
        row[f"break_even_hold_power_tie_vs_ve_{ve.label}"] = bool(h.get("tie"))
        row[f"break_even_hold_power_interval_w_vs_ve_{ve.label}"] = h.get("interval")
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


def _be_text(row: dict[str, Any], key: str, unit: str) -> str:
    if row.get(f"{key}_tie") or (key == "break_even_hold_power_w" and row.get("break_even_tie")):
        return "tie"
    return _fmt(row.get(key), unit)


def system_cot_paper(
    out: Path,
    params: WheelParams,
    ks: tuple[float, ...],
    power: ClutchPower,
    *,
    backend: str,
    rtol: float,
    progress: Callable[[str], None] | None = None,
    rows: list[dict[str, Any]] | None = None,
    points: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Write the system-CoT table (CSV per k and per branch) and figure (at the wheel's own k, params.k); return
    rows, files and headline lines. The branches come from the sweep's `rows` and `points` when given (they must
    cover ks and params.k), else are traced here (branches_at_k, with the lower search slopes)."""
    import pandas as pd

    from rimless.sim.studies.paper_figures import write_csv

    say = progress or (lambda msg: None)
    fig_k = float(params.k)
    table_rows, branch_rows, files = [], [], []
    fig_brs = None
    all_k = sorted(set(ks) | {fig_k})
    for i, k in enumerate(all_k):
        say(f"system cost of transport: k = {k:g} ({i + 1}/{len(all_k)})")
        if rows is not None:
            brs = branches_from_sweep(rows, points or [], k, backend, rtol)
        else:
            brs = branches_at_k(params, k, backend, rtol)
        row, br_rows = k_rows(k, brs, power)
        table_rows.append(row)
        branch_rows += br_rows
        if k == fig_k:
            fig_brs = brs
    files.append(write_csv(pd.DataFrame(table_rows), out / TABLE_CSV))
    files.append(write_csv(pd.DataFrame(branch_rows), out / BRANCH_CSV))
    at = next(r for r in table_rows if r["k"] == fig_k)
    if fig_brs is not None and (fig_brs["er"] or fig_brs["ve"]):
        per = {
            key.rsplit("_vs_ve_", 1)[1]: v for key, v in at.items() if key.startswith("break_even_hold_power_w_vs_ve_")
        }
        files += figure_system_cot(figure_series(fig_brs, power), fig_k, at["break_even_hold_power_w"], out, per)

    def _vs(key: str, v: float | None) -> str:
        if at.get(key.replace("_hold_power_w_", "_hold_power_tie_")):
            return "tie"
        iv = at.get(key.replace("_hold_power_w_", "_hold_power_interval_w_"))
        return _fmt(v, "W") + (f" ({iv[0]:.3g}-{iv[1]:.3g} W)" if iv else "")

    vs = "; ".join(
        f"vs VE {key.rsplit('_vs_ve_', 1)[1]} {_vs(key, v)}"
        for key, v in at.items()
        if key.startswith("break_even_hold_power_w_vs_ve_")
    )
    vs_sw = "; ".join(
        f"vs VE {key.rsplit('_vs_ve_', 1)[1]} {_fmt(v, 'J')}"
        for key, v in at.items()
        if key.startswith("break_even_switch_energy_j_vs_ve_")
    )
    interval = at.get("break_even_hold_power_interval_w")
    iv = f" ({interval[0]:.3g}-{interval[1]:.3g} W)" if interval else ""
    resolved = [r for r in table_rows if r["break_even_hold_power_w"] is not None]
    best = max(resolved, key=lambda r: r["break_even_hold_power_w"], default=None)
    grid_txt = (
        f"{best['break_even_hold_power_w']:.3g} W at k = {best['k']:g} N/m (vs VE {best['ve_least_branch']})"
        if best is not None
        else "none: ER's least CoT is not below VE's at any k"
    )
    ties = [f"{r['k']:g}" for r in table_rows if r.get("break_even_tie")]
    dearer = [f"{r['k']:g}" for r in table_rows if not r.get("break_even_tie") and r["break_even_hold_power_w"] is None]
    headline = [
        {
            "quantity": f"break-even clutch holding power at k = {fig_k:g} (W)",
            "paper": "- (not evaluated)",
            "ours": f"vs the least VE ({at['ve_least_branch']}): {_be_text(at, 'break_even_hold_power_w', 'W')}{iv}; {vs}",
            "note": "ER's least system CoT beats VE's below it; " + at["break_even_hold_power_reason"],
        },
        {
            "quantity": f"break-even switching energy, bistable clutch, k = {fig_k:g} (J)",
            "paper": "-",
            "ours": f"vs the least VE: {_fmt(at['break_even_switch_energy_j'], 'J')}; {vs_sw}",
            "note": "no holding power, two switchings per step; " + at["break_even_switch_energy_reason"],
        },
        {
            "quantity": f"largest break-even clutch holding power over k = {min(all_k):g}-{max(all_k):g} N/m",
            "paper": "-",
            "ours": grid_txt,
            "note": "against the least of every stable, valid VE gait found (searched at the start slope and "
            "below); ties (least CoTs within their location tolerance) at k = "
            + (", ".join(ties) or "none")
            + "; ER dearer than VE even with no clutch power at k = "
            + (", ".join(dearer) or "none"),
        },
    ]
    return {"rows": table_rows, "branch_rows": branch_rows, "files": files, "headline": headline}
