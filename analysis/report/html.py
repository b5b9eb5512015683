"""The trials report: import (or read) trials, compare them with the simulation, write HTML + PNG + CSV.

``build_report(paths, out_dir)`` writes into ``out_dir``:

- ``report.html`` — one page, no scripts and no external resources; the figures are PNG files beside it,
  referenced by relative paths (copy or zip the folder to share it). It holds the metrics (a row per input,
  linking to the input's section), the wheel's parameters with their sources, the step periods by series, the
  critical slope, a section per input (its figure, the importer's notes and warnings, its slope and the
  slope's source) and the provenance (`rimless.analysis.report.provenance`: version, command line, date, wheel
  file, every input by name and SHA-256). No absolute path of the machine appears in the page, the CSV or the
  figures' metadata;
- ``trial-<name>.png`` — per compared trial: CoM height and step periods, measured vs simulated;
- ``com_height.png`` — measured vs simulated CoM height of every trial (paper: "Comparison of experimental and
  simulated vertical CoM trajectories");
- ``step_period.png`` — step period vs step number, mean +- std over the trials of each slope bin within each
  series (`rimless.analysis.report.series`: never pooled across series), with the simulation (paper:
  "step-period trends");
- ``metrics.csv`` — one row per input (slope, steps, RMS CoM error, mean |period error|, fitted theta'+ ...,
  its series; the file by name);
- ``critical_slope.png`` (when asked, default on) — verdicts (sustained / decaying / undetermined) against
  slope, the fitted probability of sustained walking, the bracket and the model's critical slopes.
"""

from __future__ import annotations

import contextlib
import csv
import html
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.inference.background import Background, background_allowed
from rimless.analysis.inference.compare import Simulator, SlopeGroup, TrialComparison, compare_trial
from rimless.analysis.io.robot_log import read_clutch_log
from rimless.analysis.io.trial import slope_ci_deg
from rimless.analysis.kinematics.inputs import InputRow, load_input
from rimless.analysis.report.calibration_beside import (
    calibration_args,
    one_blas_thread,
    prepared_calibration,
    start_calibration,
)
from rimless.analysis.report.clutch import clutch_comparison, clutch_html
from rimless.analysis.report.figures import DPI, com_figure, new_figure, period_figure, save_png, trial_figure
from rimless.analysis.report.provenance import PathScrubber, Provenance, make_provenance
from rimless.analysis.report.sections import (
    CSS,
    TrialSection,
    anchors,
    metrics_tables_html,
    num,
    parameters_html,
    periods_html,
    provenance_html,
    trial_sections_html,
)
from rimless.analysis.report.series import (
    file_stem,
    pooled_slope_warnings,
    series_of,
    series_trends,
    slope_bin_words,
)
from rimless.errors import InputFileError

__all__ = ["ReportResult", "InputRow", "build_report", "load_input", "REPORT_FILES", "DPI"]

REPORT_FILES = {
    "html": "report.html",
    "com": "com_height.png",
    "period": "step_period.png",
    "csv": "metrics.csv",
    "critical": "critical_slope.png",
}
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
    "series",
    # the step periods after the first against their noise (`compare.period_misfit`, the plausibility check's)
    "period_misfit_chi2",
    "period_misfit_dof",
    "period_misfit_p",
    "period_misfit_relative_rms",
    "period_misfit_impact_sd_ms",
    "period_misfit_noise_source",
]
#: what the provenance says made a report built by a call of `build_report`
BUILD_REPORT_API = "rimless.analysis.report.html.build_report"


@dataclass
class ReportResult:
    """Paths written and what they contain."""

    out_dir: Path
    report_html: Path
    metrics_csv: Path
    figures: list[Path]
    inputs: list[InputRow]
    comparisons: list[TrialComparison]
    groups: list[SlopeGroup]  # `rimless.analysis.report.series.SeriesSlopeGroup`: per series and slope bin
    seconds: float = 0.0
    critical: Any = None  # rimless.analysis.inference.critical_slope.CriticalSlopeResult, when computed
    calibration: Any = None  # rimless.analysis.inference.calibrate.CalibrationResult, when computed
    #: per trial name (input file name): the robot log's measured clutched time per step beside the simulated one
    #: (`clutch_comparison`), when a robot trial log was given with the trial
    clutch: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: every wheel parameter's value, sd, unit and source (`rimless.sim.model.uncertain.WheelInput.parameters`)
    parameters: list[dict[str, Any]] | None = None
    #: one per input, in the order given: its anchor on the page, series, comparison and figure
    sections: list[TrialSection] = field(default_factory=list)
    provenance: Provenance | None = None
    #: warnings about the report as a whole (`pooled_slope_warnings`: a slope bin pooling trials on slopes that
    #: differ beyond their intervals)
    warnings: list[str] = field(default_factory=list)

    @property
    def refused(self) -> list[InputRow]:
        return [r for r in self.inputs if r.status == "refused"]

    def metrics(self) -> list[dict[str, Any]]:
        """metrics.csv rows: one per input (a refused file has status ``refused`` and the reason), with its
        series."""
        rows = []
        pairs: list[tuple[Any, Any, str | None]]
        if self.sections:
            pairs = [(s.row, s.comparison, s.series) for s in self.sections]
        else:  # a result assembled by hand: the comparisons by their trial's source file
            by_file = {c.file: c for c in self.comparisons}
            pairs = [
                (r, by_file.get(r.trial.meta.source_file) if r.trial is not None else None, None) for r in self.inputs
            ]
        for r, c, series in pairs:
            if c is not None:
                rows.append(c.metrics() | {"series": series})
            else:
                rows.append(
                    {k: None for k in METRIC_COLUMNS}
                    | {"trial": Path(r.file).name, "file": r.file, "status": "refused", "message": r.reason}
                    | {"series": series}
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
            "sections": [{"trial": s.name, "anchor": s.anchor, "series": s.series} for s in self.sections],
            "provenance": self.provenance.to_dict() if self.provenance is not None else None,
            "warnings": list(self.warnings),
        }


def build_report(
    paths: Sequence[str | Path],
    out_dir: str | Path,
    *,
    sim: Simulator | None = None,
    import_kwargs: dict[str, Any] | None = None,
    slope_bin_deg: float | None = 0.5,
    title: str = "Vicon trials vs simulation",
    note: str | None = None,
    progress: Callable[[str], None] | None = None,
    critical: bool = True,
    calibrate_c: bool = False,
    critical_files: Sequence[str | Path] | None = None,
    robot_logs: dict[str, Path] | None = None,
    wheel_input: Any = None,
    series: Mapping[str, str] | None = None,
    argv: Sequence[str] | None = None,
    api: str = BUILD_REPORT_API,
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
    (`rimless.analysis.inference.held`); ``series``: input file name or path -> its series (default: from the
    file name, `rimless.analysis.report.series`); ``argv``: the command line that asked for the report (its
    words after ``rimless``, shown with absolute paths shortened to names), None for a Python call of ``api``;
    ``slope_bin_deg``: the step periods' slope bins within a series, deg (None: trials pooled only while their
    slopes' 95 % intervals overlap, `rimless.analysis.report.series.interval_bins`).
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
    logs = list((robot_logs or {}).values())
    prov = make_provenance(files, argv=argv, api=api, wheel_path=win.path, robot_logs=logs)
    scrub = PathScrubber([*files, *logs, *([win.path] if win.path is not None else [])], [out])
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
            series_of(files, series),
            prov,
            scrub,
        )
    res.parameters = win.parameters()
    for comp in res.comparisons:  # each comparison held them, as `rimless.analysis.compare` lists them
        comp.parameters = [dict(p) for p in res.parameters]
    res.seconds = time.perf_counter() - t_start
    _write_text(res.report_html, _html(res, sim, title, note, slope_bin_deg, win, scrub))
    return res


def _compare_and_report(
    files: Sequence[Path],
    out: Path,
    sim: Simulator,
    import_kwargs: dict[str, Any] | None,
    slope_bin_deg: float | None,
    critical: bool,
    calibrate_c: bool,
    critical_files: Sequence[str | Path] | None,
    robot_logs: dict[str, Path] | None,
    progress: Callable[[str], None] | None,
    win: Any,
    series: list[str],
    prov: Provenance,
    scrub: PathScrubber,
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
        sections: list[TrialSection] = []
        hashes = [f.sha256 for f in prov.files if f.role == "trial"]
        for p, row, anchor, s, sha in zip(files, inputs, anchors([file_stem(p.name) for p in files]), series, hashes):
            sections.append(TrialSection(anchor, p.name, s, row, sha256=sha))
            if row.trial is not None:
                comps.append(compare_trial(row.trial, sim, name=p.name))
                sections[-1].comparison = comps[-1]
                if calibrate_c and calibrating is None:  # a cold cache: compiled once, by that comparison
                    calibrating = start_calibration(
                        sim.params, sim.model, *_critical_inputs(files, inputs, critical_files)
                    )
                    calibrate_c = calibrating is not None
            if progress:
                progress(p.name)
        res = ReportResult(
            out,
            out / REPORT_FILES["html"],
            out / REPORT_FILES["csv"],
            [],
            inputs,
            comps,
            [],
            sections=sections,
            provenance=prov,
        )
        _rest_of_report(
            res, files, sim, slope_bin_deg, critical, critical_files, calibrating, robot_logs, progress, win
        )
        _write_csv(res.metrics(), res.metrics_csv, scrub)
        return res
    finally:
        if calibrating is not None:
            calibrating.close()


def _rest_of_report(
    res: ReportResult,
    files: Sequence[Path],
    sim: Simulator,
    slope_bin_deg: float | None,
    critical: bool,
    critical_files: Sequence[str | Path] | None,
    calibrating: Background | None,
    robot_logs: dict[str, Path] | None,
    progress: Callable[[str], None] | None,
    win: Any,
) -> None:
    """The report after the comparisons: trends by series, clutch logs, figures, the critical slope."""
    compared = [s for s in res.sections if s.comparison is not None]
    slopes = {
        s.comparison.name: (s.comparison.slope_deg, slope_ci_deg(s.row.trial.meta.slope_ci_rad))
        for s in compared
        if s.row.trial is not None
    }
    res.groups = list(
        series_trends(
            [s.comparison for s in compared],
            [s.series for s in compared],
            sim,
            slope_bin_deg=slope_bin_deg,
            slopes=slopes,
            # a stalled trial and a walking one are never pooled (`series_trends`)
            outcomes=[s.row.trial.meta.outcome if s.row.trial is not None else "" for s in compared],
        )
    )
    res.warnings += pooled_slope_warnings(res.groups, slopes, slope_bin_deg)
    for name, log in (robot_logs or {}).items():
        comp = next((c for c in res.comparisons if c.name == name), None)
        res.clutch[name] = clutch_comparison(read_clutch_log(log), comp)
    out = res.out_dir
    res.figures += [
        com_figure(res.comparisons, out / REPORT_FILES["com"]),
        period_figure(res.groups, out / REPORT_FILES["period"], sim.model),
    ]
    for s in compared:
        if s.comparison.status != "failed":
            s.figure = f"{s.anchor}.png"
            res.figures.append(trial_figure(s.comparison, out / s.figure, s.name, sim.model))
    if critical:
        _add_critical(res, sim, *_critical_inputs(files, res.inputs, critical_files), calibrating, progress, win)
    if res.calibration is None and all_suspect(res):
        _calibrate_for_misfit(res, sim, progress)


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
    # the models by central differences, as `trials critical-slope` and `critical_slope()` take them, so the
    # report, the demo and the command give one interval (forward ones: 2.3 against 3.4 s of CPU, warm, Table 1's
    # input, `python -m rimless.analysis.bench.carry [--central]`)
    carry_critical(res.critical, trials, names, win, models=(sim.model,), progress=progress)
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
    fig = new_figure(9.0, 4.4)
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
    save_png(fig, path)
    return path


# ------------------------------------------------------------------------------------------------- tables


def _write_csv(rows: list[dict[str, Any]], path: Path, scrub: Callable[[str], str] = str) -> None:
    """metrics.csv: the rows with each file by name and the messages without absolute paths."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=METRIC_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            r = r | {
                "file": Path(str(r["file"])).name if r.get("file") else r.get("file"),
                "message": scrub(r["message"]) if r.get("message") else r.get("message"),
            }
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


def _html(
    res: ReportResult,
    sim: Simulator,
    title: str,
    note: str | None,
    slope_bin_deg: float | None,
    win: Any = None,
    scrub: Callable[[str], str] = str,
) -> str:
    def text(s: Any) -> str:
        return html.escape(scrub(str(s)))

    p = sim.params
    ok = [c for c in res.comparisons if c.status in ("ok", "suspect")]
    n_suspect = sum(c.status == "suspect" for c in res.comparisons)
    prov = res.provenance
    made = (
        f"rimless {html.escape(prov.version)}, {html.escape(prov.date_utc)}; " if prov is not None else ""
    ) + '<a href="#provenance">provenance</a>'
    parts = [
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{text(title)}</title>',
        f"<style>{CSS}</style></head><body>",
        f"<h1>{text(title)}</h1>",
        f'<p class="small">{made}; {len(res.inputs)} input(s), {len(ok)} compared ({n_suspect} suspect), '
        f"{len(res.refused)} refused; built in {res.seconds:.1f} s.</p>",
    ]
    if note:
        parts.append(f'<p class="note">{text(note)}</p>')
    if all_suspect(res):
        parts.append(_misfit_html(res, text))
    parts.append(
        '<p class="small">Model: '
        + html.escape(sim.model.upper())
        + f" wheel, mass model {html.escape(p.mass_model)}, m_H = {p.hub_mass_kg:g} kg, "
        f"m = {p.leg_mass_kg:g} kg, I_c = {p.inertia_kg_m2:g} kg m², L0 = {p.leg_length_m:g} m, "
        f"k = {p.stiffness_n_per_m:g} N/m, c = {p.damping_ns_per_m:g} N s/m (sources and uncertainties: "
        '<a href="#parameters">wheel parameters</a>); slope = each trial\'s (given or estimated); '
        f"rtol = {sim.rtol:g}. Fitted per trial: the release speed θ' at the rigid-touchdown state θ = −α/2 one "
        "step before the first measured impact, so that the first simulated step period equals the first "
        "measured one; θ'+ is the simulated post-impact θ' at the first measured impact. The simulated curve is "
        "shifted by the lag (≤ 50 ms) minimising the RMS; heights measured from the impact line get the best "
        "constant offset.</p>"
    )
    if res.clutch:
        parts.append(clutch_html(res.clutch))
    parts.append(metrics_tables_html(res.sections, res.metrics(), REPORT_FILES["csv"]))
    if res.parameters:
        fitted = []
        if res.calibration is not None and win is not None:
            from rimless.analysis.inference.runs import calibrated_input

            fitted = [q for q in calibrated_input(win, res.calibration).parameters() if q["source"] == "fitted"]
        # what the critical slope from the trials took from them instead (the inertia): the page says it too
        crit_params = (res.critical.parameters if res.critical is not None else None) or []
        from_trials = [q for q in crit_params if q.get("source") == "trials"]
        parts.append(parameters_html(res.parameters, fitted, text, from_trials))
    series = list(dict.fromkeys(getattr(g, "series", "") for g in res.groups))
    parts.append(
        '<h2 id="step-period">Step period</h2><figure>'
        f'<img src="{REPORT_FILES["period"]}" alt="step period vs step number, one panel per series">'
        f"<figcaption>Figure 1. Step period vs step number, one panel per series ({len(series)}: "
        + text(", ".join(series) or "none")
        + ") and release condition named in the file names (e.g. release1.9), mean ± std over the trials of each "
        f"slope bin of that series and condition ({slope_bin_words(slope_bin_deg)}; trials of different series "
        "or release conditions are never averaged together: runs of one condition are pooled as repeats), with "
        "the simulation (dashed): each trial "
        "simulated at its own slope from its own fitted release speed, averaged over the bin. Step 1 is fitted "
        "(the release speed is chosen to match it), so it agrees by construction and is left out of the period "
        "errors. A series is the file name without its slope and run tokens (see each trial's section).</figcaption>"
        "</figure>"
    )
    parts.append(periods_html(res.groups, slope_bin_deg))
    parts.extend(f'<p class="bad">warning: {text(w)}</p>' for w in res.warnings)  # a bin pooling other slopes
    parts.append(
        '<h2 id="com-height">CoM height</h2><figure>'
        f'<img src="{REPORT_FILES["com"]}" alt="CoM height, measured vs simulated">'
        "<figcaption>Figure 2. Comparison of measured and simulated vertical CoM trajectories (hub height "
        "normal to the slope); grey lines: measured impacts. <b>Fitted per trial</b> (values in each panel's "
        "title and in the table): the release speed θ' (so that the first simulated period equals the "
        "first measured one), a time shift of the simulated curve (≤ 50 ms) and a constant height offset of "
        "the measured curve (heights measured from the impact line). Each trial is simulated at its own "
        "slope. r: correlation of the two curves; a trial failing a plausibility check is marked SUSPECT. "
        "Each trial's own figure is in its section.</figcaption></figure>"
    )
    if res.critical is not None:
        parts.append(_critical_html(res, text))
    parts.append(trial_sections_html(res.sections, text))
    if prov is not None:
        parts.append(provenance_html(prov))
    parts.append("</body></html>\n")
    return "\n".join(parts)


def _misfit_html(res: ReportResult, text: Callable[[Any], str] = html.escape) -> str:
    """Every trial suspect: the model's parameters do not fit these trials; the calibrated comparison beside."""
    e = text
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
        f"{e(p.name)} = {p.value:.4g} "
        + (
            f"(95 % interval {p.ci95[0]:.4g}-{p.ci95[1]:.4g}, cut at its bound {p.bound:g})"
            if getattr(p, "ci_at_bound", False)  # a duck-typed estimate without it: not cut
            else f"± {1.96 * p.se:.2g}"
        )
        + f" {e(p.unit)} (Table 1: {p.table1:g}"
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
            f'<td class="n">{num(r["table1_rms_period_ms"], ".1f")}</td>'
            f'<td class="n">{num(r["calibrated_rms_period_ms"], ".1f")}</td>'
            f'<td class="n">{num(r["table1_rms_com_mm"], ".2f")}</td>'
            f'<td class="n">{num(r["calibrated_rms_com_mm"], ".2f")}</td></tr>'
        )
    out.append(
        f'</tbody></table><p class="small">Calibrated on these trials ({params}; 95 % intervals; fit '
        f"{'converged' if getattr(cal, 'converged', True) else 'did NOT converge'}): values fitted to "
        "these trials, not predictions.</p>"
    )
    return "\n".join(out)


def _critical_html(res: ReportResult, text: Callable[[Any], str] = html.escape) -> str:
    e = text
    cr = res.critical
    out = ['<h2 id="critical-slope">Critical slope</h2>']
    model = cr.model.get("critical_slope_deg", {})
    if cr.chosen is not None:
        out.append(
            f'<p class="note" id="critical-values">From the trials: <b>{cr.chosen.value_deg:.3f} deg</b> '
            f"({e(cr.chosen.method)}, 95 % interval {cr.chosen.ci_deg[0]:.3f}-{cr.chosen.ci_deg[1]:.3f} deg); "
            + "; ".join(
                f"model {e(model_label(m, 'with c calibrated on these trials'))}: <b>{num(v, '.3f')} deg</b>"
                for m, v in model.items()
            )
            + ".</p>"
        )
        out.append(f'<p class="small">Why this estimate: {e(cr.why)}.</p>')
    else:
        out.append(
            f'<p class="bad" id="critical-values">No critical slope from the trials: {e(cr.why)}. '
            + "; ".join(f"Model {e(m.upper())}: {num(v, '.3f')} deg" for m, v in model.items())
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
            f'<tr><td>model {e(model_label(m))}</td><td class="n">{num(v, ".3f")}</td><td></td>'
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
            f"{num(sm['rms_period_ms']['table1'], '.1f')} ms (Table 1) → "
            f"{num(sm['rms_period_ms']['calibrated'], '.1f')} ms; RMS CoM error "
            f"{num(sm['rms_com_mm']['table1'], '.2f')} → {num(sm['rms_com_mm']['calibrated'], '.2f')} mm.</p>"
        )
        sep = sm.get("loss_separation")
        if sep and sep.get("note"):
            out.append(
                f'<p class="{"small" if sep.get("damping_identified") else "bad"}" id="loss-separation">'
                f"Damping or guide friction? {e(sep['note'])}.</p>"
            )
    return "\n".join(out)
