"""The report's figures (PNG at `DPI`, written through a temporary name): each trial's CoM height and step
periods against its simulation (`trial_figure`), every trial's CoM height on one page (`com_figure`), the step
period against step number per series and slope bin (`period_figure`, one panel per series: never pooled
across series; a bin's legend names how its trials ended when the report split them by it).

matplotlib's object API on the Agg canvas (no pyplot state); the PNG metadata hold matplotlib's name and
version only (no path, no title).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.inference.compare import TrialComparison

__all__ = ["DPI", "new_figure", "save_png", "com_figure", "period_figure", "trial_figure", "wrap"]

DPI = 150
COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:gray"]
#: the PNG text chunks: matplotlib's name only (savefig's default adds nothing else)
PNG_METADATA = {"Software": "rimless (matplotlib)"}


def new_figure(w_in: float, h_in: float, *, constrained: bool = True) -> Any:
    """A matplotlib Figure on the Agg canvas, ``w_in`` x ``h_in`` inches at `DPI`: with constrained layout, or
    none (the caller places the axes: `fixed_grid`; a third of the time, for the figures drawn once per trial)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=DPI, layout="constrained" if constrained else None)
    FigureCanvasAgg(fig)
    return fig


def fixed_grid(
    fig: Any,
    nrow: int,
    ncol: int,
    *,
    margins_in: tuple[float, float, float, float],
    gaps_in: tuple[float, float],
    **kw: Any,
) -> Any:
    """``nrow`` x ``ncol`` axes (array) placed with margins (left, right, top, bottom) and gaps (between columns,
    between rows) in inches, whatever the figure's size."""
    w, h = fig.get_size_inches()
    left, right, top, bottom = margins_in
    axes = fig.subplots(nrow, ncol, squeeze=False, **kw)
    aw = (w - left - right - gaps_in[0] * (ncol - 1)) / ncol
    ah = (h - top - bottom - gaps_in[1] * (nrow - 1)) / nrow
    fig.subplots_adjust(
        left=left / w,
        right=1 - right / w,
        top=1 - top / h,
        bottom=bottom / h,
        wspace=gaps_in[0] / aw,
        hspace=gaps_in[1] / ah,
    )
    return axes


def save_png(fig: Any, path: Path) -> None:
    """Write the PNG at DPI through a temporary name (a half-written figure never has the final name)."""
    tmp = path.with_name(path.stem + ".tmp.png")
    engine = fig.get_layout_engine()
    if engine is None:
        fig.savefig(tmp, dpi=DPI, metadata=PNG_METADATA)
    else:  # lay out once: savefig with a layout engine draws the whole figure twice (layout pass, then render)
        fig.draw_without_rendering()
        fig.set_layout_engine("none")
        try:
            fig.savefig(tmp, dpi=DPI, metadata=PNG_METADATA)
        finally:
            fig.set_layout_engine(engine)
    tmp.replace(path)


def wrap(text: str, width: int) -> str:
    """``text`` wrapped at ``width`` characters, line by line."""
    return "\n".join(textwrap.fill(line, width) for line in text.splitlines())


def _com_panel(ax: Any, c: TrialComparison, title: str) -> None:
    """Measured CoM height (dots) and the simulated curve over the measured span, impacts as grey lines."""
    ax.plot(c.time_s, c.measured_com_m * 1e3, ".", ms=2.5, color="tab:blue")
    lo, hi = np.nanmin(c.time_s), np.nanmax(c.time_s)
    m = (c.sim_time_s >= lo) & (c.sim_time_s <= hi)
    ax.plot(c.sim_time_s[m], c.sim_curve_m[m] * 1e3, "-", lw=1.2, color="tab:orange")
    for ti in c.measured_impact_time_s:
        ax.axvline(ti, color="0.85", lw=0.6, zorder=0)
    ax.set_title(title, fontsize=7, color="firebrick" if c.status == "suspect" else "black")
    ax.set_xlabel("time from first impact, s", fontsize=8)
    ax.set_ylabel("CoM height, mm", fontsize=8)
    ax.tick_params(labelsize=7)


def _com_title(c: TrialComparison, name: str) -> str:
    flag = "SUSPECT  " if c.status == "suspect" else ""
    return (
        f"{flag}{name}, {c.slope_deg:.2f} deg\nRMS {c.rms_com_error_m * 1e3:.2f} mm, "
        f"r {c.com_correlation:.2f}; fitted: shift {c.time_shift_s * 1e3:+.1f} ms, "
        f"offset {c.height_offset_m * 1e3:+.1f} mm"
    )


def _message_panel(ax: Any, text: str) -> None:
    ax.text(0.5, 0.5, wrap(text, 70), ha="center", va="center", fontsize=8, transform=ax.transAxes, color="firebrick")
    ax.set_xticks([])
    ax.set_yticks([])


def trial_figure(c: TrialComparison, path: Path, name: str, model: str = "er") -> Path:
    """One trial: CoM height measured vs simulated (left) and its step periods measured vs simulated (right)."""
    fig = new_figure(7.5, 2.6, constrained=False)
    ax, bx = fixed_grid(fig, 1, 2, margins_in=(0.55, 0.12, 0.45, 0.42), gaps_in=(0.65, 0.0), width_ratios=(1.6, 1.0))[0]
    if c.status == "failed":
        _message_panel(ax, f"{name}\n{c.message or 'not compared'}")
    else:
        _com_panel(ax, c, _com_title(c, name))
    steps = c.measured_step if c.measured_step.size == c.n_steps else np.arange(1, c.n_steps + 1)
    if c.n_steps:
        bx.plot(steps, c.measured_period_s * 1e3, "o", ms=4, color="tab:blue", label="measured")
        if c.sim_period_s.size == c.n_steps and np.isfinite(c.sim_period_s).any():
            bx.plot(steps, c.sim_period_s * 1e3, "s--", ms=3, lw=1.0, color="tab:orange", label=model.upper())
        bx.legend(fontsize=7, frameon=False)
        bx.xaxis.get_major_locator().set_params(integer=True)
    else:
        bx.text(0.5, 0.5, "no step periods", ha="center", va="center", fontsize=8, transform=bx.transAxes)
    bx.set_title("step period (step 1 fitted)", fontsize=7)
    bx.set_xlabel("step number", fontsize=8)
    bx.set_ylabel("step period, ms", fontsize=8)
    bx.tick_params(labelsize=7)
    save_png(fig, path)
    return path


def com_figure(comps: Sequence[TrialComparison], path: Path) -> Path:
    """Every trial's CoM height, measured vs simulated, two panels a row (one x-range per row)."""
    from matplotlib.lines import Line2D

    n = max(len(comps), 1)
    ncol = 2 if n > 1 else 1
    nrow = math.ceil(n / ncol)
    fig = new_figure(6.0 * ncol, 2.8 * nrow + 0.8, constrained=False)
    grid = fixed_grid(fig, nrow, ncol, margins_in=(0.6, 0.15, 0.8, 0.75), gaps_in=(0.65, 0.75)).ravel()
    fig.suptitle(
        "CoM height: measured (dots) vs simulated (line); t = 0 at the first measured impact",
        fontsize=10,
        y=1 - 0.08 / fig.get_size_inches()[1],
        va="top",
    )
    handles = [
        Line2D([], [], ls="", marker=".", color="tab:blue", label="measured (+ fitted height offset)"),
        Line2D([], [], color="tab:orange", label="simulated (fitted release, time-shifted)"),
        Line2D([], [], color="0.8", lw=0.8, label="measured impacts"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False)
    axes = list(grid)
    for i, ax in enumerate(axes):
        if i >= len(comps):
            ax.axis("off")
            if not comps:
                ax.text(0.5, 0.5, "no trial to compare", ha="center", va="center", transform=ax.transAxes)
            continue
        c = comps[i]
        if c.status == "failed":
            _message_panel(ax, f"{c.name}\n{c.message}")
            continue
        _com_panel(ax, c, _com_title(c, c.name))
    for r in range(nrow):  # one x-range per figure row
        row = [
            (axes[r * ncol + j], comps[r * ncol + j])
            for j in range(ncol)
            if r * ncol + j < len(comps) and comps[r * ncol + j].status != "failed"
        ]
        if row:
            hi = max(float(np.nanmax(c.time_s)) for _, c in row)
            lo = min(float(np.nanmin(c.time_s)) for _, c in row)
            for ax, _ in row:
                ax.set_xlim(lo, hi)
    save_png(fig, path)
    return path


def period_figure(groups: Sequence[Any], path: Path, model: str = "er") -> Path:
    """Step period against step number, mean +- std over the trials of each slope bin, one panel per series and
    release condition (``groups``: `rimless.analysis.report.series.SeriesSlopeGroup`, in series order), with the
    simulation."""
    panels = list(dict.fromkeys((getattr(g, "series", ""), getattr(g, "release", "")) for g in groups)) or [("", "")]
    fig = new_figure(7.0, 2.9 * len(panels) + 0.5)
    fig.suptitle(f"Step period: mean ± std over a slope bin's trials; dashed: {model.upper()} simulation", fontsize=9)
    axes = fig.subplots(len(panels), 1, squeeze=False)[:, 0]
    if not groups:
        axes[0].text(0.5, 0.5, "no trial with detected steps", ha="center", va="center", transform=axes[0].transAxes)
    for ax, (name, release) in zip(axes, panels):
        mine = [g for g in groups if (getattr(g, "series", ""), getattr(g, "release", "")) == (name, release)]
        for j, g in enumerate(mine):
            col = COLORS[j % len(COLORS)]
            dx = (j - (len(mine) - 1) / 2) * 0.06
            std = np.where(np.isfinite(g.std_period_s), g.std_period_s, 0.0)
            ax.errorbar(
                g.step_number + dx,
                g.mean_period_s * 1e3,
                yerr=std * 1e3,
                fmt="o",
                ms=4,
                capsize=3,
                color=col,
                label=f"measured {getattr(g, 'slope_label', f'{g.slope_deg:g}')} deg"
                + (f", {g.outcome}" if getattr(g, "outcome", "") else "")
                + f" (n = {len(g.trials)})",
            )
            if np.isfinite(g.sim_period_s).any():
                ax.plot(g.step_number, g.sim_period_s * 1e3, "--", color=col, lw=1.2)
        title = ", ".join([*([f"series {name}"] if name else []), *([release] if release else [])])
        ax.set_title(title, fontsize=8, loc="left")
        ax.set_xlabel("step number (1 = first measured step)", fontsize=8)
        ax.set_ylabel("step period, ms", fontsize=8)
        ax.tick_params(labelsize=7)
        if mine:
            ax.legend(fontsize=7, ncol=2, frameon=False)
            ax.xaxis.get_major_locator().set_params(integer=True)
    save_png(fig, path)
    return path
