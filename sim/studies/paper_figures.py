"""The figures of the paper's simulation section (rimless.sim.studies.paper), drawn from data computed
there: each writes its PNG (150 dpi) and the CSV of what it shows, atomically."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

EIGEN_K = (2000.0, 2500.0, 3000.0)  # the k of figure 4's eigenvalue map, N/m
PERTURBATION = 1.05  # theta'+ of the start state = 1.05 x the fixed point's (figure 3)
# the columns of the sweep's branch points (rimless.sim.continuation.branches.GaitBranch.point_rows) figure 4 reads
POINT_COLUMNS = (
    "model",
    "k",
    "branch",
    "branch_label",
    "slope_rad",
    "slope_deg",
    "max_abs_eigenvalue",
    "stable",
    "contact_valid",
)


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_csv(frame: Any, path: Path) -> Path:
    tmp = path.with_name(f".{path.name}.tmp")
    frame.to_csv(tmp, index=False)
    tmp.replace(path)
    return path


def phase_key(traj: Any) -> list[Any]:
    """Legend patches for the phase shading of `traj` (the phases it goes through)."""
    from matplotlib.patches import Patch

    from rimless.sim.studies.figures import PHASE_COLOURS, PHASE_LABELS

    seen = {rec.name for st in traj.steps for rec in st.phases} if getattr(traj, "steps", None) else set(PHASE_COLOURS)
    return [Patch(color=c, label=f"shading: {PHASE_LABELS[n]}") for n, c in PHASE_COLOURS.items() if n in seen]


def figure_typical_gaits(trajs: dict[str, Any], out: Path) -> list[Path]:
    """Figure 1: leg lengths, CoM height and stick diagrams of both wheels side by side."""
    import pandas as pd

    from rimless.sim.studies.figures import save_figure, shade_phases, stick_diagram

    plt = pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(12, 10), constrained_layout=True)
    for col, model in enumerate(("ve", "er")):
        traj = trajs[model]
        tab = traj.table
        name = {"er": "energy-recycling", "ve": "viscoelastic"}[model]
        ax = axes[0, col]
        shade_phases(ax, traj)
        ax.plot(tab["t_s"], tab["L1_m"] * 1e3, label="stance leg L1")
        ax.plot(tab["t_s"], tab["L2_m"] * 1e3, label="trailing leg L2")
        ax.set_ylabel("leg length (mm)")
        ax.set_title(f"({'ad'[col]}) {name}: leg lengths")
        ax.legend(handles=ax.get_legend_handles_labels()[0] + phase_key(traj), fontsize=7, loc="lower right")
        ax = axes[1, col]
        shade_phases(ax, traj)
        ax.plot(tab["t_s"], tab["com_height_normal_m"] * 1e3, color="C2")
        ax.set_ylabel("CoM height normal to slope (mm)")
        ax.set_xlabel("time (s)")
        ax.set_title(f"({'be'[col]}) {name}: CoM height")
        ax = axes[2, col]
        stick_diagram(traj, ax, step=0, every_s=0.03)
        ax.set_title(f"({'cf'[col]}) {name}: stick diagram of one step")
    fig.suptitle(
        f"typical gaits at {trajs['er'].params.slope_deg:.3f} deg, k = {trajs['er'].params.k:g} N/m "
        "(shading: the phase of the step)"
    )
    png = save_figure(fig, out / "fig1_typical_gaits.png")
    frames = [pd.DataFrame(trajs[m].table).assign(model=m.upper()) for m in ("er", "ve")]
    csv = write_csv(pd.concat(frames, ignore_index=True), out / "fig1_typical_gaits.csv")
    return [png, csv]


def figure_forces(trajs: dict[str, Any], out: Path) -> list[Path]:
    """Figure 2: slope-normal ground reaction forces of both wheels, the tensile transient marked."""
    import pandas as pd

    from rimless.sim.studies.figures import plot_forces, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), constrained_layout=True, sharex=True)
    rows = []
    for ax, model in zip(axes, ("ve", "er")):
        traj = trajs[model]
        plot_forces(traj, ax)
        tab = traj.table
        lam = np.asarray(tab["lambda_b_y_N"], dtype=float)
        dl = np.asarray(tab["phase"]) == "dlsp"
        tmin = float(np.nanmin(np.where(dl, lam, np.nan)))
        ax.set_title(
            f"{'viscoelastic' if model == 've' else 'energy-recycling'}: leading-foot minimum in double "
            f"support {tmin:.2f} N"
        )
        for i in range(len(tab["t_s"])):
            rows.append(
                {
                    "model": model.upper(),
                    "t_s": tab["t_s"][i],
                    "phase": tab["phase"][i],
                    "grf_b_N": tab["lambda_b_y_N"][i],
                    "grf_a_N": tab["lambda_a_y_N"][i],
                }
            )
    axes[-1].set_xlabel("time (s)")
    png = save_figure(fig, out / "fig2_ground_reaction_forces.png")
    csv = write_csv(pd.DataFrame(rows), out / "fig2_ground_reaction_forces.csv")
    return [png, csv]


def figure_energy_ratio(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    import pandas as pd
    from matplotlib.ticker import MaxNLocator

    from rimless.sim.studies.figures import save_figure

    plt = pyplot()
    frame = pd.DataFrame(rows)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True, sharey=True)
    for ax, model in zip(axes, ("VE", "ER")):
        sub = frame[frame.model == model] if len(frame) else frame
        missing = []
        for j, (k, g) in enumerate(sub.groupby("k") if len(sub) else []):
            walked = g[g["step"] > 0]
            if not len(walked):  # no gait to start from: named on the figure, not dropped silently
                missing.append(f"k = {k:g} N/m: {g['failure'].iloc[0]}")
                continue
            gait = ""
            if "branch_label" in walked and isinstance(walked["branch_label"].iloc[0], str):
                name = "" if model == "ER" else f" {walked['branch_label'].iloc[0]}"
                gait = f", {model}{name} gait, step {walked['gait_period_s'].iloc[0]:.3f} s"
            ax.plot(
                walked["step"], walked["energy_ratio"] * 100, "o-", ms=3, color=f"C{j}", label=f"k = {k:g} N/m{gait}"
            )
        if missing:
            ax.text(
                0.02,
                0.02,
                "not shown (no gait):\n" + "\n".join(missing),
                transform=ax.transAxes,
                fontsize=7,
                va="bottom",
                color="C3",
            )
        ax.set_title({"VE": "viscoelastic", "ER": "energy-recycling"}[model])
        ax.set_xlabel("step")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    axes[0].set_ylabel("energy transition ratio E+/E- (%)")
    fig.suptitle(f"energy transition ratio at impact from a perturbed start (theta'+ x {PERTURBATION})")
    return [save_figure(fig, out / "fig3_energy_ratio.png"), write_csv(frame, out / "fig3_energy_ratio.csv")]


def missing_eigen_curves(rows: list[dict[str, Any]], ks: tuple[float, ...] = EIGEN_K) -> list[tuple[str, float]]:
    """(model, k) of figure 4's requested curves that have no branch stable at the start slope to draw."""
    have = {(r["model"], r["k"]) for r in rows if r.get("stable_at_start")}
    return [(m, float(k)) for m in ("VE", "ER") for k in ks if (m, float(k)) not in have]


def figure_eigenvalues(
    points: list[dict[str, Any]], rows: list[dict[str, Any]], out: Path, ks: tuple[float, ...] = EIGEN_K
) -> list[Path]:
    """Figure 4: max |eig| against slope along every branch stable at the start slope, down to the end of its
    stable, valid part (a branch invalid at the start: down to the end of the part that becomes valid, or its
    end); solid with filled markers where the gait respects unilateral contact, dashed with open markers where
    it does not (found with the stance foot held)."""
    import pandas as pd

    from rimless.sim.studies.figures import save_figure

    plt = pyplot()
    frame = pd.DataFrame(points)
    if not len(frame):  # no branch anywhere on the grid (every k without a gait): the axes say so, not a KeyError
        frame = pd.DataFrame(columns=POINT_COLUMNS)
    info = {(r["model"], r["k"], r.get("branch", "")): r for r in rows}
    keep = []
    for (model, k, branch), g in frame.groupby(["model", "k", "branch"]):
        r = info.get((model, k, branch))
        if k not in ks or r is None or not r.get("stable_at_start"):
            continue
        c = r.get("critical_slope_rad", math.nan)
        if not c == c:
            c = r.get("valid_end_slope_rad", math.nan)
        if not c == c:
            c = r.get("end_slope_rad", math.nan)
        keep.append(g[g.slope_rad >= c - 1e-12] if c == c else g)
    data = pd.concat(keep, ignore_index=True) if keep else frame.iloc[:0]
    if len(data):
        data = data.assign(contact_valid=data["contact_valid"].map(lambda v: bool(v) if v is not None else True))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True, sharey=True)
    styles = ["-", "-.", ":", (0, (5, 1))]
    for ax, model in zip(axes, ("VE", "ER")):
        sub = data[data.model == model] if len(data) else data
        for j, k in enumerate(ks):
            for b_i, (branch, g) in enumerate(sub[sub.k == k].groupby("branch") if len(sub) else []):  # noqa: B007
                g = g.sort_values("slope_rad")
                valid = g["contact_valid"].to_numpy(dtype=bool)
                col = f"C{j}"
                label = f"k = {k:g}, {g['branch_label'].iloc[0]}"
                ax.plot(
                    g["slope_deg"].where(valid),
                    g["max_abs_eigenvalue"].where(valid),
                    ls=styles[b_i % 4],
                    color=col,
                    label=label if valid.any() else None,
                )
                if (~valid).any():  # the invalid part, and its joint with the valid part, dashed
                    inv = ~valid | np.r_[~valid[1:], False] | np.r_[False, ~valid[:-1]]
                    ax.plot(
                        g["slope_deg"].where(inv),
                        g["max_abs_eigenvalue"].where(inv),
                        "--",
                        color=col,
                        lw=1,
                        label=None if valid.any() else label,
                    )
                    ax.plot(
                        g["slope_deg"][~valid], g["max_abs_eigenvalue"][~valid], "o", mfc="white", color=col, ms=3.5
                    )
        ax.axhline(1.0, color="k", ls="--", lw=1)
        missing = [k for m, k in missing_eigen_curves(rows, ks) if m == model]
        if missing:  # a requested k without a curve is named, not dropped silently
            ax.text(
                0.02,
                0.02,
                "no branch stable at the start slope: k = " + ", ".join(f"{k:g}" for k in missing) + " N/m",
                transform=ax.transAxes,
                fontsize=7,
                color="C3",
                va="bottom",
            )
        ax.set_xlabel("slope (deg)")
        ax.set_title({"VE": "viscoelastic", "ER": "energy-recycling"}[model])
        ax.grid(alpha=0.3)
        if len(sub) and not sub[sub.k.isin(ks)]["contact_valid"].astype(bool).all():  # a key only for what is drawn
            ax.plot([], [], "--o", mfc="white", color="0.4", lw=1, ms=3.5, label="violates unilateral contact")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    axes[0].set_ylabel("max |eigenvalue| of the Poincare map")
    return [save_figure(fig, out / "fig4_eigenvalue_map.png"), write_csv(data, out / "fig4_eigenvalue_map.csv")]


def figure_cot(
    crows: list[dict[str, Any]],
    out: Path,
    curves: list[dict[str, Any]] | None = None,
    ranges: list[dict[str, Any]] | None = None,
) -> list[Path]:
    """Figure 5: CoT against k per branch; filled markers contact-valid, open markers not; lines: the boundary
    curves traced by two-parameter continuation."""
    import pandas as pd

    from rimless.sim.studies.figures import save_figure

    plt = pyplot()
    frame = pd.DataFrame(crows)
    n_bars = len(ranges or [])
    fig, (ax, strip) = plt.subplots(
        2,
        1,
        figsize=(9, 6.2 + 0.15 * n_bars),
        constrained_layout=True,
        sharex=True,
        gridspec_kw={"height_ratios": [5, 0.6 + 0.35 * max(n_bars, 1)]},
    )
    cframe = pd.DataFrame(curves or [])
    colours0 = {"er": "C3", "fast": "C0", "medium": "C2", "slow": "C4"}
    if len(cframe):
        for (name, label), g in cframe.groupby(["curve", "branch_label"]):
            g = g.sort_values("k")
            ax.plot(
                g["k"],
                g["cot"],
                "-",
                color=colours0.get(label, "C5"),
                lw=2,
                alpha=0.35,
                label=f"{name} curve (two-parameter continuation)",
            )
    colours = {"er": "C3", "fast": "C0", "medium": "C2", "slow": "C4", "rigid": "k"}
    main = frame[
        (frame.model != "rigid")
        & ~frame.get("valid_part_only", pd.Series(False, index=frame.index)).fillna(False).astype(bool)
    ]
    for label, g in main.groupby("branch_label"):
        g = g.sort_values("k")
        name = "ER" if label == "er" else f"VE {label}"
        col = colours.get(label, "C5")
        # two gaits of one label at one k (found at different slopes): the line joins the least, markers show all
        least = g.loc[g.groupby("k")["cot"].idxmin()].sort_values("k")
        ax.plot(least["k"], least["cot"], ":", color=col, lw=1, label=f"{name} (sweep, located ends; line: least)")
        v = g[g.contact_valid]
        nv = g[~g.contact_valid]
        ax.plot(v["k"], v["cot"], "o", color=col, ms=6)
        ax.plot(nv["k"], nv["cot"], "o", mfc="white", color=col, ms=6)
    rg = frame[frame.model == "rigid"].sort_values("k")
    ax.plot(
        rg["k"], rg["cot"], "k--", label=f"rigid ({rg['critical_slope_deg'].iloc[0]:.3f} deg)" if len(rg) else "rigid"
    )
    for i, v in enumerate(ranges or []):
        col = colours.get(v["branch_label"], "C5")
        name = "ER" if v["model"] == "ER" else f"VE {v['branch_label']}"
        for side in ("low", "high"):
            if v.get(f"k_{side}_reason") in ("stance-force", "impulse"):
                ax.axvline(
                    v[f"k_{side}"],
                    color=col,
                    ls="-.",
                    lw=1,
                    label=f"{name} gait loses contact validity at k = {v[f'k_{side}']:.0f} ({v[f'k_{side}_reason']})",
                )
        lo, hi = v.get("k_low", math.nan), v.get("k_high", math.nan)
        if lo == lo and hi == hi:  # the branch's valid range in k at the start slope, a bar in the strip below
            strip.plot([lo, hi], [i, i], "-", color=col, lw=6, solid_capstyle="butt")
            strip.text(
                lo,
                i + 0.38,
                f"{name}: stable and contact-valid at {math.degrees(v['slope_rad']):.3f} deg for "
                f"k = {lo:.0f} ({v['k_low_reason']}) to {hi:.0f} ({v['k_high_reason']})",
                color=col,
                fontsize=7,
                va="center",
            )
    late = frame[frame["valid_part_only"].fillna(False).astype(bool)] if "valid_part_only" in frame else None
    if late is not None and len(late):
        for label, g in late.groupby("branch_label"):
            ax.plot(
                g["k"],
                g["cot"],
                "D",
                mfc="white",
                color=colours.get(label, "C5"),
                ms=6,
                label=f"VE {label}: invalid at the start slope, end of its valid part lower down",
            )
    ax.plot([], [], "o", color="0.4", label="contact-valid")
    ax.plot([], [], "o", mfc="white", color="0.4", label="violates unilateral contact")
    strip.set_ylim(-0.6, max(n_bars, 1) - 0.2)
    strip.set_yticks([])
    strip.set_xlabel("leg stiffness k (N/m)")
    strip.set_title("valid range of each branch in k (continuation in k at the start slope)", fontsize=8)
    ax.set_ylabel("CoT = tan(critical slope)")
    ax.set_title("cost of transport per gait branch")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    files = [save_figure(fig, out / "fig5_cot.png"), write_csv(frame, out / "fig5_cot.csv")]
    if len(cframe):
        files.append(write_csv(cframe, out / "fig5_boundary_curves.csv"))
    return files
