"""Series of trials: the step-period trends are averaged within a series, never across series.

A series is the trials of one wheel and one set-up: by default the file name without what varies from run to
run (a slope token such as ``slope2.0deg`` or ``1.5deg``, a run token such as ``run2``, ``take3``,
``release1.9``, ``trial04``, a trailing counter), so ``wheelA_slope2.0deg_run1.csv`` and
``wheelA_slope1.5deg_run2.csv`` are series ``wheelA``, and a file name with nothing left (``run1.csv``) belongs
to the series of its folder's name. A mapping given by the caller (file name or path -> series) overrides
this. Within a series the trials are binned by slope (`rimless.analysis.inference.compare.step_period_trends`);
two series at the same rounded slope stay two groups (a wheel with another damping walks at other periods).
A release condition the file name states (``release1.9``: `release_condition`) is a run token for the series,
but trials of two release conditions are never pooled: each condition is binned on its own (a release at 1.9
rad/s and one at 2.5 rad/s start different transients; pooled, their step periods' std is the difference of
the two walks, not the scatter of repeats). Runs of one condition (``run1``, ``run2``) are pooled as repeats.
Nor are trials that ended differently (their importer's outcome, `rimless.analysis.kinematics.walk.OUTCOMES`,
when the caller gives it): a trial that stalled after two steps and one that walked on are binned apart and each
bin is named by its outcome (pooled, the bin's mean after step 2 was the walker alone and its std the gap between
a stall and a walk; the demo's ``release1.9`` panel, session 22).

A slope bin of None (``rimless demo``'s default) bins by the slopes' own intervals instead of a width
(`interval_bins`): within a series, trials are pooled only while their 95 % slope intervals share a common
slope, so no bin pools trials whose slopes differ beyond their intervals (`pooled_slope_warnings` then has
nothing to say); the bin is named by the range of its trials' slopes (`range_label`; its ``slope_deg`` is their
mean, which may lie outside a member's own interval).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from rimless.analysis.inference.compare import Simulator, SlopeGroup, TrialComparison, step_period_trends

__all__ = [
    "SeriesSlopeGroup",
    "series_name",
    "series_of",
    "series_trends",
    "file_stem",
    "pooled_slope_warnings",
    "interval_bins",
    "slope_bin_words",
    "release_condition",
    "range_label",
]

#: the slope bin `step_period_trends` is handed for one bin made by `interval_bins`: wide enough to round every
#: slope the model takes (0 <= phi < alpha/2) to the same key, deg
_ONE_BIN_DEG = 1e3

_SUFFIXES = (".trial.parquet", ".parquet", ".csv", ".c3d", ".txt")
#: tokens that vary from run to run within a series: a slope, a run/take/trial/release number, a bare counter
_RUN_TOKEN = re.compile(
    r"^(?:slope)?[+-]?\d+(?:[.p]\d+)?(?:deg|d|°)$"
    r"|^slope[+-]?\d+(?:[.p]\d+)?$"
    r"|^(?:run|take|trial|rep|repeat|release|try|attempt|r|t)[+-]?\d+(?:[.p]\d+)?$"
    r"|^\d+$",
    re.IGNORECASE,
)
_SEPARATORS = re.compile(r"[_\-\s]+")
#: a run token that names a release condition (never pooled with another: `release_condition`)
_RELEASE_TOKEN = re.compile(r"^release[+-]?\d+(?:[.p]\d+)?$", re.IGNORECASE)


def file_stem(name: str) -> str:
    """A trial's file name without its format suffix (``a.trial.parquet`` -> ``a``, ``b.csv`` -> ``b``)."""
    base = Path(name).name
    for suffix in _SUFFIXES:
        if base.lower().endswith(suffix):
            return base[: -len(suffix)]
    return Path(base).stem


def series_name(path: str | Path) -> str:
    """The series of a trial file from its name (see the module doc); its folder's name when nothing is left."""
    stem = file_stem(str(path))
    kept = [t for t in _SEPARATORS.split(stem) if t and not _RUN_TOKEN.match(t)]
    if kept:
        sep = m.group(0)[0] if (m := _SEPARATORS.search(stem)) else "_"
        return sep.join(kept)
    folder = Path(path).parent.name
    return folder or stem


def release_condition(path: str | Path) -> str:
    """The release condition a trial file's name states (its ``release<number>`` token as written, e.g.
    ``release1.9``), "" when none: trials of different conditions are binned apart within their series."""
    stem = file_stem(str(path))
    return next((t for t in _SEPARATORS.split(stem) if _RELEASE_TOKEN.match(t)), "")


def series_of(files: Sequence[str | Path], given: Mapping[str, str] | None = None) -> list[str]:
    """The series of each trial file: ``given`` (keyed by the file's name, its path as given or resolved) first,
    else `series_name`."""
    given = dict(given or {})
    resolved = {}
    for k, v in given.items():
        try:
            resolved[str(Path(k).resolve())] = v
        except OSError:
            continue
    out = []
    for f in files:
        key = next((k for k in (str(f), Path(f).name) if k in given), None)
        if key is not None:
            out.append(given[key])
            continue
        try:
            hit = resolved.get(str(Path(f).resolve()))
        except OSError:
            hit = None
        out.append(hit if hit is not None else series_name(f))
    return out


@dataclass
class SeriesSlopeGroup(SlopeGroup):
    """A `SlopeGroup` of one series: the slope bin's trials are all of ``series``."""

    series: str = ""
    #: the release condition its trials' file names state (`release_condition`), "" when none
    release: str = ""
    #: how its trials ended (the importer's outcome: "walked", "stalled", ...), "" when not given
    outcome: str = ""

    def rows(self) -> list[dict[str, Any]]:
        """`SlopeGroup.rows` with the series, the release condition and the trials' outcome named in each row."""
        return [
            {"series": self.series, "release": self.release, "outcome": self.outcome} | row for row in super().rows()
        ]


def slope_bin_words(slope_bin_deg: float | None) -> str:
    """How the step periods were binned by slope, for captions and headings."""
    if slope_bin_deg is None:
        return "trials pooled only while their 95 % slope intervals overlap; a bin is labelled by its trials' slopes"
    return f"slopes rounded to {slope_bin_deg:g} deg"


def range_label(slope_range_deg: tuple[float, float]) -> str:
    """A bin of `interval_bins` named by the range of its trials' slopes, deg (``1.344-1.596``; one slope when
    they agree to 0.001 deg): every trial's own slope lies in it, which its mean slope need not (a mean of
    trials whose intervals overlap may fall outside one member's interval)."""
    lo, hi = (round(v, 3) for v in slope_range_deg)
    return f"{lo:.3f}" if lo == hi else f"{lo:.3f}-{hi:.3f}"


def interval_bins(
    comparisons: Sequence[TrialComparison], slopes: Mapping[str, tuple[float, Sequence[float] | None]]
) -> list[list[TrialComparison]]:
    """The comparisons with steps and a finite slope in bins of slopes that agree: in ascending slope, a trial
    joins the current bin while every 95 % interval in it, its own included, shares a common slope, else it
    starts the next bin. ``slopes``: per trial name, its slope and 95 % interval, deg (a trial without a finite
    interval, e.g. a slope given with ``--slope-deg``, is taken as exactly its slope)."""

    def interval(c: TrialComparison) -> tuple[float, float]:
        _, ci = slopes.get(c.name, (c.slope_deg, None))
        if ci is not None and len(ci) == 2 and all(math.isfinite(v) for v in ci):
            return float(min(ci)), float(max(ci))
        return c.slope_deg, c.slope_deg

    bins: list[list[TrialComparison]] = []
    lo, hi = math.inf, -math.inf
    for c in sorted((c for c in comparisons if c.n_steps and math.isfinite(c.slope_deg)), key=lambda c: c.slope_deg):
        a, b = interval(c)
        if bins and max(lo, a) <= min(hi, b):
            bins[-1].append(c)
            lo, hi = max(lo, a), min(hi, b)
        else:
            bins.append([c])
            lo, hi = a, b
    return bins


def series_trends(
    comparisons: Sequence[TrialComparison],
    series: Sequence[str],
    sim: Simulator | None = None,
    *,
    slope_bin_deg: float | None = 0.5,
    slopes: Mapping[str, tuple[float, Sequence[float] | None]] | None = None,
    outcomes: Sequence[str] | None = None,
) -> list[SeriesSlopeGroup]:
    """Step period against step number per series, release condition, outcome and slope bin (series in order of
    first appearance, then their release conditions (`release_condition` of each trial's file name) in that order,
    then the outcomes in that order, slopes ascending within each); ``series``: the series of each comparison
    (`series_of`), in the same order; ``outcomes``: how each trial ended (its importer's outcome), in the same
    order (None: not split by outcome). ``slope_bin_deg`` None: the bins of `interval_bins` on ``slopes`` (per
    trial name, its slope and 95 % interval, deg), each at its trials' mean slope (``slope_deg``, to 0.001 deg)
    and named by their range (`range_label`)."""
    if len(series) != len(comparisons):
        raise ValueError(f"{len(series)} series for {len(comparisons)} comparisons")
    ends = [""] * len(comparisons) if outcomes is None else [str(o) for o in outcomes]
    if len(ends) != len(comparisons):
        raise ValueError(f"{len(ends)} outcomes for {len(comparisons)} comparisons")
    order: dict[str, dict[tuple[str, str], list[TrialComparison]]] = {}
    for c, s, end in zip(comparisons, series, ends):
        order.setdefault(s, {}).setdefault((release_condition(c.file or c.name), end), []).append(c)
    out = []
    keyed = ((n, r, end, cs) for n, conds in order.items() for (r, end), cs in _conditions_in_order(conds))
    for name, release, outcome, comps in keyed:
        if slope_bin_deg is None:
            groups = []
            for trials in interval_bins(comps, slopes or {}):
                (g,) = step_period_trends(trials, sim, slope_bin_deg=_ONE_BIN_DEG)
                g.slope_deg = round(sum(c.slope_deg for c in trials) / len(trials), 3)
                g.label = range_label(g.slope_range_deg)
                groups.append(g)
        else:
            groups = step_period_trends(comps, sim, slope_bin_deg=slope_bin_deg)
        for g in groups:
            out.append(
                SeriesSlopeGroup(
                    **{f.name: getattr(g, f.name) for f in fields(g)}, series=name, release=release, outcome=outcome
                )
            )
    return out


def _conditions_in_order(
    conds: Mapping[tuple[str, str], list[TrialComparison]],
) -> list[tuple[tuple[str, str], list[TrialComparison]]]:
    """A series' (release condition, outcome) groups: release conditions in order of first appearance, each
    one's outcomes after it in theirs."""
    releases = list(dict.fromkeys(r for r, _ in conds))
    return sorted(conds.items(), key=lambda kv: releases.index(kv[0][0]))


def pooled_slope_warnings(
    groups: Sequence[SlopeGroup],
    slopes: Mapping[str, tuple[float, Sequence[float] | None]],
    slope_bin_deg: float | None,
) -> list[str]:
    """One warning per slope bin whose trials walked on slopes that differ beyond their 95 % intervals (two
    disjoint intervals) while their step periods are pooled by the rounding to ``slope_bin_deg``.

    ``slopes``: per trial name, its slope and 95 % interval, deg (None or NaN bounds: not judged). The two
    trials named are the bin's farthest apart: the one whose interval ends lowest and the one whose interval
    starts highest."""
    out = []
    for g in groups:
        known: list[tuple[str, float, Sequence[float]]] = []
        for n in g.trials:
            slope, ci = slopes.get(n, (math.nan, None))
            if ci is not None and len(ci) == 2 and all(math.isfinite(v) for v in ci):
                known.append((n, slope, ci))
        if len(known) < 2:
            continue
        low = min(known, key=lambda t: t[2][1])
        high = max(known, key=lambda t: t[2][0])
        if high[2][0] <= low[2][1]:
            continue
        series = getattr(g, "series", "")
        release = getattr(g, "release", "")
        how = (
            f"--slope-bin-deg {slope_bin_deg:g} rounds them together"
            if slope_bin_deg is not None
            else "binned by their slopes' intervals"
        )

        def told(t: tuple[str, float, Sequence[float]]) -> str:
            return f"{t[0]} ({t[1]:.3f} deg, 95 % {t[2][0]:.3f} to {t[2][1]:.3f})"

        out.append(
            f"{'series ' + repr(series) + ', ' if series else ''}{release + ', ' if release else ''}slope bin {g.slope_label} deg: the step periods "
            f"of {len(g.trials)} trials are pooled, but {told(low)} and {told(high)} walked on slopes that differ "
            f"beyond their intervals ({how}): give a smaller --slope-bin-deg (slope_bin_deg=) to keep them apart"
        )
    return out
