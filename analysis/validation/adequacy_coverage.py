"""How often `rimless.analysis.calibrate`'s adequacy check and model choice give the right verdict, by simulation.

Each series draws an ER wheel away from Table 1 (k 1500-4000 N/m, c 2-20 N s/m: `calibrate_coverage.K_RANGE`,
``C_RANGE``; guide friction F_c 0 or U(0.1, 0.6) N; the rest Table 1's), walks it with a truth model
(``truth``, `calibrate_coverage.TRUTHS`: ``independent``, `er_truth`, the ER wheel written apart from the
simulator with exact stick/slip guide friction, the default since session 22; ``simulator``, the simulator's ER
model, `floquet_truth.er_walk`, before; no slope wander) on
``trials`` slopes of 2-3.5 deg, each released at its gait's speed times U(0.95, 1.08), writes each walk as a Vicon
export in a lab drawn per series (`importer_coverage.draw_lab`, `critical_truth.record`: 0.3 mm, 1 mrad of
noise, 100 Hz), imports it (the refusals) and hands the exports to the calibration as a user would (it imports
them told the held wheel's legs; k fitted: the importer's bound, then again told the fitted k,
`rimless.analysis.api.slope_passes`), under one `SCENARIOS` entry, the held parameters exact (``uncertainty``
0) except the one the scenario makes wrong:

- ``adequate``: frictionless truth, ``--fit c,k``: the model is the truth, so "does not fit" is a false alarm
  (nominal: below ``ADEQUACY_P`` = 0.1 %, the ratio condition making it rarer still);
- ``adequate-true-slope``: as ``adequate`` with each trial's imported slope replaced by the truth's (a
  diagnosis: the calibration holds the importer's slope exact, and the step periods resolve its error);
- ``held-k``: frictionless truth, ``--fit c`` with k held 25 % off the truth (sign drawn): a misfit, counted
  as detected when the check says "does not fit" (the known gap: c may absorb it);
- ``friction-misfit``: a truth with guide friction fitted as ``c,k`` with F_c held at 0: a misfit (held exactly,
  so the calibration probes it by freeing it, `calibrate._held_exact_probe`: ``held_exact_probe`` per series and
  per scenario, with what it flagged and its CPU time);
- ``choice-null``: frictionless truth, ``--fit c,guide_friction_n`` (k exact): friction claimed (the
  likelihood-ratio test's p < ``MODEL_CHOICE_P``) is a false claim (nominal 1 %);
- ``choice-friction``: a truth with friction, ``--fit c,guide_friction_n`` (k exact, F_c starting at 0):
  friction found is the power (``by_detectable_above``: found where the truth lies above the model choice's
  stated detection limit, ``detectable_above``, and below it).

Reported per scenario: the rate of each verdict with its Wilson 95 % interval, the overall chi^2/dof ratios and
p-values (how often p < 0.05 and 0.01: for the adequate and null scenarios these should be about 5 % and 1 %
if the noise estimate and the tests are calibrated), per fitted parameter (``estimates``) how often it is called
identifiable and how often its 95 % interval holds the truth, and every refused import and failed fit with its
reason.

Both truths are the model the calibration fits (model.md's ER wheel with its guide friction; `er_truth` is a
second implementation of it, meeting the simulator's step map to 1e-8 in its test): the null scenarios check the
tests' calibration when the model is right, not the model's adequacy to a real wheel.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.validation.calibrate_coverage import C_RANGE, K_RANGE, TRUTH_MEANING, TRUTHS, walk_and_import
from rimless.analysis.validation.coverage import wilson_interval
from rimless.analysis.validation.importer_coverage import draw_lab

__all__ = ["F_RANGE", "HELD_K_ERROR", "SCENARIOS", "Scenario", "run_adequacy_coverage"]

F_RANGE = (0.1, 0.6)  # guide friction of the friction truths, N
HELD_K_ERROR = 0.25  # the held-k scenario's relative error of the held stiffness


@dataclass(frozen=True)
class Scenario:
    """One calibration set-up: the truth (``friction``), what is fitted, what a right verdict is."""

    friction: bool  # the truth has guide friction F_c ~ U(F_RANGE)
    fit: tuple[str, ...]
    k_error: float  # relative error of the held k (0: exact)
    verdict: str  # "does_not_fit" (adequacy) or "friction_claimed" (model choice)
    truth_answer: bool  # the right verdict: True when the truth makes it so
    nominal_rate: float | None  # the rate the thresholds promise when the right verdict is False
    what: str
    true_slope: bool = False  # a diagnosis: each trial's slope replaced by the truth's (the importer's is held exact)


SCENARIOS = {
    "adequate": Scenario(False, ("c", "k"), 0.0, "does_not_fit", False, 1e-3, "frictionless truth, fit c,k"),
    "adequate-true-slope": Scenario(
        False, ("c", "k"), 0.0, "does_not_fit", False, 1e-3, "as adequate, the trials' true slopes given", True
    ),
    "held-k": Scenario(
        False, ("c",), HELD_K_ERROR, "does_not_fit", True, None, "frictionless truth, fit c, k held 25 % off"
    ),
    "friction-misfit": Scenario(
        True, ("c", "k"), 0.0, "does_not_fit", True, None, "truth with guide friction, fit c,k (F_c held at 0)"
    ),
    "choice-null": Scenario(
        False, ("c", "guide_friction_n"), 0.0, "friction_claimed", False, 0.01, "frictionless truth, fit c,F_c"
    ),
    "choice-friction": Scenario(
        True, ("c", "guide_friction_n"), 0.0, "friction_claimed", True, None, "truth with guide friction, fit c,F_c"
    ),
}

_FIELD = {"c": "damping_ns_per_m", "k": "stiffness_n_per_m", "guide_friction_n": "guide_friction_n"}


def run_adequacy_coverage(
    n_series: int,
    seed: int,
    calibrate: Callable[..., Any],
    *,
    scenarios: Sequence[str] = tuple(SCENARIOS),
    trials: int = 4,
    steps: int = 10,
    progress: Callable[[int, str], None] | None = None,
    truth: str = "independent",
) -> dict[str, Any]:
    """``n_series`` series per scenario (the same seed draws the same wheels in every scenario that shares the
    truth's kind); ``calibrate(trials, fit=..., wheel=..., names=...)`` is the public `rimless.analysis.calibrate`.
    ``progress(done, what)`` counts series over all scenarios. ``truth``: the ER wheel that walks the trials
    (`calibrate_coverage.TRUTHS`: ``independent``, `er_truth`, written apart from the simulator, the default since
    session 22; ``simulator``, the calibration's own model, as before). Returns the JSON-ready summary."""
    bad = [s for s in scenarios if s not in SCENARIOS]
    if bad or not scenarios:
        raise ValueError(f"scenario takes {', '.join(SCENARIOS)}, got {list(scenarios)}")
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {', '.join(TRUTHS)}, got {truth!r}")
    cpu, wall = time.process_time(), time.perf_counter()
    out: dict[str, Any] = {}
    done = 0
    with tempfile.TemporaryDirectory(prefix=f"rimless-adqcov-{os.getpid()}-") as tmp:
        for name in scenarios:
            sc = SCENARIOS[name]
            rng = np.random.default_rng([seed, int(sc.friction)])
            rows = []
            for i in range(n_series):
                what = f"{name} {i + 1}/{n_series}"
                rows.append(
                    _series(sc, rng, Path(tmp) / f"{name}_{i}", calibrate, trials, steps, progress, what, done, truth)
                )
                done += 1
                if progress:
                    progress(done, f"{what}: done")
            out[name] = _summary(sc, rows)
    return {
        "truth": truth,
        "truth_model": TRUTH_MEANING[truth] + ": k, c drawn; guide friction F_c drawn in the friction scenarios; "
        "recorded as Vicon exports in drawn labs and imported (rimless.analysis.validation.adequacy_coverage)",
        "thresholds": _thresholds(),
        "scenarios": out,
        "series_per_scenario": n_series,
        "trials_per_series": trials,
        "steps": steps,
        "seed": seed,
        "cpu_s": time.process_time() - cpu,
        "wall_s": time.perf_counter() - wall,
    }


def _thresholds() -> dict[str, float]:
    from rimless.analysis.inference.adequacy import ADEQUACY_P, ADEQUACY_RATIO
    from rimless.analysis.inference.calibrate import MODEL_CHOICE_P

    return {"adequacy_p": ADEQUACY_P, "adequacy_ratio": ADEQUACY_RATIO, "model_choice_p": MODEL_CHOICE_P}


def _series(
    sc: Scenario,
    rng: np.random.Generator,
    stem: Path,
    calibrate: Callable[..., Any],
    trials: int,
    steps: int,
    progress: Callable[[int, str], None] | None,
    what: str,
    done: int,
    truth_model: str = "independent",
) -> dict[str, Any]:
    """One series: draw the wheel and lab, walk (the truth model ``truth_model``), write, import, calibrate; the
    verdicts and figures."""
    from rimless.errors import RimlessError
    from rimless.sim import Wheel
    from rimless.sim.model.params import WheelParams
    from rimless.sim.model.uncertain import UNCERTAIN_FIELDS

    truth = WheelParams(
        stiffness_n_per_m=float(rng.uniform(*K_RANGE)),
        damping_ns_per_m=float(rng.uniform(*C_RANGE)),
        guide_friction_n=float(rng.uniform(*F_RANGE)) if sc.friction else 0.0,
    )
    sign = float(rng.choice([-1.0, 1.0]))
    held = truth.replace(
        stiffness_n_per_m=truth.stiffness_n_per_m * (1.0 + sign * sc.k_error), guide_friction_n=0.0
    )  # the model the calibration holds: F_c 0 (fitted from 0 when in ``fit``), k off by the scenario's error
    lab = draw_lab(rng)
    row: dict[str, Any] = {
        "truth": {n: getattr(truth, f) for n, f in _FIELD.items()},
        "held_k_n_per_m": held.stiffness_n_per_m,
        "lab": {"up": lab.up, "heading_deg": lab.heading_deg, "markers": lab.markers},
    }
    if progress:
        progress(done, f"{what}: walking and writing")
    stem.mkdir(parents=True, exist_ok=True)
    series = walk_and_import(
        truth,
        lab,
        rng,
        stem,
        "",
        trials,
        steps,
        importing=(lambda: progress(done, f"{what}: importing and calibrating")) if progress else None,
        model=truth_model,
    )
    paths, refused, slopes, loaded, names = series.paths, series.refused, series.slopes_deg, series.loaded, series.names
    row.update(
        trials=len(paths),
        refused=refused,
        slope_error_deg=[t.meta.slope_deg - slopes[n] for t, n in zip(loaded, names)],
        slope_ci_deg=[[math.degrees(v) for v in t.meta.slope_ci_rad] for t in loaded],
    )
    # the exports, as a user hands them over: `calibrate` imports them with the held wheel's legs (k fitted: the
    # importer's bound, then again with the fitted k); the diagnosis with the true slopes hands `Trial`s
    given: list[Any] = list(series.imported)
    if sc.true_slope:
        given = [replace(t, meta=replace(t.meta, slope_deg=slopes[n])) for t, n in zip(loaded, names)]
    cpu = time.process_time()
    try:
        if len(loaded) < 2:
            raise RimlessError(f"{len(loaded)} trial(s) imported")
        res = calibrate(
            given, fit=sc.fit, wheel=Wheel(held, uncertainty={f: 0.0 for f in UNCERTAIN_FIELDS}), names=names
        )
    except RimlessError as err:
        row["failed"] = f"{type(err).__name__}: {str(err).splitlines()[0]}"
        return row
    row["calibrate_cpu_s"] = time.process_time() - cpu
    passes = getattr(res, "slope_passes", None)
    if passes and not sc.true_slope:  # the slopes the calibration held: those of the pass it kept
        kept = [h for h in passes["history"] if h["calibrated"]][-1]["slopes"]
        row.update(
            slope_error_deg=[r["slope_deg"] - slopes[n] for r, n in zip(kept, names)],
            slope_ci_deg=[r["ci95_deg"] for r in kept],
            slope_passes={k: passes.get(k) for k in ("passes", "reimported_with_fitted_k", "stable", "legs", "legs_k")},
        )
    row.update(_verdicts(res))
    return row


#: the model choice's keys a series keeps: its verdict, and the test's figures, so that another rule can be
#: checked on a study's JSON offline
CHOICE_KEYS = (
    "delta_chi2",
    "p_value",
    "supported",
    "boundary",
    "statement",
    "p_value_chi2",
    "dispersion",
    "dispersion_source",
    "dispersion_dof",
    "dispersion_parts",
    "statistic",
    "detectable_above",
)


def _verdicts(res: Any) -> dict[str, Any]:
    """What the calibration said: adequacy (overall ratios, p-values, fits), the model choice, each estimate."""
    adq = res.adequacy or {}
    ov = adq.get("overall", {})
    per_trial = adq.get("per_trial", [])
    choice = (res.model_choice or {}).get("guide_friction_n")
    return {
        "converged": bool(res.converged),
        "fits": bool(adq.get("fits", True)),
        "trials_flagged": sum(not t["fits"] for t in per_trial),
        "per_trial_ratio": [{k: t[k]["ratio"] for k in ("com", "periods")} for t in per_trial],
        "overall": {
            k: {"ratio": ov[k]["ratio"], "p_value": ov[k]["p_value"]} for k in ("com", "periods", "total") if k in ov
        },
        "noise": {
            k: (adq.get("noise") or {}).get(k)
            for k in ("com_mm", "impact_time_ms", "timing_noise_source", "timing_noise_estimate_ms")
        },
        "model_choice": None if choice is None else {k: choice[k] for k in CHOICE_KEYS if k in choice},
        "held_exact_probe": _probe(res),
        "estimates": {
            e.name: {
                "value": e.value,
                "se": e.se if math.isfinite(e.se) else None,
                "identifiable": bool(e.identifiable),
                "effective_only": bool(e.effective_only),
            }
            for e in res.params
        },
    }


def _probe(res: Any) -> dict[str, Any] | None:
    """The held-exact probe of guide friction (`calibrate._held_exact_probe`), when run: whether it refitted,
    converged, what depends on the held value, F_c freed, the test's figures and its CPU time."""
    row = (getattr(res, "held_exact_probe", None) or {}).get("guide_friction_n")
    if row is None:
        return None
    test = row.get("test") or {}
    return {
        "refit": row["refit"],
        "converged": row["converged"],
        "depends": list(row["depends"]),
        "shifts_se": row["shifts_se"],
        "reach_se": row.get("reach_se"),  # one-sided, 1 se above the freed fit (`calibrate._reach_one_sided`)
        "reach_at_bound_se": row.get("reach_at_bound_se"),  # no refit: a diagnosis (`calibrate._reach_at_bound`)
        "friction_freed_n": (row.get("values_freed") or {}).get("guide_friction_n"),
        "delta_chi2": test.get("delta_chi2"),
        "p_value": test.get("p_value"),
        "supported": test.get("supported"),
        "cpu_s": row["cpu_s"],
    }


def _rate(k: int, n: int) -> dict[str, Any]:
    lo, hi = wilson_interval(k, n)
    return {"count": k, "of": n, "rate": k / n if n else None, "ci95": [lo, hi] if n else None}


def _estimate_summary(done: list[dict[str, Any]], name: str) -> dict[str, Any]:
    """How often a fitted parameter is called identifiable, how often its 95 % interval (value +- 1.96 se) holds
    the truth (all series, and those called identifiable), and its median absolute error relative to the truth."""
    rows = [(r["estimates"][name], r["truth"][name]) for r in done if name in r.get("estimates", {})]
    with_se = [(e, t) for e, t in rows if e["se"] is not None]
    covers = [abs(e["value"] - t) <= 1.96 * e["se"] for e, t in with_se]
    ident = [c for (e, _), c in zip(with_se, covers) if e["identifiable"]]
    errs = [abs(e["value"] / t - 1.0) for e, t in rows if t]
    return {
        "identifiable": _rate(sum(e["identifiable"] for e, _ in rows), len(rows)),
        "covered_95": _rate(sum(covers), len(covers)),
        "covered_95_when_identifiable": _rate(sum(ident), len(ident)),
        "median_abs_error_rel": float(np.median(errs)) if errs else None,
    }


def _summary(sc: Scenario, rows: list[dict[str, Any]]) -> dict[str, Any]:
    done = [r for r in rows if "failed" not in r]
    if sc.verdict == "does_not_fit":
        said = [not r["fits"] for r in done]
    else:
        said = [bool(r["model_choice"] and r["model_choice"]["supported"]) for r in done]
    out: dict[str, Any] = {
        "what": sc.what,
        "fit": list(sc.fit),
        "held_k_error": sc.k_error,
        "verdict": sc.verdict,
        "right_verdict": sc.truth_answer,
        "nominal_rate": sc.nominal_rate,
        "series": len(rows),
        "calibrated": len(done),
        "converged": sum(r["converged"] for r in done),
        sc.verdict: _rate(sum(said), len(done)),
        "right": _rate(sum(s == sc.truth_answer for s in said), len(done)),
        "does_not_fit_trials": {"count": sum(r["trials_flagged"] for r in done), "of": sum(r["trials"] for r in done)},
    }
    for key in ("com", "periods"):
        ps = [r["overall"][key]["p_value"] for r in done if r["overall"].get(key, {}).get("p_value") is not None]
        ratios = [r["overall"][key]["ratio"] for r in done if r["overall"].get(key, {}).get("ratio") is not None]
        out[f"{key}_figure"] = {
            "median_ratio": float(np.median(ratios)) if ratios else None,
            "max_ratio": float(np.max(ratios)) if ratios else None,
            "p_below_0.05": _rate(sum(p < 0.05 for p in ps), len(ps)),
            "p_below_0.01": _rate(sum(p < 0.01 for p in ps), len(ps)),
        }
    out["estimates"] = {name: _estimate_summary(done, name) for name in sc.fit}
    sp = [r["slope_passes"] for r in done if r.get("slope_passes")]
    out["slope_passes"] = {  # how the calibration's slopes were imported (`rimless.analysis.api.slope_passes`)
        "reimported_with_fitted_k": sum(bool(p["reimported_with_fitted_k"]) for p in sp),
        "passes": {str(n): sum(p["passes"] == n for p in sp) for n in sorted({p["passes"] for p in sp})},
        "stable": sum(bool(p["stable"]) for p in sp),
    }
    probes = [r["held_exact_probe"] for r in done if r.get("held_exact_probe")]
    if probes:  # F_c held exactly while c is fitted: the probe's verdicts and cost
        out["held_exact_probe"] = {
            "probed": len(probes),
            "refit": sum(bool(q["refit"]) for q in probes),
            "converged": sum(bool(q["converged"]) for q in probes),
            "c_depends": _rate(sum("c" in q["depends"] for q in probes), len(probes)),
            "any_depends": _rate(sum(bool(q["depends"]) for q in probes), len(probes)),
            "supported": sum(bool(q["supported"]) for q in probes),
            "cpu_s": sum(q["cpu_s"] for q in probes),
        }
    mc = [r["model_choice"] for r in done if r.get("model_choice")]
    if mc:
        out["model_choice_p"] = {
            "p_below_0.05": _rate(sum(m["p_value"] < 0.05 for m in mc), len(mc)),
            "median_delta_chi2": float(np.median([m["delta_chi2"] for m in mc])),
        }
    if sc.friction:
        fc = [(r["truth"]["guide_friction_n"], s) for r, s in zip(done, said)]
        out["by_friction_n"] = {
            f"{a:g}-{b:g}": _rate(sum(s for f, s in fc if a <= f < b), sum(a <= f < b for f, _ in fc))
            for a, b in ((0.1, 0.3), (0.3, 0.6))
        }
        limits = [
            (r["truth"]["guide_friction_n"], (r.get("model_choice") or {}).get("detectable_above"), s)
            for r, s in zip(done, said)
        ]
        known = [(f, lim, s) for f, lim, s in limits if lim is not None]
        if known:  # found where the truth is above the model choice's stated detection limit, and below it
            out["by_detectable_above"] = {
                "above": _rate(sum(s for f, lim, s in known if f >= lim), sum(f >= lim for f, lim, _ in known)),
                "below": _rate(sum(s for f, lim, s in known if f < lim), sum(f < lim for f, lim, _ in known)),
                "median_limit_n": float(np.median([lim for _, lim, _ in known])),
            }
    if sc.k_error:
        for label, sgn in (("k_held_high", 1.0), ("k_held_low", -1.0)):
            pick = [s for r, s in zip(done, said) if (r["held_k_n_per_m"] > r["truth"]["k"]) == (sgn > 0)]
            out[label] = _rate(sum(pick), len(pick))
    failed: dict[str, int] = {}
    for r in rows:
        if "failed" in r:
            failed[r["failed"][:80]] = failed.get(r["failed"][:80], 0) + 1
    out["failed"] = failed
    out["imports"] = {"trials": sum(r["trials"] for r in rows), "refused": sum(len(r["refused"]) for r in rows)}
    out["calibrate_cpu_s"] = sum(r.get("calibrate_cpu_s", 0.0) for r in rows)
    out["per_series"] = rows
    return out
