"""The batch jobs behind ``rimless trials import``, ``trials report`` and ``rimless demo``: each takes the
parsed options, does the work with a progress bar on stderr, and returns what the command prints.

`import_files` writes one ``<name>.trial.parquet`` per export and returns the JSON rows of ``trials import
--json``; `run_report` compares the trials with the simulation and writes the report (whole or not at all: an
interrupted run or one in which no trial could be compared leaves nothing behind); `run_demo` does that on the
bundled SYNTHETIC trials.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

from rimless.analysis.examples.bundled import DATA_DIR, data_files
from rimless.analysis.examples.critical_series import data_files as critical_data_files
from rimless.analysis.inference.compare import Simulator
from rimless.analysis.io.trial import slope_ci_deg
from rimless.analysis.io.vicon_csv import ViconCsvError
from rimless.analysis.kinematics.build import DEFAULT_MAX_GAP_S, import_trial
from rimless.analysis.kinematics.build import import_parameters as held_parameters
from rimless.analysis.report.html import ReportResult, build_report
from rimless.errors import OutputFileError, RunFailure, UserError
from rimless.output import check_output_folder, ctrl_c_held, writable_dir
from rimless.progress import progress_bar

__all__ = [
    "shown_path",
    "check_inputs",
    "import_row",
    "import_files",
    "import_parameters",
    "parameters_line",
    "run_report",
    "run_demo",
    "demo_inputs",
    "DemoReport",
    "bundled_relative",
    "DEMO_NOTE",
    "demo_verdicts",
]

DEMO_NOTE = (
    "SYNTHETIC DATA: the bundled example trials are simulated (ER wheel, Table 1 parameters, slopes "
    "1.5/2/2.5 deg, 0.3 mm noise), not measured; see rimless/analysis/data/README.md. The SYNTHETIC_crit "
    "series (1.3-2.05 deg, two release speeds, an 11-step ramp) comes from another truth model, for the critical "
    "slope and the calibration: c = 10 N s/m and a constant 0.06 N force against the wheel's travel (a loss this "
    "model has no parameter for; its F_c is the legs' guide friction). That wheel loses more energy a step than "
    "Table 1's, so compared with Table 1's wheel most of these trials come out suspect, as they should: the "
    "simulated walk speeds up where they slow down. The c calibrated on them is an effective loss that stands in "
    "for it (rimless/analysis/data/critical/README.md)."
)
#: the series of the bundled trials made by the simulator itself at Table 1, and the one made by another truth
DEMO_TABLE1_SERIES = "SYNTHETIC_er"
DEMO_OTHER_TRUTH_SERIES = "SYNTHETIC_crit"


def shown_path(path: str | Path) -> str:
    """``path`` relative to the working directory when it lies below it, else as given."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except (ValueError, OSError):
        return str(p)


def check_inputs(files: Sequence[Path]) -> None:
    """Refuse a folder or a missing file among the inputs before any work (a `UserError` naming it)."""
    for f in files:
        if f.is_dir():
            raise UserError(f"{shown_path(f)}: is a folder, not a Vicon export (give the files, e.g. {f}/*.csv)")
        if not f.exists():
            raise UserError(f"{shown_path(f)}: no such file")


def _clean_reason(err: Exception) -> str:
    """The message of a user error with the Python argument names replaced by the CLI option names."""
    msg = str(err)
    for py, opt in (
        ("object=", "--object "),
        ("markers=", "--markers "),
        ("hub_offset_m=", "--hub-offset-mm "),
        ("max_gap_s", "--max-gap-ms"),
    ):
        msg = msg.replace(py, opt)
    return msg


def import_row(path: Path, trial: Any | None, error: Exception | None) -> dict[str, Any]:
    """The JSON row of one imported (or refused) file: the `trials import --json` contract."""
    row: dict[str, Any] = {
        "file": shown_path(path),
        "status": "refused",
        "reason": None,
        "frames": None,
        "rate_hz": None,
        "steps": None,
        "source": None,
        "slope_deg": None,
        "ramp_slope_deg": None,
        "outcome": None,
        "window_s": None,
        "impact_times_s": [],
        "step_periods_s": [],
        "hub_offset_mm": None,
        "hub_offset_sd_mm": None,
        "hub_offset_sd_axes_mm": None,
        "warnings": [],
        "errors": [],
        "trial": None,
        "slope_source": None,
        "slope_ci_deg": None,
        "up_axis": None,
    }
    if error is not None or trial is None:
        row["reason"] = _clean_reason(error) if error is not None else "not imported"
        if isinstance(error, ViconCsvError):
            row["errors"] = error.all_locations()
        else:
            row["errors"] = [row["reason"]]
        return row
    m = trial.meta
    row.update(
        status="imported",
        frames=m.n_frames,
        rate_hz=m.rate_hz,
        steps=int(trial.step_period_s.size),
        reason=None if m.step_refused is None else f"steps not detected: {m.step_refused}",
        source={"object": m.object, "markers": list(m.markers), "section": m.section, "why": m.source_reason},
        slope_deg=m.slope_deg,
        ramp_slope_deg=m.ramp_slope_deg,
        outcome=m.outcome,
        window_s=list(m.window_s) if m.window_s else None,
        impact_times_s=trial.impact_time_s.tolist(),
        step_periods_s=trial.step_period_s.tolist(),
        hub_offset_mm=None if m.hub_offset_m is None else [round(v * 1e3, 3) for v in m.hub_offset_m],
        hub_offset_sd_mm=None if m.hub_offset_sd_m is None else round(m.hub_offset_sd_m * 1e3, 4),
        hub_offset_sd_axes_mm=None
        if m.hub_offset_sd_axes_m is None
        else [round(v * 1e3, 4) for v in m.hub_offset_sd_axes_m],
        warnings=list(m.warnings) + ([f"steps not detected: {m.step_refused}"] if m.step_refused else []),
        slope_source=m.slope_source,
        slope_ci_deg=slope_ci_deg(m.slope_ci_rad),
        up_axis=m.up_axis,
        _estimated_deg=m.slope_estimated_deg,
    )
    return row


def import_parameters(import_kwargs: dict[str, Any]) -> list[dict[str, Any]]:
    """The ``parameters`` of ``trials import --json``: `rimless.analysis.kinematics.build.import_parameters` of the
    keyword arguments of `import_trial` (``wheel``, ``leg_length_m``), the one place that lists them."""
    return held_parameters(import_kwargs.get("wheel"), import_kwargs.get("leg_length_m"))


def parameters_line(parameters: list[dict[str, Any]]) -> str:
    """``parameters`` as one printed line: symbol = value (± sd or exact/bound) unit [source]."""
    parts = []
    for p in parameters:
        if p["sd"] is None or p["sd"] == 0:
            how = "exact" if p["sd"] == 0 else ("bound" if p["source"] == "assumed_bound" else "derived")
            parts.append(f"{p['symbol']} = {p['value']:.4g} {p['unit']} ({how}) [{p['source']}]")
        else:
            parts.append(f"{p['symbol']} = {p['value']:.4g} ± {p['sd']:.3g} {p['unit']} [{p['source']}]")
    return "held parameters (slope interval): " + "; ".join(parts)


def _stem(path: Path) -> str:
    name = path.name
    for suffix in (".csv", ".c3d", ".txt"):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)]
    return path.stem


def _import_one(path: Path, out: Path, kwargs: dict[str, Any]) -> dict[str, Any]:
    try:
        trial = import_trial(path, **kwargs)
        target = out / (_stem(path) + ".trial.parquet")
        trial.to_parquet(target)
    except UserError as err:
        return import_row(path, None, err)
    except OSError as err:
        return import_row(path, None, UserError(f"{shown_path(path)}: {err.strerror or err}"))
    row = import_row(path, trial, None)
    row["trial"] = row["_trial"] = shown_path(target)
    row["_outcome_reason"] = trial.meta.outcome_reason
    return row


def import_files(
    files: Sequence[Path], out: Path, import_kwargs: dict[str, Any], *, json_out: bool = False
) -> list[dict[str, Any]]:
    """Import each export and write ``out/<name>.trial.parquet``; a refused file does not stop the others.

    One `import_row` per file, each with ``parameters`` (`import_parameters`: what the import held); keys starting
    with ``_`` (the written path, the outcome's reason) are for the table and are not part of the JSON contract. A folder or a missing input, or an ``out`` that cannot be
    written, stops before any work (`UserError`).
    """
    check_inputs(files)
    writable_dir(out, option="--out")
    held = import_parameters(import_kwargs)
    rows: list[dict[str, Any]] = []
    # one file as several: a transient bar on a terminal (an import takes seconds), plain lines off one with --json
    with progress_bar("importing", total=len(files), json_out=json_out) as bar:
        for f in files:
            bar.update(description=f"importing {f.name}")
            rows.append({**_import_one(f, out, import_kwargs), "parameters": held})
            bar.advance()
    return rows


def run_report(
    files: Sequence[Path],
    out: Path,
    *,
    json_out: bool,
    import_kwargs: dict[str, Any],
    model: str,
    slope_bin_deg: float | None,
    note: str | None = None,
    title: str = "Vicon trials vs simulation",
    params: Any = None,
    wheel_input: Any = None,
    argv: Sequence[str] | None = None,
    api: str = "rimless.analysis.write_report",
    **report_kwargs: Any,
) -> ReportResult:
    """`build_report` with the ``model`` simulator at ``params`` (WheelParams, default Table 1; the slope is each
    trial's) and a progress bar, written whole or not at all.

    The report is built in a temporary folder (in or beside ``out``) and its files are moved into ``out``
    (created if needed; other files there stay) only once it is complete, with a Ctrl-C held back while they
    are: a Ctrl-C or an error leaves nothing behind, and an earlier report in ``out`` stays until the new one
    replaces it. A folder or a missing input stops before
    any work (`UserError`). When no trial could be compared (every input refused or its comparison failed)
    nothing is written: a `UserError` with the first refusal when an input was refused, else a `RunFailure`
    with the first failure. ``argv``: the command's words for the report's provenance (None: a Python call of
    ``api``, by default `rimless.analysis.write_report`, whose implementation this is)."""
    check_inputs(files)
    from rimless.sim.api.wheel import Wheel

    # the importer's legs' drift (`import_trial(wheel=)`): the wheel the report compares with, with the wheel
    # input's uncertainties (default Table 1's stated ones), so each slope is the one `compare` gets for it
    legs = Wheel(params, model) if wheel_input is None else Wheel.from_input(wheel_input, model, params=params)  # type: ignore[arg-type]
    import_kwargs = {"wheel": legs, **import_kwargs}
    out = Path(out)
    out_is_new = not out.exists()
    building, created = _report_draft(out)
    try:
        with progress_bar("simulator", total=len(files), json_out=json_out) as bar:
            sim = Simulator(model=model, params=params)
            bar.update(description="comparing")

            compared = 0

            def step(name: str) -> None:  # one call per input, then one per later stage (critical slope, ...)
                nonlocal compared
                if compared < len(files):  # the bar counts the inputs: a later stage never takes it past them
                    compared += 1
                    bar.update(description=f"compared {name}")
                    bar.advance()
                else:
                    bar.update(description=name)

            res = build_report(
                files,
                building,
                sim=sim,
                import_kwargs=import_kwargs,
                slope_bin_deg=slope_bin_deg,
                note=note,
                title=title,
                progress=step,
                wheel_input=wheel_input,
                argv=argv,
                api=api,
                **report_kwargs,
            )
        _no_result(res)
        _move_report(res, building, out)
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        for folder in (out if out_is_new else None, created):
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)
        raise
    shutil.rmtree(building, ignore_errors=True)
    return res


def _report_draft(out: Path) -> tuple[Path, Path | None]:
    """A new temporary folder for the report (hidden, ``.NAME.*.part``: inside ``out`` when it exists, else
    beside it) and the first folder that had to be created for it (None when none was): removed again if the
    report fails."""
    import tempfile

    if out.exists() and not out.is_dir():
        raise OutputFileError(f"--out {out}: exists and is not a folder")
    parent = out if out.is_dir() else (out.parent if str(out.parent) else Path("."))
    created = None
    probe = parent
    while not probe.exists() and probe != probe.parent:
        created, probe = probe, probe.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f".{out.name or 'report'}.", suffix=".part", dir=parent)), created
    except OSError as err:
        if created is not None:
            shutil.rmtree(created, ignore_errors=True)
        raise OutputFileError(f"--out {out}: cannot create the folder ({err.strerror or err})") from None


def _no_result(res: ReportResult) -> None:
    """Raise when no trial could be compared: the first refusal (`UserError`) or the first failure (`RunFailure`)."""
    if any(c.status in ("ok", "suspect") for c in res.comparisons):
        return
    if res.refused:  # nothing could be read: one error, no empty report left behind
        more = f" (and {len(res.refused) - 1} more input(s) refused)" if len(res.refused) > 1 else ""
        raise UserError(f"{res.refused[0].reason}{more}")
    failed = [c for c in res.comparisons if c.status == "failed"]
    first = f": {shown_path(failed[0].file)}: {failed[0].message}" if failed else ""
    more = f" (and {len(failed) - 1} more failed)" if len(failed) > 1 else ""
    raise RunFailure(f"no trial could be compared with the simulation{first}{more}; no report written")


def _move_report(res: ReportResult, building: Path, out: Path) -> None:
    """Move the complete report's files from ``building`` into ``out`` and point ``res`` at them there."""
    import os

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputFileError(f"--out {out}: cannot create the folder ({err.strerror or err})") from None
    for item in sorted(building.iterdir()):
        if (out / item.name).is_dir() and not item.is_dir():
            raise OutputFileError(f"--out {out}: {out / item.name} is a folder, the report writes a file there")
    # the page last: until it is replaced, an earlier report.html still finds its own figures' names
    with ctrl_c_held():
        for item in sorted(building.iterdir(), key=lambda p: p == res.report_html):
            os.replace(item, out / item.name)

    def moved(p: Path) -> Path:
        return out / p.name if p.parent == building else p

    res.out_dir = out
    res.report_html = moved(res.report_html)
    res.metrics_csv = moved(res.metrics_csv)
    res.figures = [moved(p) for p in res.figures]


def robot_log_pairs(specs: Sequence[str], trials: Sequence[Path]) -> dict[str, Path]:
    """``--robot-log [TRIAL=]FILE`` values -> {trial input file name: log path}. Without ``TRIAL=`` the log
    belongs to the only trial given; a missing log, an unknown or repeated trial is a `ParameterError` naming
    the option."""
    from rimless.errors import ParameterError

    names = [Path(t).name for t in trials]
    out: dict[str, Path] = {}
    for spec in specs:
        trial, sep, file = spec.rpartition("=")
        if not sep:
            if len(names) != 1:
                raise ParameterError(
                    f"--robot-log {spec}: with {len(names)} trials, name the trial: "
                    "--robot-log TRIAL=FILE (TRIAL: the trial's file name)"
                )
            trial = names[0]
        trial = Path(trial).name
        if trial not in names:
            raise ParameterError(f"--robot-log {spec}: {trial!r} is not one of the trials given ({', '.join(names)})")
        if trial in out:
            raise ParameterError(f"--robot-log {spec}: a second log for {trial}")
        if not Path(file).is_file():
            raise ParameterError(f"--robot-log {spec}: {file}: no such file")
        out[trial] = Path(file)
    return out


def demo_inputs() -> list[Path]:
    """The bundled SYNTHETIC example trials (both series), sorted; a `UserError` when the install lacks them."""
    files = sorted(set(data_files()) | set(critical_data_files()))
    if not files:
        raise UserError("the bundled example dataset is missing from this install (rimless/analysis/data)")
    return files


def bundled_relative(obj: Any) -> Any:
    """``obj`` (a text, or a JSON-ready object: its keys and texts) with the bundled data's paths named relative to
    the data folder (``SYNTHETIC_er_...csv``, ``critical/SYNTHETIC_crit_...csv``), as the report and its
    provenance name them: the install's absolute path (anywhere in a text) and the working folder's relative
    path (at a text's start) to the data folder are dropped."""
    if isinstance(obj, str):
        out = obj.replace(f"{DATA_DIR}{os.sep}", "")
        rel = shown_path(DATA_DIR)
        if rel != str(DATA_DIR) and out.startswith(rel + os.sep):
            out = out[len(rel) + 1 :]
        return out
    if isinstance(obj, dict):
        return {bundled_relative(k): bundled_relative(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [bundled_relative(v) for v in obj]
    return obj


def demo_verdicts(res: ReportResult) -> list[dict[str, Any]]:
    """Per series of the demo's trials: how many were compared ``ok``, ``suspect`` or not (``failed`` or
    ``refused``), and ``meaning``: what that says about these trials, in words (JSON ``verdicts``; printed).

    The SYNTHETIC_er trials were made by this simulator at Table 1: against Table 1 they should all agree. The
    SYNTHETIC_crit trials were made by a truth that loses more energy a step (its c and travel force from
    ``critical/SYNTHETIC_crit_truth.toml``): against Table 1's wheel (the demo's default) most are expected to be
    suspect, and the meaning says so, with the c calibrated on them (when it was) as the wheel to compare them
    with. Against a wheel the user gave (``--params``) the counts are given without that expectation."""
    from rimless.analysis.examples.critical_series import load_truth

    c_held = next((p for p in res.parameters or [] if p["name"] == "damping_ns_per_m"), None)
    table1 = all(p["source"] == "table1" for p in res.parameters or [])
    out = []
    for series in dict.fromkeys(s.series for s in res.sections):
        in_series = [s for s in res.sections if s.series == series]
        statuses = [s.comparison.status if s.comparison is not None else "refused" for s in in_series]
        n, ok, suspect = len(statuses), statuses.count("ok"), statuses.count("suspect")
        other = n - ok - suspect
        counts = f"{series}: {ok} of {n} trials ok, {suspect} suspect, {other} not compared"
        if not table1:
            meaning = f"{counts}, against the wheel given (--params); see each trial's reasons above"
        elif series == DEMO_TABLE1_SERIES:
            meaning = f"{counts}; made by this simulator at Table 1, they " + (
                "agree with it, as they should" if ok == n else "should all agree with it: a fault to report"
            )
        elif series == DEMO_OTHER_TRUTH_SERIES and ok < n:
            try:
                truth = load_truth()["dataset"]
                losses = (
                    f"c = {truth['damping_ns_per_m']:g} N s/m and a constant {truth['guide_friction_n']:g} N force "
                    "against its travel"
                )
            except (OSError, KeyError, ValueError):  # an install without the truth file: the README's words
                losses = "more leg damping and a constant force against its travel"
            cal = res.calibration
            with_c = (
                f"; the c calibrated on them ({cal.calibrated_params.damping_ns_per_m:.1f} N s/m, effective) stands in "
                "for that loss: compare them with it (`rimless trials report` with `--params`, a wheel file of that "
                'c; docs/trials.md, "The demo\'s verdicts")'
                if cal is not None
                else ""
            )
            meaning = (
                f"{counts}, against Table 1's wheel (c = {c_held['value'] if c_held else 8:g} N s/m). Expected, not a "
                f"fault of the import or the comparison: their truth wheel loses more energy a step ({losses}, "
                "critical/SYNTHETIC_crit_truth.toml; this model has no parameter for that force), so "
                "the simulated walk speeds up where they slow down and drifts out of step (the |dT| column)" + with_c
            )
        else:
            meaning = counts
        out.append({"series": series, "ok": ok, "suspect": suspect, "not_compared": other, "meaning": meaning})
    return out


class DemoReport(ReportResult):
    """The `ReportResult` of `run_demo`: its JSON (`summary`) and its printed names (`shown`) of the bundled
    trials are relative to the data folder wherever the demo ran (`bundled_relative`); the JSON adds
    ``verdicts`` (`demo_verdicts`: what each series' verdicts mean)."""

    def summary(self) -> dict[str, Any]:
        """`ReportResult.summary` with the bundled trials named relative to the data folder, and ``verdicts``."""
        out: dict[str, Any] = bundled_relative(super().summary())
        out["verdicts"] = demo_verdicts(self)
        return out

    def shown(self, path: str | Path) -> str:
        """A trial's file as the demo prints it (relative to the data folder)."""
        return str(bundled_relative(str(path)))


def run_demo(
    out: Path,
    *,
    json_out: bool,
    starting: Callable[[int], None] | None = None,
    wheel_input: Any = None,
    argv: Sequence[str] | None = None,
    slope_bin_deg: float | None = None,
) -> DemoReport:
    """The ``rimless demo`` report on `demo_inputs` (ER model, critical slope and calibrated c on the series),
    the bundled trials named relative to the data folder in its JSON and printed lines (`DemoReport`).

    Checks ``out`` (``--out``) before any work; ``starting(n)`` is called with the number of trials just before
    the run; ``argv``: the command's words for the report's provenance (None: ``run_demo`` from Python);
    ``slope_bin_deg``: the step periods' slope bins (``--slope-bin-deg``), deg; None (the default): per series,
    trials pooled only while their slopes' 95 % intervals overlap (`rimless.analysis.report.series.interval_bins`:
    the demo's series, 0.15 deg apart, are never pooled across slopes that differ beyond their intervals)."""
    files = demo_inputs()
    check_output_folder(out, option="--out")
    if starting is not None:
        starting(len(files))
    res = run_report(
        files,
        out,
        json_out=json_out,
        import_kwargs={"max_gap_s": DEFAULT_MAX_GAP_S},
        model="er",
        slope_bin_deg=slope_bin_deg,
        note=DEMO_NOTE,
        title="rimless demo: SYNTHETIC trials vs simulation",
        critical_files=critical_data_files(),
        calibrate_c=True,
        params=wheel_input.params if wheel_input is not None else None,
        wheel_input=wheel_input,
        argv=argv,
        api="rimless.analysis.report.batch.run_demo",
    )
    return DemoReport(**{f.name: getattr(res, f.name) for f in fields(res)})
