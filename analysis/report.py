"""The trials report: import (or read) trials, compare them with the simulation, write HTML + PNG + CSV.

``build_report(paths, out_dir)`` writes into ``out_dir``:

- ``report.html`` — one page, no scripts and no external resources; the figures are PNG files beside it,
  referenced by relative paths (copy or zip the folder to share it);
- ``com_height.png`` — measured vs simulated CoM height per trial (paper: "Comparison of experimental and
  simulated vertical CoM trajectories");
- ``step_period.png`` — step period vs step number, mean +- std over the trials of each slope bin, with the
  simulation (paper: "step-period trends");
- ``metrics.csv`` — one row per input (slope, steps, RMS CoM error, mean |period error|, fitted theta'+ ...).
"""

from __future__ import annotations

import csv
import html
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.errors import InputFileError, UserError

from .compare import Simulator, SlopeGroup, TrialComparison, compare_trial, step_period_trends

__all__ = ["ReportResult", "InputRow", "build_report", "load_input", "REPORT_FILES"]

REPORT_FILES = {"html": "report.html", "com": "com_height.png", "period": "step_period.png", "csv": "metrics.csv"}
METRIC_COLUMNS = ["trial", "file", "status", "slope_deg", "slope_source", "model", "steps", "rms_com_error_mm",
                  "mean_abs_period_error_ms", "theta_dot_plus_rad_s", "release_theta_dot_rad_s", "time_shift_ms",
                  "height_offset_mm", "message"]


@dataclass
class InputRow:
    """What became of one input file."""

    file: str
    kind: str  # "parquet" or "csv"
    status: str  # "imported", "read" or "refused"
    reason: str | None = None
    trial: Any = None
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        d: dict[str, Any] = {"file": self.file, "kind": self.kind, "status": self.status, "reason": self.reason,
                             "warnings": self.warnings}
        if self.trial is not None:
            m = self.trial.meta
            d.update(frames=m.n_frames, rate_hz=m.rate_hz, slope_deg=m.slope_deg, slope_source=m.slope_source,
                     hub_source=m.hub_source, gap_frames=m.n_gap_frames, interpolated_frames=m.n_interpolated_frames,
                     steps=int(self.trial.step_period_s.size))
        return d


@dataclass
class ReportResult:
    """Paths written and what they contain."""

    out_dir: Path
    report_html: Path
    metrics_csv: Path
    figures: list[Path]
    inputs: list[InputRow]
    comparisons: list[TrialComparison]
    groups: list[SlopeGroup]
    seconds: float = 0.0

    @property
    def refused(self) -> list[InputRow]:
        return [r for r in self.inputs if r.status == "refused"]

    def metrics(self) -> list[dict[str, Any]]:
        """metrics.csv rows: one per input (a refused file has status ``refused`` and the reason)."""
        rows = []
        by_file = {c.file: c for c in self.comparisons}
        for r in self.inputs:
            c = by_file.get(r.trial.meta.source_file) if r.trial is not None else None
            if c is not None:
                rows.append(c.metrics())
            else:
                rows.append({k: None for k in METRIC_COLUMNS} | {"trial": Path(r.file).name, "file": r.file,
                                                                "status": "refused", "message": r.reason})
        return rows

    def summary(self) -> dict[str, Any]:
        """The JSON summary of `rimless trials report --json`."""
        return {"report": str(self.report_html), "metrics_csv": str(self.metrics_csv),
                "figures": [str(p) for p in self.figures], "trials": self.metrics(),
                "inputs": [r.summary() for r in self.inputs],
                "step_period_by_slope": [row for g in self.groups for row in g.rows()],
                "refused": [r.file for r in self.refused]}


def _trial_warnings(trial: Any) -> list[str]:
    m = trial.meta
    w = list(m.notes)
    if m.step_refused:
        w.append(f"steps not detected: {m.step_refused}")
    if m.n_gap_frames:
        w.append(f"{m.n_gap_frames} frame(s) without a hub (gaps)")
    if m.n_interpolated_frames:
        w.append(f"{m.n_interpolated_frames} frame(s) interpolated over gaps up to {m.max_gap_s * 1e3:g} ms "
                 "(not used in the RMS)")
    return w


def load_input(path: Path, import_kwargs: dict[str, Any] | None = None) -> InputRow:
    """Read a Parquet trial, or import a Vicon CSV; a refused file gives status ``refused`` with the reason."""
    from .trial import import_trial, read_trial

    kind = "parquet" if path.suffix.lower() == ".parquet" else "csv"
    try:
        trial = read_trial(path) if kind == "parquet" else import_trial(path, **(import_kwargs or {}))
    except UserError as err:
        msg = str(err)
        return InputRow(str(path), kind, "refused", msg if str(path) in msg else f"{path}: {msg}")
    except OSError as err:
        return InputRow(str(path), kind, "refused", f"{path}: {err}")
    return InputRow(str(path), kind, "read" if kind == "parquet" else "imported", None, trial, _trial_warnings(trial))


def build_report(
    paths: Sequence[str | Path],
    out_dir: str | Path,
    *,
    sim: Simulator | None = None,
    import_kwargs: dict[str, Any] | None = None,
    slope_bin_deg: float = 0.5,
    title: str = "Vicon trials vs simulation",
    note: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> ReportResult:
    """Import/read every input, compare with the simulation and write the report files (see the module doc).

    Raises `InputFileError` before doing anything if an input does not exist; a file that exists but is
    refused by the importer is listed in the report (status ``refused``) and does not stop the others.
    ``progress`` is called once per input (with its name) after it is done.
    """
    t_start = time.perf_counter()
    files = [Path(p) for p in paths]
    if not files:
        raise InputFileError("no trial files given")
    missing = [str(p) for p in files if not p.is_file()]
    if missing:
        raise InputFileError(f"{', '.join(missing)}: no such file")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputFileError(f"{out}: cannot create the output folder ({err})") from None
    sim = sim or Simulator()
    inputs: list[InputRow] = []
    comps: list[TrialComparison] = []
    for p in files:
        row = load_input(p, import_kwargs)
        inputs.append(row)
        if row.trial is not None:
            comps.append(compare_trial(row.trial, sim, name=p.name))
        if progress:
            progress(p.name)
    groups = step_period_trends(comps, sim, slope_bin_deg=slope_bin_deg)
    com_png = _com_figure(comps, out / REPORT_FILES["com"])
    per_png = _period_figure(groups, out / REPORT_FILES["period"], sim.model)
    res = ReportResult(out, out / REPORT_FILES["html"], out / REPORT_FILES["csv"], [com_png, per_png], inputs, comps,
                       groups)
    _write_csv(res.metrics(), res.metrics_csv)
    res.seconds = time.perf_counter() - t_start
    res.report_html.write_text(_html(res, sim, title, note, slope_bin_deg), encoding="utf-8")
    return res


# ------------------------------------------------------------------------------------------------ figures


def _figure(w_in: float, h_in: float):  # noqa: ANN202
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _com_figure(comps: Sequence[TrialComparison], path: Path) -> Path:
    n = max(len(comps), 1)
    ncol = 2 if n > 1 else 1
    nrow = math.ceil(n / ncol)
    fig = _figure(6.0 * ncol, 2.6 * nrow + 0.4)
    fig.suptitle("CoM height: measured (dots) vs simulated (line); t = 0 at the first measured impact")
    for i in range(nrow * ncol):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        if i >= len(comps):
            ax.axis("off")
            if not comps:
                ax.text(0.5, 0.5, "no trial to compare", ha="center", va="center", transform=ax.transAxes)
            continue
        c = comps[i]
        if c.status != "ok":
            ax.text(0.5, 0.5, _wrap(f"{c.name}\n{c.message}", 70), ha="center", va="center", fontsize=8,
                    transform=ax.transAxes, color="firebrick")
            ax.set_xticks([])
            ax.set_yticks([])
            continue
        ax.plot(c.time_s, c.measured_com_m * 1e3, ".", ms=2.5, color="tab:blue", label="measured")
        lo, hi = np.nanmin(c.time_s), np.nanmax(c.time_s)
        m = (c.sim_time_s >= lo) & (c.sim_time_s <= hi)
        ax.plot(c.sim_time_s[m], c.sim_curve_m[m] * 1e3, "-", lw=1.2, color="tab:orange", label=f"simulated ({c.model.upper()})")
        for ti in c.measured_impact_time_s:
            ax.axvline(ti, color="0.85", lw=0.6, zorder=0)
        ax.set_title(f"{c.name}  |  {c.slope_deg:.2f} deg, RMS {c.rms_com_error_m * 1e3:.2f} mm", fontsize=8)
        ax.set_xlabel("time from first impact, s", fontsize=8)
        ax.set_ylabel("CoM height, mm", fontsize=8)
        ax.tick_params(labelsize=7)
        if i == 0:
            ax.legend(fontsize=7, loc="lower right")
    fig.savefig(path)
    return path


def _period_figure(groups: Sequence[SlopeGroup], path: Path, model: str = "er") -> Path:
    fig = _figure(7.0, 4.2)
    ax = fig.add_subplot(1, 1, 1)
    if not groups:
        ax.text(0.5, 0.5, "no trial with detected steps", ha="center", va="center", transform=ax.transAxes)
    colors = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:gray"]
    for j, g in enumerate(groups):
        col = colors[j % len(colors)]
        dx = (j - (len(groups) - 1) / 2) * 0.06
        std = np.where(np.isfinite(g.std_period_s), g.std_period_s, 0.0)
        ax.errorbar(g.step_number + dx, g.mean_period_s * 1e3, yerr=std * 1e3, fmt="o", ms=4, capsize=3, color=col,
                    label=f"measured {g.slope_deg:g} deg (n = {len(g.trials)})")
        if np.isfinite(g.sim_period_s).any():
            ax.plot(g.step_number, g.sim_period_s * 1e3, "--", color=col, lw=1.2, label=f"simulated {g.slope_deg:g} deg")
    ax.set_xlabel("step number (1 = first measured step)")
    ax.set_ylabel("step period, ms")
    ax.set_title(f"Step period vs step number: mean ± std over trials, and the {model.upper()} simulation")
    if groups:
        ax.legend(fontsize=8, ncol=2)
        ax.xaxis.get_major_locator().set_params(integer=True)
    fig.savefig(path)
    return path


def _wrap(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.fill(line, width) for line in text.splitlines())


# ------------------------------------------------------------------------------------------------- tables


def _write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=METRIC_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None or (isinstance(v, float) and not math.isfinite(v)) else
                            (f"{v:.6g}" if isinstance(v, float) else v)) for k, v in r.items()})


def _num(v: Any, fmt: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:2em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.5em;margin-bottom:.2em} h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0} th,td{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f3f3f3} td.n{text-align:right;font-variant-numeric:tabular-nums}
.ok{color:#1a7f37} .bad{color:#b42318} .note{background:#fff8e1;border-left:4px solid #f0b400;padding:.5em .8em}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #eee} figcaption{font-size:.85em;color:#555}
.small{font-size:.85em;color:#555}
"""


def _html(res: ReportResult, sim: Simulator, title: str, note: str | None, slope_bin_deg: float) -> str:
    e = html.escape
    p = sim.params
    rows = res.metrics()
    ok = [c for c in res.comparisons if c.status == "ok"]
    parts = [f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{e(title)}</title>",
             f"<style>{_CSS}</style></head><body>", f"<h1>{e(title)}</h1>",
             f"<p class=\"small\">rimless trials report, {time.strftime('%Y-%m-%d %H:%M')}; {len(res.inputs)} input(s), "
             f"{len(ok)} compared, {len(res.refused)} refused; built in {res.seconds:.1f} s.</p>"]
    if note:
        parts.append(f"<p class=\"note\">{e(note)}</p>")
    parts.append(
        "<p class=\"small\">Model: " + e(sim.model.upper()) + f" wheel, mass model {e(p.mass_model)}, m_H = {p.hub_mass_kg:g} kg, "
        f"m = {p.leg_mass_kg:g} kg, I_c = {p.inertia_kg_m2:g} kg m², L0 = {p.leg_length_m:g} m, k = {p.stiffness_n_per_m:g} N/m, "
        f"c = {p.damping_ns_per_m:g} N s/m; slope = each trial's (given or estimated); rtol = {sim.rtol:g}. "
        "Fitted per trial: the release speed θ' at the rigid-touchdown state θ = −α/2 one step before the first "
        "measured impact, so that the first simulated step period equals the first measured one; θ'+ is the "
        "simulated post-impact θ' at the first measured impact. The simulated curve is shifted by the lag (≤ 50 ms) "
        "minimising the RMS; heights measured from the impact line get the best constant offset.</p>")

    parts.append("<h2>CoM height</h2><figure>"
                 f"<img src=\"{REPORT_FILES['com']}\" alt=\"CoM height, measured vs simulated\">"
                 "<figcaption>Figure 1. Comparison of measured and simulated vertical CoM trajectories (hub height "
                 "normal to the slope); grey lines: measured impacts.</figcaption></figure>")
    parts.append("<h2>Step period</h2><figure>"
                 f"<img src=\"{REPORT_FILES['period']}\" alt=\"step period vs step number\">"
                 f"<figcaption>Figure 2. Step period vs step number, mean ± std over the trials of each slope bin "
                 f"(slopes rounded to {slope_bin_deg:g} deg), with the simulation at the bin's slope from the bin's "
                 "mean fitted release speed (dashed).</figcaption></figure>")

    parts.append("<h2>Metrics</h2><table id=\"metrics\"><thead><tr><th>trial</th><th>status</th><th>slope, deg</th>"
                 "<th>steps</th><th>RMS CoM error, mm</th><th>mean |period error|, ms</th><th>fitted θ'+, rad/s</th>"
                 "<th>release θ', rad/s</th><th>time shift, ms</th><th>message</th></tr></thead><tbody>")
    for r in rows:
        cls = "ok" if r["status"] == "ok" else "bad"
        parts.append(
            f"<tr class=\"trial\"><td>{e(str(r['trial']))}</td><td class=\"{cls}\">{e(str(r['status']))}</td>"
            f"<td class=\"n\">{_num(r['slope_deg'], '.3f')}</td><td class=\"n\">{_num(r['steps'], 'd')}</td>"
            f"<td class=\"n\">{_num(r['rms_com_error_mm'], '.2f')}</td>"
            f"<td class=\"n\">{_num(r['mean_abs_period_error_ms'], '.1f')}</td>"
            f"<td class=\"n\">{_num(r['theta_dot_plus_rad_s'], '.3f')}</td>"
            f"<td class=\"n\">{_num(r['release_theta_dot_rad_s'], '.3f')}</td>"
            f"<td class=\"n\">{_num(r['time_shift_ms'], '+.1f')}</td><td>{e(r['message'] or '')}</td></tr>")
    parts.append(f"</tbody></table><p class=\"small\">Also in <a href=\"{REPORT_FILES['csv']}\">{REPORT_FILES['csv']}</a>.</p>")

    if res.groups:
        parts.append("<h2>Step period by slope</h2><table id=\"periods\"><thead><tr><th>slope bin, deg</th><th>step</th>"
                     "<th>trials</th><th>mean, ms</th><th>std, ms</th><th>simulated, ms</th></tr></thead><tbody>")
        for g in res.groups:
            for row in g.rows():
                parts.append(f"<tr><td class=\"n\">{row['slope_deg']:g}</td><td class=\"n\">{row['step']}</td>"
                             f"<td class=\"n\">{row['trials']}</td><td class=\"n\">{_num(row['mean_period_ms'], '.1f')}</td>"
                             f"<td class=\"n\">{_num(row['std_period_ms'], '.1f')}</td>"
                             f"<td class=\"n\">{_num(row['sim_period_ms'], '.1f')}</td></tr>")
        parts.append("</tbody></table>")
        for g in res.groups:
            if g.message:
                parts.append(f"<p class=\"bad\">{g.slope_deg:g} deg: {e(g.message)}</p>")

    parts.append("<h2>Imported files</h2><table id=\"imports\"><thead><tr><th>file</th><th>status</th><th>frames</th>"
                 "<th>slope (source)</th><th>hub</th><th>steps</th><th>warnings / reason</th></tr></thead><tbody>")
    for r in res.inputs:
        s = r.summary()
        cls = "bad" if r.status == "refused" else "ok"
        if r.trial is not None:
            cells = (f"<td class=\"n\">{s['frames']} @ {s['rate_hz']:g} Hz</td>"
                     f"<td>{s['slope_deg']:.3f} deg ({e(s['slope_source'])})</td><td>{e(s['hub_source'])}</td>"
                     f"<td class=\"n\">{s['steps']}</td><td>{'<br>'.join(e(w) for w in r.warnings) or 'none'}</td>")
        else:
            cells = f"<td></td><td></td><td></td><td></td><td class=\"bad\">{e(r.reason or '')}</td>"
        parts.append(f"<tr><td>{e(r.file)}</td><td class=\"{cls}\">{e(r.status)}</td>{cells}</tr>")
    parts.append("</tbody></table></body></html>\n")
    return "\n".join(parts)
