"""How honest is `trials floquet`'s interval (``rimless trials floquet-coverage``): series of truth trials
(`rimless.analysis.validation.floquet_truth`), recorded as Vicon Tracker exports, imported and estimated as the
command does; the share of 95 % intervals holding the truth's multiplier, with the errors:

    rimless trials floquet-coverage --kind rigid --series 300 --seed 3
    rimless trials floquet-coverage --kind er --series 100 --seed 4

Each series: ``--trials`` trials of ``--steps`` impacts at one slope, each released at its gait's speed times
U(0.9, 1.1), each step's slope N(slope, ``--slope-sd-deg``^2). rigid: the rigid truth wheel (M 2.6 kg, I_hub
0.05 kg m^2, L 0.21 m; truth beta^2 = 0.634, closed form) at 4.5 deg; er: an ER wheel with k = 2000 N/m,
c = 14 N s/m (Table 1: 2700, 8) at 2.5 deg, walked by the truth model ``truth`` (`TRUTHS`, the JSON's ``truth``
and ``truth_model``):

- ``independent`` (default): `rimless.analysis.validation.er_truth` (the ER wheel of docs/model.md written apart
  from `rimless.sim`: `er_truth.er_truth_walk`), its multiplier that truth's own (`er_truth.multiplier`: the
  dominant eigenvalue of its step map's Jacobian at its own fixed point), so a defect the simulator and the
  estimate shared would show;
- ``simulator``: the simulator's ER wheel (`floquet_truth.er_walk`), its multiplier the model's dominant
  eigenvalue there (`rimless.analysis.inference.floquet.model_multiplier`), as before.

The same seed draws the same releases and per-step slopes under both truths (each walk draws one normal a step
and the recording the same noise) until a walk stalls on one truth and not on the other, or a recording is
one frame longer on one. The importer is told
the wheel (`told_wheel`, for its legs' drift in the slope's interval), as a user would. ``rms_z``: the rms of
(estimate - truth) / se over the series (the corrected and lagged estimates' se; the OLS interval's half width
over its t point), 1 when the se is honest; ``coverage_wilson95``: the Wilson interval of the coverage beside
``coverage_ci95`` (Clopper-Pearson, as before).
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import binomtest

from rimless.analysis.validation.coverage import wilson_interval
from rimless.analysis.validation.floquet_truth import RigidWheel, er_walk, record, rigid_multiplier, rigid_walk

#: the ER truth models (``run``'s ``truth``); the first is the default
TRUTHS = ("independent", "simulator")
#: what each is (the JSON's ``truth_model`` starts with it)
TRUTH_MEANING = {
    "independent": "er_truth, the ER wheel of docs/model.md written apart from rimless.sim (hub coordinates, "
    "Newton-Euler, scipy events); its multiplier from its own step map's Jacobian at its own gait",
    "simulator": "the simulator's ER wheel (floquet_truth.er_walk); its multiplier the model's dominant eigenvalue",
}
RIGID_MEANING = "floquet_truth.rigid_walk, the rigid wheel written here (RK4 stance, closed-form beta^2)"


def truth_of(kind: str, truth: str = "simulator") -> tuple[Any, float, float]:
    """(wheel, slope deg, true multiplier) of ``kind``; for ``er`` of the truth model ``truth`` (`TRUTHS`)."""
    if kind == "rigid":
        wheel = RigidWheel()
        return wheel, 4.5, rigid_multiplier(wheel)
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {', '.join(TRUTHS)}, got {truth!r}")
    from rimless.sim.model.params import WheelParams

    params = WheelParams(stiffness_n_per_m=2000.0, damping_ns_per_m=14.0)
    if truth == "independent":
        from rimless.analysis.validation.er_truth import ERWheel, multiplier

        return params, 2.5, multiplier(ERWheel.of(params, slope_rad=math.radians(2.5)))
    from rimless.analysis.inference.floquet import model_multiplier

    return params, 2.5, float(model_multiplier(params.replace(slope_rad=math.radians(2.5)), "er")["eigenvalue"])


def _ols_sd(e: Any) -> float:
    """The OLS estimate's sd: its interval's half width over Student's 97.5 % point (n_pairs - 2 dof)."""
    from scipy.stats import t as student

    return (e.ols_ci95[1] - e.ols_ci95[0]) / 2 / float(student.ppf(0.975, e.n_pairs - 2))


def told_wheel(kind: str, truth: Any) -> Any:
    """The wheel a user who knows the truth states, handed to the importer for its legs' drift (as `trials import
    --rigid-legs` or `trials floquet --params` do): rigid legs for the rigid truth; for the ER truth its k and c
    with the example's uncertainties (``floquet_truth``'s wheel.toml: k 2000 +- 100 N/m, c 14 +- 2 N s/m)."""
    from rimless.sim import Wheel

    if kind == "rigid":
        return Wheel(model="rigid")
    return Wheel(truth, uncertainty={"k": 100.0, "c": 2.0})


def run(
    kind: str,
    series: int,
    trials: int,
    steps: int,
    slope_sd_deg: float,
    seed: int,
    progress: Callable[[int], None] | None = None,
    labs: str = "fixed",
    truth: str = "independent",
) -> dict[str, Any]:
    """The study's JSON object (see the module's docstring); ``progress(i)`` after each series; ``truth``: the
    ER truth model (`TRUTHS`; the rigid truth is one). ``labs``:
    ``fixed`` (a Z-up lab, the ramp heading 25 deg, a Tracker object: the figures of docs/trials.md) or
    ``drawn`` (per series a lab drawn by `importer_coverage.draw_lab` from its own generator: Z-up or Y-up, any
    heading, an object or four markers; `critical_truth.record`)."""
    from rimless.analysis.inference.floquet import NotIdentifiable, estimate_multiplier, group_data, section_points
    from rimless.analysis.kinematics.build import import_trial
    from rimless.analysis.kinematics.slope_evidence import leg_compliance
    from rimless.analysis.validation.critical_truth import record as record_in_lab
    from rimless.analysis.validation.er_truth import TruthFailure, er_truth_walk
    from rimless.analysis.validation.importer_coverage import draw_lab
    from rimless.errors import RimlessError
    from rimless.sim.model.failures import StepFailure

    if labs not in ("fixed", "drawn"):
        raise ValueError(f"labs must be 'fixed' or 'drawn', got {labs!r}")
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {', '.join(TRUTHS)}, got {truth!r}")
    model = truth
    walker = er_truth_walk if model == "independent" else er_walk
    wheel, slope, truth_value = truth_of(kind, model)
    told = told_wheel(kind, wheel)
    rng = np.random.default_rng(seed)
    lab_rng = np.random.default_rng([seed, 1])  # apart from rng: the fixed labs' figures do not change
    lab_counts = {"y_up": 0, "markers": 0}
    rows, flags, failed = [], [], []
    stalls = 0
    cpu = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"trial{os.getpid()}.csv"
        for i_series in range(series):
            if progress is not None and i_series:
                progress(i_series)
            lab = draw_lab(lab_rng) if labs == "drawn" else None
            if lab is not None:
                lab_counts["y_up"] += lab.up == "y"
                lab_counts["markers"] += lab.markers
            pts = []
            for _ in range(trials):
                rel = float(rng.uniform(0.9, 1.1))
                if kind == "rigid":
                    walk = rigid_walk(wheel, slope, slope_sd_deg, steps, rng, start=rel * wheel.fixed_point(slope))
                else:
                    try:
                        walk = walker(wheel, slope, slope_sd_deg, steps, rng, release=rel)
                    except (TruthFailure, StepFailure) as err:  # a stall before the second impact: no trial
                        flags.append(f"truth walk failed: {type(err).__name__}")
                        continue
                stalls += walk.stalled
                if lab is None:
                    record(walk, path, rng)
                else:
                    record_in_lab(walk, path, rng, lab, rest_s=0.0)
                try:
                    trial = import_trial(path, wheel=told)
                except RimlessError as err:  # a refused import is counted, as a user would drop the file
                    flags.append("refused: " + str(err).splitlines()[0][:60])
                    continue
                p = section_points(trial, path.name)
                if p.status != "used":
                    flags.append(p.reason.split(":")[0])
                pts.append(p)
            x, y, v, triples = group_data(pts)
            try:
                e = estimate_multiplier(x, y, v, triples)
            except NotIdentifiable as err:
                failed.append(str(err).split(":")[0])
                continue
            rows.append(e)
    if progress is not None:
        progress(series)
    out: dict[str, Any] = {
        "kind": kind,
        "truth": model,
        "truth_model": RIGID_MEANING if kind == "rigid" else TRUTH_MEANING[model],
        "truth_multiplier": truth_value,
        "series": series,
        "trials_per_series": trials,
        "steps": steps,
        "slope_deg": slope,
        "slope_sd_deg": slope_sd_deg,
        "seed": seed,
        "labs": labs,
        "drawn_labs": lab_counts if labs == "drawn" else None,
        "import_legs": leg_compliance(told).source,
        "estimated": len(rows),
        "stalled_trials": stalls,
        "flagged_trials": {k: flags.count(k) for k in sorted(set(flags))},
        "not_estimated": {k: failed.count(k) for k in sorted(set(failed))},
        "median_reliability": float(np.median([e.reliability for e in rows])) if rows else None,
        "cpu_s": time.process_time() - cpu,
    }
    lag = [e for e in rows if e.lagged is not None and e.lagged_ci95 is not None]
    for name, est, ci, se in (
        ("corrected", [e.multiplier for e in rows], [e.ci95 for e in rows], [e.se for e in rows]),
        # the OLS interval's sd: its half width over the t point it used (n_pairs - 2 degrees of freedom)
        ("ols", [e.ols for e in rows], [e.ols_ci95 for e in rows], [_ols_sd(e) for e in rows]),
        ("lagged", [e.lagged for e in lag], [e.lagged_ci95 for e in lag], [e.lagged_se for e in lag]),
    ):
        if not ci:  # no series gave an estimate: nothing to count (never NaN)
            out[name] = {"covered": 0, "of": 0, "coverage": None, "coverage_ci95": None}
            continue
        a, c = np.array(est, float), np.array(ci, float)
        hits = int(np.sum((c[:, 0] <= truth_value) & (truth_value <= c[:, 1])))
        lo, hi = binomtest(hits, len(c)).proportion_ci(0.95)
        wlo, whi = wilson_interval(hits, len(c))
        z = (a - truth_value) / np.array(se, float)
        out[name] = {
            "covered": hits,
            "of": len(c),
            "coverage": hits / len(c),
            "coverage_ci95": [lo, hi],
            "coverage_wilson95": [wlo, whi],
            "rms_z": float(np.sqrt(np.mean(z**2))),
            "median_error": float(np.median(a - truth_value)),
            "median_abs_error": float(np.median(np.abs(a - truth_value))),
            "median_ci_width": float(np.median(c[:, 1] - c[:, 0])),
        }
    return out
