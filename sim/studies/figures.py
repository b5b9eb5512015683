"""Figures of the simulator. Compute first, plot second; every function accepts `ax`/returns the figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rimless.sim.step.gait import GaitTrajectory

PHASE_COLOURS = {"dlsp": "#f4cccc", "slsp_free": "#d9ead3", "slsp_clutched": "#cfe2f3"}
PHASE_LABELS = {
    "dlsp": "double support",
    "slsp_free": "single support, free",
    "slsp_clutched": "single support, clutched",
}


def shade_phases(ax, traj: GaitTrajectory) -> None:
    """Shade each phase of every step of `traj` on `ax` (time axis in s) in its PHASE_COLOURS."""
    for step in traj.steps:
        for rec in step.phases:
            if rec.duration_s > 0:
                ax.axvspan(rec.t_start_s, rec.t_end_s, color=PHASE_COLOURS[rec.name], lw=0, zorder=0)


def save_figure(fig, path: str | Path, dpi: int = 150, *, option: str | None = None) -> Path:
    """Write the figure atomically (rimless.output.atomic_file; `option` names the CLI option in errors) and
    close it, also when writing fails."""
    import matplotlib.pyplot as plt

    from rimless.output import atomic_file

    path = Path(path)
    try:
        with atomic_file(path, option=option) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return path


def stick_diagram(traj: GaitTrajectory, ax, *, every_s: float = 0.025, step: int | None = None) -> None:
    """The wheel drawn every `every_s` seconds in the slope frame (x down the slope, y normal, mm): stance and
    trailing legs in the colour of the phase, the other legs grey, the hub as a dot."""
    from rimless.sim.model.mechanics import ALPHA

    tab = traj.table
    t = tab["t_s"]
    sel = np.ones(len(t), bool) if step is None else (tab["step"] == step)
    idx = np.flatnonzero(sel)
    if not len(idx):
        return
    L0 = traj.params.leg_length_m
    colours = {"dlsp": "#cc0000", "slsp_free": "#38761d", "slsp_clutched": "#0b5394"}
    next_t = t[idx[0]]
    for i in idx:
        if t[i] < next_t:
            continue
        next_t = t[i] + every_s
        th, xb, yb, L2 = tab["theta_rad"][i], tab["x_b_m"][i], tab["y_b_m"][i], tab["L2_m"][i]
        hx, hy = tab["hub_x_m"][i], tab["hub_y_m"][i]
        col = colours.get(str(tab["phase"][i]), "k")
        for j in range(2, 8):
            a = th + j * ALPHA
            ax.plot(
                [hx * 1e3, (hx - L0 * np.sin(a)) * 1e3], [hy * 1e3, (hy - L0 * np.cos(a)) * 1e3], color="0.8", lw=0.5
            )
        ax.plot([xb * 1e3, hx * 1e3], [yb * 1e3, hy * 1e3], color=col, lw=1.2)
        a = th + ALPHA
        ax.plot(
            [hx * 1e3, (hx - L2 * np.sin(a)) * 1e3],
            [hy * 1e3, (hy - L2 * np.cos(a)) * 1e3],
            color=col,
            lw=0.8,
            alpha=0.7,
        )
        ax.plot([hx * 1e3], [hy * 1e3], "o", color=col, ms=2)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x along the slope (mm)")
    ax.set_ylabel("y normal (mm)")
    from matplotlib.lines import Line2D

    names = [n for n in colours if traj.model == "er" or n != "slsp_clutched"]
    ax.legend(
        handles=[Line2D([], [], color=colours[n], label=PHASE_LABELS[n]) for n in names], fontsize=7, loc="upper right"
    )


def plot_forces(traj: GaitTrajectory, ax) -> None:
    """Normal ground reaction forces of the stance (leading) foot b and the trailing foot a, N, phases shaded."""
    tab = traj.table
    if "lambda_b_y_N" not in tab:
        raise ValueError("the trajectory has no forces: simulate with forces=True")
    shade_phases(ax, traj)
    t = tab["t_s"]
    ax.plot(t, tab["lambda_b_y_N"], color="C0", label="foot b (leading/stance) normal")
    ax.plot(t, tab["lambda_a_y_N"], color="C1", label="foot a (trailing) normal")
    ax.axhline(0.0, color="k", lw=0.8, ls="--")
    neg = np.where(np.nan_to_num(tab["lambda_b_y_N"], nan=1.0) < 0, tab["lambda_b_y_N"], np.nan)
    ax.plot(t, neg, color="red", lw=2, label="tensile (unphysical) transient")
    ax.set_ylabel("slope-normal GRF (N)")
    ax.legend(fontsize=7, loc="upper right")


def plot_gait(traj: GaitTrajectory, path: str | Path | None = None, *, forces: bool = False):
    """Leg lengths, CoM height and wheel angle against time with the phases shaded (paper's typical gait);
    with forces, also the normal ground reaction forces and a stick diagram of the first step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    tab = traj.table
    t = tab["t_s"]
    with_forces = forces and "lambda_b_y_N" in tab
    n = 5 if with_forces else 3
    fig = plt.figure(figsize=(9, 13 if with_forces else 8), constrained_layout=True)
    grid = fig.add_gridspec(n, 1, height_ratios=[1] * (n - 1) + ([1.3] if with_forces else [1]))
    axes = [fig.add_subplot(grid[0])]
    for i in range(1, 4 if with_forces else 3):
        axes.append(fig.add_subplot(grid[i], sharex=axes[0]))
    ax = axes[0]
    shade_phases(ax, traj)
    ax.plot(t, tab["L1_m"] * 1e3, color="C0", label="stance leg L1")
    ax.plot(t, tab["L2_m"] * 1e3, color="C1", label="trailing leg L2", alpha=0.8)
    ax.axhline(traj.params.leg_length_m * 1e3, color="k", lw=0.6, ls=":")
    ax.set_ylabel("leg length (mm)")
    handles = ax.get_legend_handles_labels()[0] + [
        Patch(color=c, label=PHASE_LABELS[n])
        for n, c in PHASE_COLOURS.items()
        if traj.model == "er" or n != "slsp_clutched"
    ]
    ax.legend(handles=handles, loc="lower right", fontsize=8, ncol=2)
    ax = axes[1]
    shade_phases(ax, traj)
    ax.plot(t, tab["com_height_normal_m"] * 1e3, color="C2")
    ax.set_ylabel("CoM height normal\nto slope (mm)")
    ax = axes[2]
    shade_phases(ax, traj)
    ax.plot(t, np.degrees(tab["theta_rad"]), color="C3", label="theta (deg)")
    ax2 = ax.twinx()
    ax2.plot(t, tab["dtheta_rad_s"], color="C4", label="theta' (rad/s)")
    ax.set_ylabel("theta (deg)", color="C3")
    ax2.set_ylabel("theta' (rad/s)", color="C4")
    if with_forces:
        plot_forces(traj, axes[3])
        axes[3].set_xlabel("time (s)")
        stick_diagram(traj, fig.add_subplot(grid[4]), step=0)
    else:
        ax.set_xlabel("time (s)")
    name = {"er": "energy-recycling", "ve": "viscoelastic"}[traj.model]
    fig.suptitle(
        f"{name} wheel, slope {traj.params.slope_deg:.3f} deg, k = {traj.params.k:g} N/m, "
        f"c = {traj.params.c:g} N s/m ({len(traj.steps)} steps)"
    )
    if path is not None:
        save_figure(fig, path)
    return fig
