"""The trials report: import (or read) trials, compare them with the simulation, write HTML + PNG + CSV.

``build_report(paths, out_dir)`` writes into ``out_dir``:

- ``report.html`` — one page, no scripts and no external resources; the figures are PNG files beside it,
  referenced by relative paths (copy or zip the folder to share it);
- ``com_height.png`` — measured vs simulated CoM height per trial (paper: "Comparison of experimental and
  simulated vertical CoM trajectories");
- ``step_period.png`` — step period vs step number, mean +- std over the trials of each slope bin, with the
  simulation (paper: "step-period trends");
- ``metrics.csv`` — one row per input (slope, steps, RMS CoM error, mean |period error|, fitted theta'+ ...);
- ``critical_slope.png`` (when asked, default on) — verdicts (sustained / decaying / undetermined) against
  slope, the fitted probability of sustained walking, the bracket and the model's critical slopes.
"""

from __future__ import annotations

import contextlib
import csv
import html
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.inference.background import Background, background_allowed
from rimless.analysis.inference.compare import Simulator, SlopeGroup, TrialComparison, compare_trial, step_period_trends
from rimless.analysis.io.robot_log import read_clutch_log
from rimless.analysis.kinematics.inputs import InputRow, load_input
from rimless.analysis.report.calibration_beside import (
    calibration_args,
    one_blas_thread,
    prepared_calibration,
    start_calibration,
)
from rimless.analysis.report.clutch import clutch_comparison, clutch_html
from rimless.errors import InputFileError

__all__ = ["ReportResult", "InputRow", "build_report", "load_input", "REPORT_FILES"]

REPORT_FILES = {
    "html": "report.html",
    "com": "com_height.png",
    "period": "step_period.png",
    "csv": "metrics.csv",
    "critical": "critical_slope.png",
}
DPI = 150
METRIC_COLUMNS = [
    "trial",
    "file",
    "status",
    "slope_deg",
    "slope_source",
    "model",
    "steps",
    "rms_com_error_mm",
    "mean_abs_period_error_ms",
    "rms_com_relative",
    "com_correlation",
    "theta_dot_plus_rad_s",
    "release_theta_dot_rad_s",
    "time_shift_ms",
    "height_offset_mm",
    "message",
]


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
    critical: Any = None  # rimless.analysis.inference.critical_slope.CriticalSlopeResult, when computed
    calibration: Any = None  # rimless.analysis.inference.calibrate.CalibrationResult, when computed
    #: per trial name (input file name): the robot log's measured clutched time per step beside the simulated one
    #: (`clutch_comparison`), when a robot trial log was given with the trial
    clutch: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: every wheel parameter's value, sd, unit and source (`rimless.sim.model.uncertain.WheelInput.parameters`)
    parameters: list[dict[str, Any]] | None = None

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
                rows.append(
                    {k: None for k in METRIC_COLUMNS}
                    | {"trial": Path(r.file).name, "file": r.file, "status": "refused", "message": r.reason}
                )
        return rows

    def __repr__(self) -> str:
        ok = sum(c.status == "ok" for c in self.comparisons)
        return (
            f"ReportResult({self.report_html}: {len(self.comparisons)} trial(s) compared, {ok} ok, "
            f"{len(self.refused)} refused; .summary())"
        )

    def to_dict(self) -> dict[str, Any]:
        """`summary()`: the JSON object of `rimless trials report --json`."""
        return self.summary()

    def summary(self) -> dict[str, Any]:
        """The JSON summary of `rimless trials report --json`."""
        return {
            "report": str(self.report_html),
            "metrics_csv": str(self.metrics_csv),
            "figures": [str(p) for p in self.figures],
            "trials": self.metrics(),
            "inputs": [r.summary() for r in self.inputs],
            "step_period_by_slope": [row for g in self.groups for row in g.rows()],
            "refused": [r.file for r in self.refused],
            "critical_slope": self.critical.summary() if self.critical is not None else None,
            "calibration": self.calibration.summary() if self.calibration is not None else None,
            "clutch_time_per_step": self.clutch,
            "parameters": self.parameters,
        }


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
    critical: bool = True,
    calibrate_c: bool = False,
    critical_files: Sequence[str | Path] | None = None,
    robot_logs: dict[str, Path] | None = None,
    wheel_input: Any = None,
) -> ReportResult:
    """Import/read every input, compare with the simulation and write the report files (see the module doc).

    Raises `InputFileError` before doing anything if an input does not exist; a file that exists but is
    refused by the importer is listed in the report (status ``refused``) and does not stop the others.
    ``progress`` is called once per input (with its name) after it is done, and once per later stage.
    ``critical``: add the critical slope from the trials (verdicts, estimates, the model's value);
    ``calibrate_c`` also calibrates c on them and gives the calibrated model's critical slope;
    ``critical_files``: only these inputs enter the critical slope (default: every input with steps);
    ``robot_logs``: input file name -> the robot's trial log of that trial (`clutch_comparison`);
    ``wheel_input``: the wheel's parameters with their uncertainties (`rimless.sim.model.uncertain.WheelInput`,
    default ``sim.params`` with the default uncertainties), listed and carried into the critical slopes
    (`rimless.analysis.inference.held`).
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
    from rimless.sim.model.uncertain import default_wheel_input

    win = wheel_input if wheel_input is not None else default_wheel_input(sim.params)
    beside = critical and calibrate_c and background_allowed()
    # two processes on the cores: BLAS threads here would wait for a core (warm demo 13.0-14.5 s, 14.5-18.5 s)
    with one_blas_thread() if beside else contextlib.nullcontext():
        res = _compare_and_report(
            files,
            out,
            sim,
            import_kwargs,
            slope_bin_deg,
            critical,
            critical and calibrate_c,
            critical_files,
            robot_logs,
            progress,
            win,
        )
    res.parameters = win.parameters()
    res.seconds = time.perf_counter() - t_start
    _write_text(res.report_html, _html(res, sim, title, note, slope_bin_deg))
    return res


def _compare_and_report(
    files: Sequence[Path],
    out: Path,
    sim: Simulator,
    import_kwargs: dict[str, Any] | None,
    slope_bin_deg: float,
    critical: bool,
    calibrate_c: bool,
    critical_files: Sequence[str | Path] | None,
    robot_logs: dict[str, Path] | None,
    progress: Callable[[str], None] | None,
    win: Any,
) -> ReportResult:
    """Import, compare (the calibration of c in a second process meanwhile, when asked), then the rest."""
    calibrating: Background | None = prepared_calibration(sim.params) if calibrate_c else None
    try:
        inputs: list[InputRow] = [load_input(p, import_kwargs) for p in files]
        if calibrating is not None:  # started (imports, kernels) while the files loaded
            calibrating.submit(
                *calibration_args(sim.params, sim.model, *_critical_inputs(files, inputs, critical_files))
            )
        comps: list[TrialComparison] = []
        for p, row in zip(files, inputs):
            if row.trial is not None:
                comps.append(compare_trial(row.trial, sim, name=p.name))
                if calibrate_c and calibrating is None:  # a cold cache: compiled once, by that comparison
                    calibrating = start_calibration(
                        sim.params, sim.model, *_critical_inputs(files, inputs, critical_files)
                    )
                    calibrate_c = calibrating is not None
            if progress:
                progress(p.name)
        return _rest_of_report(
            files,
            out,
            sim,
            inputs,
            comps,
            slope_bin_deg,
            critical,
            critical_files,
            calibrating,
            robot_logs,
            progress,
            win,
        )
    finally:
        if calibrating is not None:
            calibrating.close()


def _rest_of_report(
    files: Sequence[Path],
    out: Path,
    sim: Simulator,
    inputs: list[InputRow],
    comps: list[TrialComparison],
    slope_bin_deg: float,
    critical: bool,
    critical_files: Sequence[str | Path] | None,
    calibrating: Background | None,
    robot_logs: dict[str, Path] | None,
    progress: Callable[[str], None] | None,
    win: Any,
) -> ReportResult:
    """The report after the comparisons: trends, clutch logs, figures, the critical slope, metrics.csv."""
    groups = step_period_trends(comps, sim, slope_bin_deg=slope_bin_deg)
    clutch = {}
    for name, log in (robot_logs or {}).items():
        comp = next((c for c in comps if c.name == name), None)
        clutch[name] = clutch_comparison(read_clutch_log(log), comp)
    com_png = _com_figure(comps, out / REPORT_FILES["com"])
    per_png = _period_figure(groups, out / REPORT_FILES["period"], sim.model)
    res = ReportResult(
        out,
        out / REPORT_FILES["html"],
        out / REPORT_FILES["csv"],
        [com_png, per_png],
        inputs,
        comps,
        groups,
        clutch=clutch,
    )
    if critical:
        _add_critical(res, sim, *_critical_inputs(files, inputs, critical_files), calibrating, progress, win)
    if res.calibration is None and all_suspect(res):
        _calibrate_for_misfit(res, sim, progress)
    _write_csv(res.metrics(), res.metrics_csv)
    return res


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def _calibrate_for_misfit(res: ReportResult, sim: Simulator, progress: Callable[[str], None] | None) -> None:
    """Every trial suspect: calibrate c on the compared trials, for the comparison shown beside Table 1."""
    from rimless.analysis.inference.calibrate import NoTrialCalibrated, calibrate

    names = [c.name for c in res.comparisons if c.status in ("ok", "suspect")]
    pairs = [
        (row.trial, row.file)
        for row in res.inputs
        if row.trial is not None and row.trial.step_period_s.size > 0 and Path(row.file).name in names
    ]
    if not pairs:
        return
    try:
        res.calibration = calibrate(
            [t for t, _ in pairs], [n for _, n in pairs], ["c"], params=sim.params, model=sim.model
        )
    except NoTrialCalibrated:
        res.calibration = None
    if progress:
        progress("calibration of c (every trial suspect)")


def _critical_inputs(
    files: Sequence[Path], inputs: Sequence[InputRow], only: Sequence[str | Path] | None
) -> tuple[list[Any], list[str]]:
    """The trials (with steps) and their file names that enter the critical slope: every one, or ``only``."""
    keep = {Path(p).resolve() for p in only} if only is not None else None
    trials, names = [], []
    for p, row in zip(files, inputs):
        if row.trial is None or row.trial.step_period_s.size == 0:
            continue
        if keep is not None and p.resolve() not in keep:
            continue
        trials.append(row.trial)
        names.append(row.file)
    return trials, names


def _add_critical(
    res: ReportResult,
    sim: Simulator,
    trials: list[Any],
    names: list[str],
    calibrating: Background | None,
    progress: Callable[[str], None] | None,
    win: Any,
) -> None:
    """The critical slope from ``trials``, the model's at ``sim.params`` with the held parameters of ``win``
    carried (`rimless.analysis.inference.held`), and with ``calibrating`` (the calibration of c started beside
    the comparisons) the calibration and the calibrated model's."""
    from rimless.analysis.inference.critical_slope import add_calibrated_model, run_critical_slope
    from rimless.analysis.inference.held import carry_critical

    if not trials:
        return
    res.critical = run_critical_slope(trials, names, sim.params, models=(sim.model,))
    # the held parameters' runs while the calibration goes on beside (they need only the model's critical slope);
    # the models by forward differences: half the runs
    carry_critical(res.critical, trials, names, win, models=(sim.model,), progress=progress, central_models=False)
    if calibrating is not None:
        res.calibration = calibrating.result()
        if progress:
            progress("calibration of c")
        if res.calibration is not None:
            add_calibrated_model(res.critical, res.calibration.calibrated_params, models=(sim.model,))
    if progress:
        progress("critical slope")
    res.figures.append(_critical_figure(res.critical, res.out_dir / REPORT_FILES["critical"]))


# ------------------------------------------------------------------------------------------------ figures


def _figure(w_in: float, h_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: Path) -> None:
    """Write the PNG at DPI through a temporary name (a half-written figure never has the final name)."""
    tmp = path.with_name(path.stem + ".tmp.png")
    engine = fig.get_layout_engine()
    if engine is None:
        fig.savefig(tmp, dpi=DPI)
    else:  # lay out once: savefig with a layout engine draws the whole figure twice (layout pass, then render)
        fig.draw_without_rendering()
        fig.set_layout_engine("none")
        try:
            fig.savefig(tmp, dpi=DPI)
        finally:
            fig.set_layout_engine(engine)
    tmp.replace(path)


def _com_figure(comps: Sequence[TrialComparison], path: Path) -> Path:
    from matplotlib.lines import Line2D

    n = max(len(comps), 1)
    ncol = 2 if n > 1 else 1
    nrow = math.ceil(n / ncol)
    fig = _figure(6.0 * ncol, 2.8 * nrow + 0.8)
    fig.suptitle("CoM height: measured (dots) vs simulated (line); t = 0 at the first measured impact", fontsize=10)
    handles = [
        Line2D([], [], ls="", marker=".", color="tab:blue", label="measured (+ fitted height offset)"),
        Line2D([], [], color="tab:orange", label="simulated (fitted release, time-shifted)"),
        Line2D([], [], color="0.8", lw=0.8, label="measured impacts"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    axes = []
    for i in range(nrow * ncol):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        axes.append(ax)
        if i >= len(comps):
            ax.axis("off")
            if not comps:
                ax.text(0.5, 0.5, "no trial to compare", ha="center", va="center", transform=ax.transAxes)
            continue
        c = comps[i]
        if c.status == "failed":
            ax.text(
                0.5,
                0.5,
                _wrap(f"{c.name}\n{c.message}", 70),
                ha="center",
                va="center",
                fontsize=8,
                transform=ax.transAxes,
                color="firebrick",
            )
            ax.set_xticks([])
            ax.set_yticks([])
            continue
        ax.plot(c.time_s, c.measured_com_m * 1e3, ".", ms=2.5, color="tab:blue")
        lo, hi = np.nanmin(c.time_s), np.nanmax(c.time_s)
        m = (c.sim_time_s >= lo) & (c.sim_time_s <= hi)
        ax.plot(c.sim_time_s[m], c.sim_curve_m[m] * 1e3, "-", lw=1.2, color="tab:orange")
        for ti in c.measured_impact_time_s:
            ax.axvline(ti, color="0.85", lw=0.6, zorder=0)
        flag = "SUSPECT  " if c.status == "suspect" else ""
        ax.set_title(
            f"{flag}{c.name}, {c.slope_deg:.2f} deg\nRMS {c.rms_com_error_m * 1e3:.2f} mm, "
            f"r {c.com_correlation:.2f}; fitted: shift {c.time_shift_s * 1e3:+.1f} ms, "
            f"offset {c.height_offset_m * 1e3:+.1f} mm",
            fontsize=7,
            color="firebrick" if c.status == "suspect" else "black",
        )
        ax.set_xlabel("time from first impact, s", fontsize=8)
        ax.set_ylabel("CoM height, mm", fontsize=8)
        ax.tick_params(labelsize=7)
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
    _save(fig, path)
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
        ax.errorbar(
            g.step_number + dx,
            g.mean_period_s * 1e3,
            yerr=std * 1e3,
            fmt="o",
            ms=4,
            capsize=3,
            color=col,
            label=f"measured {g.slope_deg:g} deg (n = {len(g.trials)})",
        )
        if np.isfinite(g.sim_period_s).any():
            ax.plot(
                g.step_number, g.sim_period_s * 1e3, "--", color=col, lw=1.2, label=f"simulated {g.slope_deg:g} deg"
            )
    ax.set_xlabel("step number (1 = first measured step)")
    ax.set_ylabel("step period, ms")
    ax.set_title(f"Step period vs step number: mean ± std over trials, and the {model.upper()} simulation")
    if groups:
        ax.legend(fontsize=8, ncol=2)
        ax.xaxis.get_major_locator().set_params(integer=True)
    _save(fig, path)
    return path


def model_label(key: str, calibrated_text: str = "calibrated on these trials") -> str:
    """``er`` -> ``ER``; ``er_calibrated`` -> ``ER calibrated on these trials (fitted, not a prediction)``."""
    if key.endswith("_calibrated"):
        return f"{key.removesuffix('_calibrated').upper()} {calibrated_text} (fitted, not a prediction)"
    return key.upper()


def all_suspect(res: ReportResult) -> bool:
    """Every compared trial is suspect against the model's parameters (and at least one was compared)."""
    compared = [c for c in res.comparisons if c.status in ("ok", "suspect")]
    return bool(compared) and all(c.status == "suspect" for c in compared)


def _critical_figure(cr: Any, path: Path) -> Path:
    """Verdicts against slope, the logistic P(sustained), the bracket, the estimates and the model's values."""
    fig = _figure(9.0, 4.4)
    ax = fig.add_subplot(1, 1, 1)
    decided = [r["slope_deg"] for r in cr.per_trial if r["verdict"] != "undetermined"]
    ref = decided + [e.value_deg for e in cr.estimates]
    x_lo, x_hi = (min(ref) - 0.15, max(ref) + 0.15) if ref else (0.0, 3.0)
    levels = {"sustained": 1.0, "undetermined": 0.5, "decaying": 0.0}
    colors = {"sustained": "tab:green", "undetermined": "goldenrod", "decaying": "tab:red"}
    slopes = [r["slope_deg"] for r in cr.per_trial]
    rng = np.random.default_rng(0)
    for verdict, y in levels.items():
        xs = [r["slope_deg"] for r in cr.per_trial if r["verdict"] == verdict]
        inside = [x for x in xs if x_lo <= x <= x_hi]
        if xs:
            more = f", {len(xs) - len(inside)} outside the plotted slopes" if len(inside) < len(xs) else ""
            rows_in = [r for r in cr.per_trial if r["verdict"] == verdict and x_lo <= r["slope_deg"] <= x_hi]
            xerr = np.array(
                [
                    [r["slope_deg"] - r["slope_ci_deg"][0], r["slope_ci_deg"][1] - r["slope_deg"]]
                    if r.get("slope_ci_deg")
                    else [0.0, 0.0]
                    for r in rows_in
                ]
            ).T.reshape(2, -1)
            ax.errorbar(
                inside,
                y + rng.uniform(-0.025, 0.025, len(inside)),
                xerr=xerr,
                fmt="o",
                ms=6,
                mfc="none",
                mew=1.5,
                elinewidth=1.0,
                capsize=2,
                color=colors[verdict],
                label=f"{verdict} ({len(xs)}{more}); bars: 95 % slope interval",
            )
    x_all = [x_lo, x_hi]
    if cr.bracket_deg:
        ax.axvspan(
            *cr.bracket_deg, color="0.9", zorder=0, label=f"bracket {cr.bracket_deg[0]:.2f}-{cr.bracket_deg[1]:.2f} deg"
        )
    if cr.logistic is not None and slopes:
        b0, b1 = cr.logistic
        xx = np.linspace(x_lo - 0.2, x_hi + 0.2, 300)
        ax.plot(xx, 1.0 / (1.0 + np.exp(-(b0 + b1 * xx))), "-", color="tab:blue", lw=1.2, label="logistic P(sustained)")
    styles = {"bracket": ":", "logistic": "-.", "fixed-point-extrapolation": "--"}
    for e in cr.estimates:
        lw = 2.0 if e is cr.chosen else 1.0
        ax.axvline(
            e.value_deg,
            ls=styles.get(e.method, "-"),
            color="black",
            lw=lw,
            label=f"{e.method}: {e.value_deg:.3f} deg" + (" (reported)" if e is cr.chosen else ""),
        )
        x_all.append(e.value_deg)
    model_cols = ["tab:purple", "tab:brown", "tab:pink", "tab:cyan"]
    for j, (m, v) in enumerate(cr.model.get("critical_slope_deg", {}).items()):
        if v is not None and math.isfinite(v):
            ax.axvline(
                v,
                color=model_cols[j % 4],
                lw=1.5,
                ls="--" if m.endswith("_calibrated") else "-",
                label=f"model {model_label(m)}: {v:.3f} deg",
            )
            x_all.append(v)
    ax.set_xlim(min(x_all) - 0.05, max(x_all) + 0.05)
    ax.set_ylim(-0.1, 1.1)
    ax.set_yticks([0, 0.5, 1], ["decaying", "undetermined", "sustained"])
    ax.set_xlabel("slope, deg")
    ax.set_title("Critical slope: verdict of each trial from its step-to-step return map", fontsize=10)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    _save(fig, path)
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
            w.writerow(
                {
                    k: (
                        ""
                        if v is None or (isinstance(v, float) and not math.isfinite(v))
                        else (f"{v:.6g}" if isinstance(v, float) else v)
                    )
                    for k, v in r.items()
                }
            )


def _num(v: Any, fmt: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:2em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.5em;margin-bottom:.2em} h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0;max-width:100%} th,td{overflow-wrap:anywhere;border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f3f3f3} td.n{text-align:right;font-variant-numeric:tabular-nums}
.ok{color:#1a7f37} .bad{color:#b42318} .suspect{color:#b54708;font-weight:bold} .note{background:#fff8e1;border-left:4px solid #f0b400;padding:.5em .8em}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #eee} figcaption{font-size:.85em;color:#555}
.small{font-size:.85em;color:#555}
"""


def _html(res: ReportResult, sim: Simulator, title: str, note: str | None, slope_bin_deg: float) -> str:
    e = html.escape
    p = sim.params
    rows = res.metrics()
    ok = [c for c in res.comparisons if c.status in ("ok", "suspect")]
    n_suspect = sum(c.status == "suspect" for c in res.comparisons)
    parts = [
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>',
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{e(title)}</h1>",
        f'<p class="small">rimless trials report, {time.strftime("%Y-%m-%d %H:%M")}; {len(res.inputs)} input(s), '
        f"{len(ok)} compared ({n_suspect} suspect), {len(res.refused)} refused; built in {res.seconds:.1f} s.</p>",
    ]
    if note:
        parts.append(f'<p class="note">{e(note)}</p>')
    if all_suspect(res):
        parts.append(_misfit_html(res))
    parts.append(
        '<p class="small">Model: '
        + e(sim.model.upper())
        + f" wheel, mass model {e(p.mass_model)}, m_H = {p.hub_mass_kg:g} kg, "
        f"m = {p.leg_mass_kg:g} kg, I_c = {p.inertia_kg_m2:g} kg m², L0 = {p.leg_length_m:g} m, k = {p.stiffness_n_per_m:g} N/m, "
        f"c = {p.damping_ns_per_m:g} N s/m; slope = each trial's (given or estimated); rtol = {sim.rtol:g}. "
        "Fitted per trial: the release speed θ' at the rigid-touchdown state θ = −α/2 one step before the first "
        "measured impact, so that the first simulated step period equals the first measured one; θ'+ is the "
        "simulated post-impact θ' at the first measured impact. The simulated curve is shifted by the lag (≤ 50 ms) "
        "minimising the RMS; heights measured from the impact line get the best constant offset.</p>"
    )

    if res.clutch:
        parts.append(clutch_html(res.clutch))
    parts.append(
        "<h2>CoM height</h2><figure>"
        f'<img src="{REPORT_FILES["com"]}" alt="CoM height, measured vs simulated">'
        "<figcaption>Figure 1. Comparison of measured and simulated vertical CoM trajectories (hub height "
        "normal to the slope); grey lines: measured impacts. <b>Fitted per trial</b> (values in each panel's "
        "title and in the table): the release speed θ' (so that the first simulated period equals the "
        "first measured one), a time shift of the simulated curve (≤ 50 ms) and a constant height offset of "
        "the measured curve (heights measured from the impact line). Each trial is simulated at its own "
        "slope. r: correlation of the two curves; a trial failing a plausibility check is marked SUSPECT."
        + _fitted_list(res.comparisons)
        + "</figcaption></figure>"
    )
    parts.append(
        "<h2>Step period</h2><figure>"
        f'<img src="{REPORT_FILES["period"]}" alt="step period vs step number">'
        f"<figcaption>Figure 2. Step period vs step number, mean ± std over the trials of each slope bin "
        f"(slopes rounded to {slope_bin_deg:g} deg), with the simulation (dashed): each trial simulated at "
        "its own slope from its own fitted release speed, averaged over the bin. Step 1 is fitted (the "
        "release speed is chosen to match it), so it agrees by construction and is left out of the period "
        "errors.</figcaption></figure>"
    )

    parts.append(
        '<h2>Metrics</h2><table id="metrics"><thead><tr><th>trial</th><th>status</th><th>slope, deg</th>'
        "<th>steps</th><th>RMS CoM error, mm</th><th>RMS / amplitude</th><th>r</th>"
        "<th>mean |period error|, steps 2..N, ms</th><th>fitted θ'+, rad/s</th>"
        "<th>fitted release θ', rad/s</th><th>fitted time shift, ms</th><th>fitted height offset, mm</th>"
        "<th>message</th></tr></thead><tbody>"
    )
    for r in rows:
        cls = "ok" if r["status"] == "ok" else ("suspect" if r["status"] == "suspect" else "bad")
        parts.append(
            f'<tr class="trial"><td>{e(str(r["trial"]))}</td><td class="{cls}">{e(str(r["status"]))}</td>'
            f'<td class="n">{_num(r["slope_deg"], ".3f")}</td><td class="n">{_num(r["steps"], "d")}</td>'
            f'<td class="n">{_num(r["rms_com_error_mm"], ".2f")}</td>'
            f'<td class="n">{_num(r.get("rms_com_relative"), ".2f")}</td>'
            f'<td class="n">{_num(r.get("com_correlation"), ".3f")}</td>'
            f'<td class="n">{_num(r["mean_abs_period_error_ms"], ".1f")}</td>'
            f'<td class="n">{_num(r["theta_dot_plus_rad_s"], ".3f")}</td>'
            f'<td class="n">{_num(r["release_theta_dot_rad_s"], ".3f")}</td>'
            f'<td class="n">{_num(r["time_shift_ms"], "+.1f")}</td>'
            f'<td class="n">{_num(r["height_offset_mm"], "+.1f")}</td><td>{e(r["message"] or "")}</td></tr>'
        )
    parts.append(
        f'</tbody></table><p class="small">Also in <a href="{REPORT_FILES["csv"]}">{REPORT_FILES["csv"]}</a>.</p>'
    )

    if res.groups:
        parts.append(
            '<h2>Step period by slope</h2><table id="periods"><thead><tr><th>slope bin, deg</th><th>step</th>'
            "<th>trials</th><th>mean, ms</th><th>std, ms</th><th>simulated, ms</th></tr></thead><tbody>"
        )
        for g in res.groups:
            for row in g.rows():
                parts.append(
                    f'<tr><td class="n">{row["slope_deg"]:g}</td><td class="n">{row["step"]}</td>'
                    f'<td class="n">{row["trials"]}</td><td class="n">{_num(row["mean_period_ms"], ".1f")}</td>'
                    f'<td class="n">{_num(row["std_period_ms"], ".1f")}</td>'
                    f'<td class="n">{_num(row["sim_period_ms"], ".1f")}</td></tr>'
                )
        parts.append("</tbody></table>")
        for g in res.groups:
            if g.message:
                parts.append(f'<p class="bad">{g.slope_deg:g} deg: {e(g.message)}</p>')

    if res.critical is not None:
        parts.append(_critical_html(res))

    parts.append(
        '<h2>Imported files</h2><table id="imports"><thead><tr><th>file</th><th>status</th><th>frames</th>'
        "<th>slope (source)</th><th>hub</th><th>steps</th><th>warnings / reason</th></tr></thead><tbody>"
    )
    for inp in res.inputs:
        s = inp.summary()
        cls = "bad" if inp.status == "refused" else "ok"
        if inp.trial is not None:
            cells = (
                f'<td class="n">{s["frames"]} @ {s["rate_hz"]:g} Hz</td>'
                f"<td>{s['slope_deg']:.3f} deg ({e(s['slope_source'])})</td><td>{e(s['hub_source'])}</td>"
                f'<td class="n">{s["steps"]}</td><td>{"<br>".join(e(w) for w in inp.warnings) or "none"}</td>'
            )
        else:
            cells = f'<td></td><td></td><td></td><td></td><td class="bad">{e(inp.reason or "")}</td>'
        parts.append(f'<tr><td>{e(inp.file)}</td><td class="{cls}">{e(inp.status)}</td>{cells}</tr>')
    parts.append("</tbody></table></body></html>\n")
    return "\n".join(parts)


def _fitted_list(comps: Sequence[TrialComparison]) -> str:
    items = [
        f"{html.escape(c.name)}: θ' = {c.release_theta_dot_rad_s:.3f} rad/s, shift {c.time_shift_s * 1e3:+.1f} ms, "
        f"offset {c.height_offset_m * 1e3:+.1f} mm"
        for c in comps
        if c.status != "failed"
    ]
    return (" Fitted values: " + "; ".join(items) + ".") if items else ""


def _misfit_html(res: ReportResult) -> str:
    """Every trial suspect: the model's parameters do not fit these trials; the calibrated comparison beside."""
    e = html.escape
    out = [
        '<p class="bad" id="model-misfit"><b>The model\'s parameters do not fit these trials</b>: every '
        "compared trial is suspect against them. The per-trial numbers below compare the data with a model that "
        "does not describe this wheel; the comparison with the model calibrated on these trials is beside "
        "them.</p>"
    ]
    cal = res.calibration
    if cal is None:
        out.append(
            '<p class="small">No calibration could be made on these trials (see `rimless trials calibrate`).</p>'
        )
        return "\n".join(out)
    params = "; ".join(
        f"{e(p.name)} = {p.value:.4g} ± {1.96 * p.se:.2g} {e(p.unit)} (Table 1: {p.table1:g}"
        + (")" if p.identifiable else f"; NOT identifiable: {e(p.note)})")
        for p in cal.params
    )
    out.append(
        '<table id="misfit"><thead><tr><th>trial</th><th>slope, deg</th><th>RMS period, ms: Table 1</th>'
        "<th>calibrated</th><th>RMS CoM, mm: Table 1</th><th>calibrated</th></tr></thead><tbody>"
    )
    for r in cal.residuals:
        out.append(
            f'<tr><td>{e(Path(r["trial"]).name)}</td><td class="n">{r["slope_deg"]:.3f}</td>'
            f'<td class="n">{_num(r["table1_rms_period_ms"], ".1f")}</td>'
            f'<td class="n">{_num(r["calibrated_rms_period_ms"], ".1f")}</td>'
            f'<td class="n">{_num(r["table1_rms_com_mm"], ".2f")}</td>'
            f'<td class="n">{_num(r["calibrated_rms_com_mm"], ".2f")}</td></tr>'
        )
    out.append(
        f'</tbody></table><p class="small">Calibrated on these trials ({params}; 95 % intervals; fit '
        f"{'converged' if getattr(cal, 'converged', True) else 'did NOT converge'}): values fitted to "
        "these trials, not predictions.</p>"
    )
    return "\n".join(out)


def _critical_html(res: ReportResult) -> str:
    e = html.escape
    cr = res.critical
    out = ['<h2 id="critical-slope">Critical slope</h2>']
    model = cr.model.get("critical_slope_deg", {})
    if cr.chosen is not None:
        out.append(
            f'<p class="note" id="critical-values">From the trials: <b>{cr.chosen.value_deg:.3f} deg</b> '
            f"({e(cr.chosen.method)}, 95 % interval {cr.chosen.ci_deg[0]:.3f}-{cr.chosen.ci_deg[1]:.3f} deg); "
            + "; ".join(
                f"model {e(model_label(m, 'with c calibrated on these trials'))}: <b>{_num(v, '.3f')} deg</b>"
                for m, v in model.items()
            )
            + ".</p>"
        )
        out.append(f'<p class="small">Why this estimate: {e(cr.why)}.</p>')
    else:
        out.append(
            f'<p class="bad" id="critical-values">No critical slope from the trials: {e(cr.why)}. '
            + "; ".join(f"Model {e(m.upper())}: {_num(v, '.3f')} deg" for m, v in model.items())
            + ".</p>"
        )
    out.append(
        f'<figure><img src="{REPORT_FILES["critical"]}" alt="critical slope: verdicts against slope">'
        "<figcaption>Figure 3. Each trial's verdict from its step-to-step return map (not whether it reached "
        "the end of the ramp): the measured step periods are turned into the squared speed over the stance "
        "foot e (rigid stance pendulum of the wheel), the map e<sub>k+1</sub> = a e<sub>k</sub> + b is fitted, "
        "and its fixed point e* decides: sustained (e* &gt; 0 by 2 standard errors), decaying (e* &lt; 0, or "
        "stalled on the ramp), undetermined. Grey band: the bracket between the highest slope without a "
        "sustained trial and the lowest with one; blue: the logistic P(sustained) (when several trials share "
        "a slope); dashed: the slope where the fitted fixed points reach the stall (e* = 0); coloured lines: "
        "the model's critical slope (smallest slope with a stable period-1 gait; dashed: the model calibrated on "
        "these trials, a fit to them and not a prediction). Horizontal bars: each trial's 95 % slope interval "
        "(from its slope's source), which the critical slope's interval propagates.</figcaption></figure>"
    )
    out.append(
        '<table id="critical"><thead><tr><th>estimate</th><th>deg</th><th>95 % interval</th>'
        "<th>how</th></tr></thead><tbody>"
    )
    for est in cr.estimates:
        out.append(
            f"<tr><td>{e(est.method)}{' (reported)' if est is cr.chosen else ''}</td>"
            f'<td class="n">{est.value_deg:.3f}</td>'
            f'<td class="n">{est.ci_deg[0]:.3f}-{est.ci_deg[1]:.3f}</td><td>{e(est.detail)}</td></tr>'
        )
    for m, v in model.items():
        d = cr.model.get("detail", {}).get(m, {})
        out.append(
            f'<tr><td>model {e(model_label(m))}</td><td class="n">{_num(v, ".3f")}</td><td></td>'
            f"<td>branch ends by {e(str(d.get('reason', '')))}: {e(str(d.get('detail', '')))}</td></tr>"
        )
    out.append("</tbody></table>")
    out.append(
        '<table id="verdicts"><thead><tr><th>trial</th><th>slope, deg</th><th>steps</th><th>verdict</th>'
        "<th>reason</th></tr></thead><tbody>"
    )
    for r in cr.per_trial:
        cls = {"sustained": "ok", "decaying": "bad"}.get(r["verdict"], "suspect")
        out.append(
            f'<tr><td>{e(Path(r["file"]).name)}</td><td class="n">{r["slope_deg"]:.3f}</td>'
            f'<td class="n">{r["steps"]}</td><td class="{cls}">{e(r["verdict"])}</td>'
            f"<td>{e(r['reason'])}</td></tr>"
        )
    out.append("</tbody></table>")
    cal = res.calibration
    if cal is not None:
        rows = "".join(
            f'<tr><td>{e(p.name)} ({e(p.unit)})</td><td class="n">{p.table1:g}</td>'
            f'<td class="n">{p.value:.4g} ± {p.se:.2g}</td>'
            f"<td>{'yes' if p.identifiable else 'NO: ' + e(p.note)}</td></tr>"
            for p in cal.params
        )
        sm = cal.summary()
        out.append(
            '<h3>Calibration</h3><table id="calibration"><thead><tr><th>parameter</th><th>Table 1</th>'
            f"<th>fitted ± 1 sigma</th><th>identifiable</th></tr></thead><tbody>{rows}</tbody></table>"
            f'<p class="small">Least squares on the step periods and CoM heights of {len(cal.residuals)} '
            "trials (a release speed and a time shift fitted per trial). RMS period error "
            f"{_num(sm['rms_period_ms']['table1'], '.1f')} ms (Table 1) → "
            f"{_num(sm['rms_period_ms']['calibrated'], '.1f')} ms; RMS CoM error "
            f"{_num(sm['rms_com_mm']['table1'], '.2f')} → {_num(sm['rms_com_mm']['calibrated'], '.2f')} mm.</p>"
        )
        sep = sm.get("loss_separation")
        if sep and sep.get("note"):
            out.append(
                f'<p class="{"small" if sep.get("damping_identified") else "bad"}" id="loss-separation">'
                f"Damping or guide friction? {e(sep['note'])}.</p>"
            )
    return "\n".join(out)
