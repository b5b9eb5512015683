"""Figures of the simulator. Compute first, plot second; every function accepts `ax`/returns the figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rimless.sim.gait import GaitTrajectory

PHASE_COLOURS = {"dlsp": "#f4cccc", "slsp_free": "#d9ead3", "slsp_clutched": "#cfe2f3"}
PHASE_LABELS = {"dlsp": "double support", "slsp_free": "single support, free", "slsp_clutched": "single support, clutched"}


def _shade_phases(ax, traj: GaitTrajectory) -> None:  # noqa: ANN001
    for step in traj.steps:
        for rec in step.phases:
            if rec.duration_s > 0:
                ax.axvspan(rec.t_start_s, rec.t_end_s, color=PHASE_COLOURS[rec.name], lw=0, zorder=0)


def plot_gait(traj: GaitTrajectory, path: str | Path | None = None):  # noqa: ANN201
    """Leg lengths, CoM height and wheel angle against time with the phases shaded (paper's typical gait)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    tab = traj.table
    t = tab["t_s"]
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True, constrained_layout=True)
    ax = axes[0]
    _shade_phases(ax, traj)
    ax.plot(t, tab["L1_m"] * 1e3, color="C0", label="stance leg L1")
    ax.plot(t, tab["L2_m"] * 1e3, color="C1", label="trailing leg L2", alpha=0.8)
    ax.axhline(traj.params.leg_length_m * 1e3, color="k", lw=0.6, ls=":")
    ax.set_ylabel("leg length (mm)")
    handles = ax.get_legend_handles_labels()[0] + [Patch(color=c, label=PHASE_LABELS[n]) for n, c in PHASE_COLOURS.items()
                                                  if traj.model == "er" or n != "slsp_clutched"]
    ax.legend(handles=handles, loc="lower right", fontsize=8, ncol=2)
    ax = axes[1]
    _shade_phases(ax, traj)
    ax.plot(t, tab["com_height_normal_m"] * 1e3, color="C2")
    ax.set_ylabel("CoM height normal\nto slope (mm)")
    ax = axes[2]
    _shade_phases(ax, traj)
    ax.plot(t, np.degrees(tab["theta_rad"]), color="C3", label="theta (deg)")
    ax2 = ax.twinx()
    ax2.plot(t, tab["dtheta_rad_s"], color="C4", label="theta' (rad/s)")
    ax.set_ylabel("theta (deg)", color="C3")
    ax2.set_ylabel("theta' (rad/s)", color="C4")
    ax.set_xlabel("time (s)")
    name = {"er": "energy-recycling", "ve": "viscoelastic"}[traj.model]
    fig.suptitle(f"{name} wheel, slope {traj.params.slope_deg:.3f} deg, k = {traj.params.k:g} N/m, "
                 f"c = {traj.params.c:g} N s/m ({len(traj.steps)} steps)")
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
