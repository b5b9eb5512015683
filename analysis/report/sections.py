"""The report page's parts that a reader scans: the metrics tables (a row per input, linking to its section),
a section per trial (its figure, import notes and warnings, slope and its source), the wheel's parameters with
their sources, the provenance, the step-period table by series and slope bin, and the page's CSS.

The metrics tables are sized for a 1280 px window: units in the headers (which may wrap between words), numbers
never wrapped (``white-space: nowrap``), a trial's name breakable after ``_`` and ``-`` only (``<wbr>``), the
fitted values in a second table, each table in a horizontally scrolling wrapper should a name still not fit.
Every text that comes from the data goes through the report's `PathScrubber` (no absolute machine path).
"""

from __future__ import annotations

import html
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.io.trial import slope_ci_deg

__all__ = [
    "TrialSection",
    "anchors",
    "num",
    "breakable",
    "metrics_tables_html",
    "trial_sections_html",
    "parameters_html",
    "provenance_html",
    "periods_html",
    "CSS",
    "SOURCE_LABELS",
]

#: `rimless.sim.model.uncertain.SOURCES` as the page says them
SOURCE_LABELS = {
    "table1": "Table 1",
    "wheel_file": "wheel file",
    "wheel": "Wheel (Python API)",
    "leg_test_prior": "leg test",
    "fitted": "fitted",
    "trials": "the trials' step periods",
}


@dataclass
class TrialSection:
    """One input's section: its anchor, what became of it (``row``: `rimless.analysis.kinematics.inputs.InputRow`),
    its comparison with the simulation (None when refused), its series and its figure (relative to the page)."""

    anchor: str
    name: str
    series: str
    row: Any
    comparison: Any = None
    figure: str | None = None
    sha256: str = ""
    notes: list[str] = field(default_factory=list)


def anchors(names: Sequence[str]) -> list[str]:
    """A unique HTML id per input, ``trial-<name>`` (letters, digits, ``.``, ``_``, ``-``; ``-2``... on repeats)."""
    out: list[str] = []
    seen: set[str] = set()
    for name in names:
        base = "trial-" + (re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-") or "input")
        anchor, k = base, 2
        while anchor in seen:
            anchor, k = f"{base}-{k}", k + 1
        seen.add(anchor)
        out.append(anchor)
    return out


def num(v: Any, fmt: str) -> str:
    """A number as the page shows it, ``–`` when missing or not finite."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


def breakable(name: str) -> str:
    """An escaped name that may break after ``_`` and ``-`` only (never inside a number such as ``1.9``)."""
    return re.sub(r"([_-])", r"\1<wbr>", html.escape(name))


def _status_class(status: str) -> str:
    return {"ok": "ok", "suspect": "suspect"}.get(status, "bad")


def _link(s: TrialSection) -> str:
    return f'<a href="#{s.anchor}">{breakable(s.name)}</a>'


#: (header, metrics key, format) of the summary table and of the fitted-values table
SUMMARY_COLUMNS = (
    ("slope, deg", "slope_deg", ".3f"),
    ("steps", "steps", "d"),
    ("RMS CoM, mm", "rms_com_error_mm", ".2f"),
    ("RMS / amplitude", "rms_com_relative", ".2f"),
    ("CoM r", "com_correlation", ".3f"),
    ("mean |ΔT|, ms", "mean_abs_period_error_ms", ".1f"),
)
FITTED_COLUMNS = (
    ("θ'+, rad/s", "theta_dot_plus_rad_s", ".3f"),
    ("release θ', rad/s", "release_theta_dot_rad_s", ".3f"),
    ("time shift, ms", "time_shift_ms", "+.1f"),
    ("height offset, mm", "height_offset_mm", "+.1f"),
)
#: (header, metrics key, format) of the table of the step periods after the first against their noise
#: (`rimless.analysis.inference.compare.period_misfit`, the plausibility check's figures)
PERIOD_FIT_COLUMNS = (
    ("periods χ²", "period_misfit_chi2", ".3g"),
    ("dof", "period_misfit_dof", "d"),
    ("p", "period_misfit_p", ".2g"),
    ("rms miss / period", "period_misfit_relative_rms", ".1%"),
    ("impact noise, ms", "period_misfit_impact_sd_ms", ".2f"),
)


def _compared_table(
    table_id: str,
    columns: Sequence[tuple[str, str, str]],
    sections: Sequence[TrialSection],
    rows: Sequence[dict[str, Any]],
) -> list[str]:
    """A table of the compared trials (status ok or suspect), one row each, its name linking to its section;
    ``columns``: (header, row key, format). The HTML pieces up to the body's end (its caption follows)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h, _, _ in columns)
    out = [f'<div class="wide"><table id="{table_id}"><thead><tr><th>trial</th>{head}</tr></thead><tbody>']
    for s, r in zip(sections, rows):
        if r.get("status") in ("ok", "suspect"):
            cells = "".join(f'<td class="n">{num(r.get(k), f)}</td>' for _, k, f in columns)
            out.append(f"<tr><td>{_link(s)}</td>{cells}</tr>")
    return out


def metrics_tables_html(sections: Sequence[TrialSection], rows: Sequence[dict[str, Any]], csv_name: str) -> str:
    """The metrics (one row per input, its name linking to its section) and the values fitted per trial."""
    e = html.escape
    head = "".join(f"<th>{e(h)}</th>" for h, _, _ in SUMMARY_COLUMNS)
    out = [
        '<h2 id="metrics-heading">Metrics</h2><div class="wide"><table id="metrics"><thead><tr><th>trial</th>'
        f"<th>series</th><th>status</th>{head}</tr></thead><tbody>"
    ]
    for s, r in zip(sections, rows):
        cells = "".join(f'<td class="n">{num(r.get(k), f)}</td>' for _, k, f in SUMMARY_COLUMNS)
        status = str(r["status"])
        out.append(
            f'<tr class="trial"><td>{_link(s)}</td><td>{breakable(s.series)}</td>'
            f'<td class="{_status_class(status)}">{e(status)}</td>{cells}</tr>'
        )
    out.append(
        "</tbody></table></div>"
        '<p class="small">RMS CoM: the RMS CoM-height error, measured vs simulated; RMS / amplitude: the same '
        "relative to the measured CoM amplitude; CoM r: the correlation of the two curves; mean |ΔT|: the mean "
        "|period error|, simulated minus measured, over steps 2..N (step 1 is fitted).</p>"
    )
    out.extend(_compared_table("fitted", FITTED_COLUMNS, sections, rows))
    out.append(
        "</tbody></table></div>"
        '<p class="small">Fitted per trial (table above): θ\'+, the simulated post-impact speed at the first '
        "measured impact; the release speed θ'; the time shift of the simulated curve; the height offset of the "
        "measured one (heights from the impact line: that line's height above the slope plane, about L0 cos(α/2) "
        "less the legs' compression, see each trial's section). Each trial's message, notes and warnings are in its section below. Also in "
        f'<a href="{e(csv_name)}">{e(csv_name)}</a>.</p>'
    )
    from rimless.analysis.inference.compare import PLAUSIBILITY as lim

    out.extend(_compared_table("period-fit", PERIOD_FIT_COLUMNS, sections, rows))
    out.append(
        "</tbody></table></div>"
        '<p class="small">The simulated step periods after the first against the measured ones (table above; '
        "the plausibility check's figures): periods χ², the chi-square of their misses against the periods' "
        "noise, each period the difference of two impact times (so neighbours share one), on dof periods, with "
        "its tail probability p; the rms miss relative to the median measured period; the impact-time noise taken "
        "(from the measured periods' second differences, never below the importer's floor; the source is in "
        f'<a href="{e(csv_name)}">{e(csv_name)}</a>, <code>period_misfit_noise_source</code>). A trial is '
        f"suspect on its periods only when p is below {lim['period_p']:g} and the rms miss is over "
        f"{lim['max_relative_period_rms']:.0%} of a period.</p>"
    )
    return "\n".join(out)


def _slope_text(m: Any) -> str:
    ci = slope_ci_deg(m.slope_ci_rad)
    text = f"{m.slope_deg:.3f} deg from {m.slope_source}" + (f" ({m.slope_method})" if m.slope_method else "")
    if ci:
        text += f", 95 % interval {ci[0]:.3f}-{ci[1]:.3f} deg"
    if m.ramp_slope_deg is not None and m.slope_source != "ramp":
        text += f"; static ramp {m.ramp_slope_deg:.3f} deg"
    if m.slope_estimated_deg is not None and m.slope_source != "estimated":
        text += f"; from the motion {m.slope_estimated_deg:.3f} deg"
    return text


def _facts(s: TrialSection, text: Callable[[Any], str]) -> list[tuple[str, str]]:
    row, c = s.row, s.comparison
    facts = [("series", text(s.series)), ("input", f"{text(s.name)} ({text(row.kind)}, {text(row.status)})")]
    if s.sha256:
        facts.append(("SHA-256", f"<code>{s.sha256}</code>"))
    if row.trial is None:
        facts.append(("refused", f'<span class="bad">{text(row.reason or "not imported")}</span>'))
        return facts
    m = row.trial.meta
    if row.kind == "parquet":
        facts.append(("exported from", text(Path(m.source_file).name)))
    facts.append(("slope", text(_slope_text(m))))
    facts.append(
        ("recording", text(f"{m.n_frames} frames at {m.rate_hz:g} Hz; wheel from {m.source_reason or m.hub_source}"))
    )
    facts.append(("walk", text(f"{m.outcome}: {m.outcome_reason}" if m.outcome_reason else m.outcome)))
    if c is not None:
        status = f'<span class="{_status_class(c.status)}">{text(c.status)}</span>'
        facts.append(("comparison", status + (f": {text(c.message)}" if c.message else "")))
        offset = height_offset_text(c)
        if offset:
            facts.append(("height offset", text(offset)))
    return facts


def height_offset_text(c: Any) -> str:
    """What the fitted height offset is, when the trial's CoM heights are measured from the impact line (no leg
    length at import): the height of that line above the slope plane, which the simulated hub stands at when its
    legs touch down (about L0 cos(alpha/2), less the legs' compression), not an error of the recording's frame;
    only a departure from it larger than the CoM swing would be one. Empty when no offset was fitted."""
    off = float(getattr(c, "height_offset_m", float("nan")))
    curve = np.asarray(getattr(c, "sim_curve_m", np.zeros(0)), float)
    curve = curve[np.isfinite(curve)]
    if not math.isfinite(off) or off == 0.0 or curve.size == 0:
        return ""
    low, high = float(curve.min()), float(curve.max())
    return (
        f"{off * 1e3:+.1f} mm: the measured CoM heights are from the line through the hub at the impacts (no leg "
        f"length given at import), the simulated ones from the slope plane; the simulated hub stands "
        f"{low * 1e3:.1f}-{high * 1e3:.1f} mm above the plane (lowest at touchdown: L0 cos(alpha/2) less the legs' "
        f"compression), so an offset near {low * 1e3:.0f} mm is that height, not an error of the recording's frame "
        f"(it differs by {abs(off - low) * 1e3:.1f} mm; give --leg-length-m to compare heights from the plane)"
    )


def trial_sections_html(sections: Sequence[TrialSection], text: Callable[[Any], str]) -> str:
    """A section per input: what became of it, its figure, the importer's notes and warnings, the comparison's."""
    out = ['<h2 id="trials">Trials</h2>']
    for s in sections:
        status = s.comparison.status if s.comparison is not None else s.row.status
        out.append(
            f'<section class="trial" id="{s.anchor}"><h3>{breakable(s.name)} '
            f'<span class="{_status_class(status)}">{text(status)}</span></h3>'
        )
        facts = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in _facts(s, text))
        out.append(f'<table class="facts">{facts}</table>')
        if s.figure:
            out.append(
                f'<figure><img src="{html.escape(s.figure)}" alt="{text(s.name)}: CoM height and step periods, '
                'measured vs simulated"><figcaption>Left: CoM height, measured (dots, with the fitted height '
                "offset) and simulated (line, fitted release speed and time shift); grey lines: measured impacts. "
                "Right: step periods, measured and simulated (step 1 fitted).</figcaption></figure>"
            )
        notes = list(s.row.warnings)
        warnings = list(s.row.trial.meta.warnings) if s.row.trial is not None else []
        if s.comparison is not None:
            warnings += [w for w in s.comparison.warnings if w not in warnings and w != s.comparison.message]
        for label, items, cls in (("import notes", notes, "small"), ("warnings", warnings, "bad")):
            if items:
                lis = "".join(f"<li>{text(w)}</li>" for w in items)
                out.append(f'<p class="{cls}">{label}:</p><ul class="{cls}">{lis}</ul>')
        if not notes and not warnings and s.row.trial is not None:
            out.append('<p class="small">import notes: none; warnings: none.</p>')
        out.append('<p class="small"><a href="#metrics">back to the metrics</a></p></section>')
    return "\n".join(out)


def parameters_html(
    parameters: Sequence[dict[str, Any]],
    fitted: Sequence[dict[str, Any]],
    text: Callable[[Any], str],
    from_trials: Sequence[dict[str, Any]] = (),
) -> str:
    """Every model parameter with its value, 1-sigma uncertainty, unit, source and basis; ``fitted``: the
    parameters fitted on these trials (the calibrated model), listed after the held ones; ``from_trials``: those
    the critical slope from the trials took from the trials instead (source ``trials``: the inertia from the
    step periods), listed last."""
    out = [
        '<h2 id="parameters-heading">Wheel parameters</h2><div class="wide"><table id="parameters"><thead><tr>'
        "<th>parameter</th><th>value</th><th>1 sigma</th><th>unit</th><th>source</th><th>basis</th></tr></thead>"
        "<tbody>"
    ]
    roles = [(p, "held") for p in parameters] + [(p, "fitted") for p in fitted]
    roles += [(p, "from-trials") for p in from_trials]
    only = {
        "held": "",
        "fitted": " (the calibrated model only)",
        "from-trials": " (the critical slope from the trials only)",
    }
    for p, role in roles:
        sd = "exact" if p["sd"] == 0 else format(p["sd"], ".3g")
        label = SOURCE_LABELS.get(p["source"], p["source"])
        what = only[role]
        out.append(
            f'<tr class="parameter {role}"><td>{text(p["symbol"])} <span class="small">{text(p["name"])}</span></td>'
            f'<td class="n">{num(p["value"], ".4g")}</td><td class="n">{sd}</td><td>{text(p["unit"])}</td>'
            f'<td data-source="{text(p["source"])}">{text(label)}{what}</td><td>{text(p["basis"])}</td></tr>'
        )
    out.append(
        "</tbody></table></div>"
        "<p class=\"small\">The comparisons and the model's critical slope use the held values; the critical slopes' "
        'intervals carry their uncertainty (docs/trials.md, "What is held, is carried"). Sources: Table 1 (the '
        "paper's, with an assumed uncertainty), wheel file (--params), Wheel (Python API), leg test (--prior), "
        "fitted (on these trials), the trials' step periods (an inertia the wheel input does not state).</p>"
    )
    return "\n".join(out)


def provenance_html(prov: Any) -> str:
    """The version, command line, date, wheel file and every file read with its SHA-256."""
    e = html.escape
    rows = [
        ("rimless", e(prov.version)),
        ("command", f"<code>{e(prov.command)}</code>"),
        ("date", e(prov.date_utc)),
        ("wheel file", e(prov.wheel_file) if prov.wheel_file else "none: Table 1 with the assumed uncertainties"),
    ]
    facts = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    files = "".join(
        f'<tr><td>{e(f.role)}</td><td>{breakable(f.name)}</td><td class="n">{f.size_bytes}</td>'
        f"<td><code>{e(f.sha256)}</code></td></tr>"
        for f in prov.files
    )
    return (
        f'<h2 id="provenance">Provenance</h2><table class="facts" id="provenance-facts">{facts}</table>'
        '<div class="wide"><table id="input-files"><thead><tr><th>role</th><th>file</th><th>bytes</th>'
        f"<th>SHA-256</th></tr></thead><tbody>{files}</tbody></table></div>"
        '<p class="small">Files by name and content hash (no folder of the machine the report was made on).</p>'
    )


def periods_html(groups: Sequence[Any], slope_bin_deg: float | None) -> str:
    """Step period per series, slope bin and step: trials, mean, std and the simulation (``slope_bin_deg`` None:
    bins of overlapping slope intervals, `rimless.analysis.report.series.interval_bins`)."""
    e = html.escape
    if not groups:
        return ""
    bins = f"bins of {slope_bin_deg:g} deg" if slope_bin_deg is not None else "bins of overlapping slope intervals"
    out = [
        f'<h2 id="periods-heading">Step period by series and slope ({bins})</h2>'
        '<div class="wide"><table id="periods"><thead><tr><th>series</th><th>release</th><th>ended</th>'
        "<th>slope bin, deg</th>"
        "<th>step</th>"
        "<th>trials</th><th>mean, ms</th><th>std, ms</th><th>simulated, ms</th></tr></thead><tbody>"
    ]
    for g in groups:
        for row in g.rows():
            out.append(
                f"<tr><td>{breakable(str(row.get('series', '')))}</td><td>{e(str(row.get('release', '')))}</td>"
                f"<td>{e(str(row.get('outcome', '')))}</td>"
                f'<td class="n">{e(str(row.get("slope_bin_label_deg", format(row["slope_deg"], "g"))))}</td>'
                f'<td class="n">{row["step"]}</td>'
                f'<td class="n">{row["trials"]}</td><td class="n">{num(row["mean_period_ms"], ".1f")}</td>'
                f'<td class="n">{num(row["std_period_ms"], ".1f")}</td>'
                f'<td class="n">{num(row["sim_period_ms"], ".1f")}</td></tr>'
            )
    out.append("</tbody></table></div>")
    for g in groups:
        if g.message:
            where = " ".join(
                x
                for x in (str(getattr(g, "series", "")), str(getattr(g, "release", "")), getattr(g, "outcome", ""))
                if x
            )
            out.append(f'<p class="bad">{e(where)} {e(g.slope_label)} deg: {e(g.message)}</p>')
    return "\n".join(out)


#: body 16 px, tables at .85em (13.6 px); numbers never wrap; a table wider than the page scrolls in its wrapper
CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;font-size:16px;margin:2em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.5em;margin-bottom:.2em} h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ddd} h3{font-size:1em;margin:1.4em 0 .3em}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0} th,td{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}
td{overflow-wrap:break-word} th{background:#f3f3f3;font-weight:600} td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.wide{overflow-x:auto;max-width:100%} table.facts th{white-space:nowrap} code{font-size:.95em;overflow-wrap:anywhere}
.ok{color:#1a7f37} .bad{color:#b42318} .suspect{color:#b54708;font-weight:bold} .note{background:#fff8e1;border-left:4px solid #f0b400;padding:.5em .8em}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #eee} figcaption{font-size:.85em;color:#555}
.small{font-size:.85em;color:#555} ul.small,ul.bad{margin-top:0;font-size:.85em} section.trial{border-top:1px solid #eee}
"""
