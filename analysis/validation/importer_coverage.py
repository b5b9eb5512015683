"""Coverage of the critical-slope interval through the importer (``rimless trials coverage``, ``--truth importer``).

Each series draws a wheel away from Table 1 (`critical_truth.LossyWheel`: total mass M 1.6-3.0 kg, legs L
0.21-0.26 m, inertia ratio I_hub / (M L^2) 0.3-3 log-uniform (Table 1: 0.43), guide friction F_c 0-0.6 N as a
constant loss per step) and a lab (Z-up or Y-up, a ramp heading 0-360 deg, a Tracker object or four markers),
walks it on six slopes straddling its own true critical slope (two releases each, up to `RAMP_STEPS` impacts),
writes each trial as a Vicon export, imports it as a user would (`import_trial`: the slope, the impacts and the
ending from the recording) and hands the imported trials to the critical-slope estimate with the wheel input a
user would give (`INPUTS`): ``table1``, Table 1 with its stated default uncertainties (the user who does not
know the wheel), and ``truth``, the truth's own parameters with an uncertainty (m_H 2 %, I_c 10 %, L0 1 mm, as
a wheel file would state them). Each input imports the trials with its wheel (`import_trial(wheel=)`, for the
legs' drift allowed in the slope interval): ``table1`` Table 1's compliant legs, ``truth`` rigid legs (the user
who measured the wheel knows it has no springs). The estimate is called through the function the caller gives (the CLI passes
the public `rimless.analysis.critical_slope`; this room may not import the API), without model critical slopes
(``models=[]``: the coverage is the trials' estimate's).

Reported per input and per estimator: how often the 95 % interval holds the truth (Wilson binomial interval),
with the held parameters' uncertainty (``ci_with_parameters_deg``) and without (``ci_deg``), the median and
median absolute errors, and every refused import and every series without an estimate, with its reason.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.validation.coverage import wilson_interval
from rimless.analysis.validation.critical_truth import Lab, LossyWheel, record, walk

__all__ = [
    "INPUTS",
    "TRUTH_MODEL",
    "RAMP_STEPS",
    "draw_wheel",
    "draw_lab",
    "truth_input",
    "write_series",
    "ImporterSeries",
    "ImporterCoverageResult",
    "run_importer_coverage",
]

INPUTS = ("table1", "truth")
TRUTH_MODEL = (
    "rigid rimless wheel with a constant loss per step (guide friction), rimless.analysis.validation.critical_truth; "
    "recorded as Vicon exports and imported"
)
RAMP_STEPS = 11
#: the wheel file's uncertainty for the ``truth`` input: relative for masses and inertia, absolute for L0 (m)
TRUTH_SD_REL = {"hub_mass_kg": 0.02, "inertia_kg_m2": 0.10}
TRUTH_SD_L0_M = 0.001
Z95 = 1.959963984540054
#: the guide friction drawn (uniform), N: the truth's constant loss per step is F_c x 20 mm
FRICTION_N = (0.0, 0.6)


def draw_wheel(rng: np.random.Generator, friction_n: tuple[float, float] = FRICTION_N) -> tuple[LossyWheel, float]:
    """A wheel away from Table 1 whose true critical slope is 0.5-4 deg: (wheel, critical slope deg); its guide
    friction uniform in ``friction_n`` (N; (0, 0) for a lossless truth)."""
    while True:
        mass = float(rng.uniform(1.6, 3.0))
        leg = float(rng.uniform(0.21, 0.26))
        ratio = float(np.exp(rng.uniform(math.log(0.3), math.log(3.0))))
        wheel = LossyWheel(
            mass_kg=mass, inertia_hub_kg_m2=ratio * mass * leg**2, leg_m=leg, friction_n=float(rng.uniform(*friction_n))
        )
        crit = wheel.critical_slope_deg()
        if 0.5 < crit < 4.0:
            return wheel, crit


def draw_lab(rng: np.random.Generator) -> Lab:
    return Lab(
        up=str(rng.choice(["z", "y"])), heading_deg=float(rng.uniform(0.0, 360.0)), markers=bool(rng.random() < 0.5)
    )


def truth_input(wheel: LossyWheel) -> tuple[Any, dict[str, float]]:
    """(WheelParams, 1-sigma uncertainties) a user who measured this wheel would give (`TRUTH_SD_REL`)."""
    p = wheel.wheel_params()
    sd = {
        "hub_mass_kg": TRUTH_SD_REL["hub_mass_kg"] * p.hub_mass_kg,
        "leg_mass_kg": 0.0,
        "inertia_kg_m2": TRUTH_SD_REL["inertia_kg_m2"] * p.inertia_kg_m2,
        "leg_length_m": TRUTH_SD_L0_M,
        "guide_friction_n": 0.2,
    }
    return p, sd


@dataclass
class SeriesTrial:
    path: Path
    slope_deg: float
    release_rad_s: float
    impacts: int
    stalled: bool


def write_series(
    rng: np.random.Generator,
    wheel: LossyWheel,
    crit_deg: float,
    lab: Lab,
    folder: Path,
    *,
    ramp_steps: int = RAMP_STEPS,
) -> list[SeriesTrial]:
    """Six slopes straddling ``crit_deg`` at random offsets, two releases each (over the top of the first stance
    by a factor 1.1-1.6 and 1.7-2.3 in speed), each written as a Vicon export in ``lab`` under ``folder``."""
    spacing = float(rng.uniform(0.1, 0.25))
    offsets = (np.arange(6) - float(rng.uniform(1.5, 3.5))) * spacing
    out = []
    for j, off in enumerate(offsets):
        slope = crit_deg + float(off)
        if slope <= 0.05:
            continue
        top = math.sqrt(wheel.top_threshold(math.radians(slope)))
        for r, (lo, hi) in enumerate(((1.1, 1.6), (1.7, 2.3))):
            release = top * float(rng.uniform(lo, hi))
            wk = walk(wheel, slope, release, ramp_steps)
            path = folder / f"series_slope{j}_release{r}.csv"
            record(wk, path, rng, lab)
            out.append(SeriesTrial(path, slope, release, int(wk.impacts.size), bool(wk.stalled)))
    return out


@dataclass
class ImporterSeries:
    """One series: its truth, its lab, the imports, and per input the estimate (or why there is none)."""

    wheel: LossyWheel
    truth_deg: float
    lab: Lab
    trials: int
    refused: list[str]
    results: dict[str, dict[str, Any]] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        w = self.wheel
        return {
            "truth_critical_slope_deg": self.truth_deg,
            "wheel": {
                "mass_kg": w.mass_kg,
                "inertia_hub_kg_m2": w.inertia_hub_kg_m2,
                "leg_m": w.leg_m,
                "inertia_ratio": w.inertia_ratio,
                "friction_n": w.friction_n,
                "loss_per_step_j": w.loss_j,
            },
            "lab": {"up": self.lab.up, "heading_deg": self.lab.heading_deg, "markers": self.lab.markers},
            "trials": self.trials,
            "refused": self.refused,
            "inputs": self.results,
        }


def _covers(ci: Sequence[float] | None, truth: float) -> bool | None:
    if ci is None or len(ci) != 2 or not all(math.isfinite(v) for v in ci):
        return None
    return bool(ci[0] <= truth <= ci[1])


def _inertia_row(inertia: dict[str, Any] | None, wheel: LossyWheel) -> dict[str, Any]:
    """What the trials' inertia ratio (JSON ``inertia_from_trials``) says about the truth's r = I_hub / (M L^2):
    the ratio reported (r and L0 fitted together) and the one at the held L0 (what I_c is given from)."""
    truth = wheel.inertia_ratio
    row: dict[str, Any] = {"truth_inertia_ratio": truth, "truth_leg_m": wheel.leg_m}
    if not inertia or not inertia.get("estimated"):
        return {**row, "estimated": False, "why": (inertia or {}).get("note", "not tried")}
    r, se = inertia["inertia_ratio"], inertia["inertia_ratio_se"]
    rh, seh = inertia.get("inertia_ratio_at_held_leg_length"), inertia.get("inertia_ratio_at_held_leg_length_se")
    return {
        **row,
        "estimated": True,
        "inertia_ratio": r,
        "inertia_ratio_se": se,
        "error_pct": 100 * (r / truth - 1),
        "z": (r - truth) / se,
        "covered": bool(abs(r - truth) <= Z95 * se),
        "leg_length_m": inertia.get("leg_length_m"),
        "leg_length_sd_m": inertia.get("leg_length_sd_m"),
        "rigid_map_fits": inertia.get("rigid_map_fits"),
        "effective_only": bool(inertia.get("effective_only", False)),
        "reduced_chi2": inertia.get("reduced_chi2"),
        "loss_per_step_rad2_s2": inertia.get("loss_per_step_rad2_s2"),
        "truth_loss_per_step_rad2_s2": 2 * wheel.loss_j / wheel.inertia_foot,
        "inertia_ratio_at_held_leg_length": rh,
        "covered_at_held_leg_length": bool(abs(rh - truth) <= Z95 * seh) if rh is not None and seh else None,
        "assumption": inertia.get("assumption"),
    }


def _result_row(res: Any, truth: float, wheel: LossyWheel | None = None) -> dict[str, Any]:
    """What one series' estimate says about the truth (JSON-ready); with ``wheel``, the trials' inertia ratio
    against the truth's (``inertia_from_trials``)."""
    c = res.chosen
    inertia = {"inertia_from_trials": _inertia_row(res.inertia, wheel)} if wheel is not None else {}
    if c is None:
        return {"estimated": False, "why": res.why, **inertia}
    held = (res.held or {}).get("trials") or {}
    ci_par = held.get("ci_deg")
    return {
        "estimated": True,
        "method": c.method,
        "critical_slope_deg": c.value_deg,
        "error_deg": c.value_deg - truth,
        "ci_deg": list(c.ci_deg),
        "covered": _covers(c.ci_deg, truth),
        "ci_with_parameters_deg": list(ci_par) if ci_par else None,
        "covered_with_parameters": _covers(ci_par, truth),
        "half_width_parts_deg": half_width_parts(c, held),
        "per_method": {
            e.method: {"value_deg": e.value_deg, "ci_deg": list(e.ci_deg), "covered": _covers(e.ci_deg, truth)}
            for e in res.estimates
        },
        **inertia,
    }


def half_width_parts(chosen: Any, held: dict[str, Any]) -> dict[str, Any]:
    """The chosen estimate's 95 % half width (deg) and its parts, each alone as a 95 % half width: ``data`` (the
    trials' interval, ``ci_deg``), for the extrapolation split into ``fixed_points`` (the e* standard errors:
    impact timing), ``slopes`` (the trials' slope uncertainties) and ``scatter`` (the factor the line's reduced
    chi^2 and Student's t put on both; 1 when not inflated); ``parameters`` (the held parameters' standard error,
    per parameter under ``parameters_by_name``); ``total`` (``ci_with_parameters_deg``: data and parameters in
    quadrature). Parts add in quadrature to the total."""
    half = 0.5 * (chosen.ci_deg[1] - chosen.ci_deg[0])
    se_par = held.get("se_parameters_deg")
    out: dict[str, Any] = {"data": half}
    parts = getattr(chosen, "se_parts_deg", None)
    if parts:
        out["fixed_points"] = Z95 * parts["fixed_points"] * parts["scatter"]
        out["slopes"] = Z95 * parts["slopes"] * parts["scatter"]
        out["scatter"] = parts["scatter"]
    out["parameters"] = Z95 * se_par if se_par is not None else None
    out["parameters_by_name"] = {
        r["name"]: Z95 * r["contribution_deg"]
        for r in held.get("contributions", [])
        if r.get("contribution_deg") is not None
    }
    out["total"] = math.hypot(half, out["parameters"]) if out["parameters"] is not None else None
    return out


def summarise_parts(est: list[dict[str, Any]]) -> dict[str, Any]:
    """Median half-width parts (deg, `half_width_parts`) of one input's series beside the spread of the actual
    errors: ``rms_z_data`` and ``rms_z_with_parameters`` (error over the interval's se: 1 for an honest
    interval) and ``rms_z_expected_with_parameters``, the rms z the carried interval would show were the data's
    interval honest and the held parameters exact (as the ``truth`` input's are): below 1 by design."""
    rows = [r for r in est if r.get("half_width_parts_deg")]
    if not rows:
        return {}
    parts = [r["half_width_parts_deg"] for r in rows]
    keys = ("data", "fixed_points", "slopes", "scatter", "parameters", "total")
    med: dict[str, Any] = {k: _median([p[k] for p in parts if p.get(k) is not None]) for k in keys}
    names = sorted({n for p in parts for n in p.get("parameters_by_name", {})})
    med["parameters_by_name"] = {n: _median([p["parameters_by_name"].get(n, 0.0) for p in parts]) for n in names}
    z_data = [r["error_deg"] / (p["data"] / Z95) for r, p in zip(rows, parts) if p["data"] > 0]
    z_tot = [r["error_deg"] / (p["total"] / Z95) for r, p in zip(rows, parts) if p.get("total")]
    share = [(p["data"] / p["total"]) ** 2 for p in parts if p.get("total")]
    return {
        "median_half_width_parts_deg": med,
        "rms_z_data": float(np.sqrt(np.mean(np.square(z_data)))) if z_data else None,
        "rms_z_with_parameters": float(np.sqrt(np.mean(np.square(z_tot)))) if z_tot else None,
        "rms_z_expected_with_parameters": float(np.sqrt(np.mean(share))) if share else None,
        "rms_error_deg": float(np.sqrt(np.mean([r["error_deg"] ** 2 for r in rows]))),
    }


def _share(k: int, n: int) -> dict[str, Any]:
    lo, hi = wilson_interval(k, n)
    return {"covered": k, "of": n, "coverage": k / n if n else None, "coverage_ci95": [lo, hi] if n else None}


def _median(v: list[float]) -> float | None:
    return float(np.median(v)) if v else None


def summarise_inertia(series: list[ImporterSeries], name: str) -> dict[str, Any]:
    """The row "inertia ratio from trials" of one input: how often r's 95 % interval holds the truth's r
    (Wilson interval), its median and largest errors (%), median se (%), the 95th percentile of |error| / se, and
    the same coverage for the ratio at the held L0. Coverage counts the ratios the import claims
    (``estimated``, not ``effective_only``: an effective pendulum's r is not the wheel's and is not claimed);
    ``effective_only`` counts the others."""
    rows = [
        r["inertia_from_trials"]
        for s in series
        if name in s.results and "inertia_from_trials" in (r := s.results[name])
    ]
    est = [r for r in rows if r["estimated"] and not r.get("effective_only")]
    share = _share(sum(r["covered"] for r in est), len(est))
    held = [r for r in est if r["covered_at_held_leg_length"] is not None]
    held_share = _share(sum(r["covered_at_held_leg_length"] for r in held), len(held))
    err = [r["error_pct"] for r in est]
    return {
        "series": len(rows),
        "estimated": len(est),
        "effective_only": sum(bool(r["estimated"] and r.get("effective_only")) for r in rows),
        **share,
        "median_error_pct": _median(err),
        "median_abs_error_pct": _median([abs(e) for e in err]),
        "max_abs_error_pct": max((abs(e) for e in err), default=None),
        "median_se_pct": _median([100 * r["inertia_ratio_se"] / r["inertia_ratio"] for r in est]),
        "abs_z_p95": float(np.percentile([abs(r["z"]) for r in est], 95)) if est else None,
        "at_held_leg_length": {k: held_share[k] for k in ("covered", "of", "coverage", "coverage_ci95")},
        "assumption": next((r["assumption"] for r in est if r.get("assumption")), None),
    }


def summarise_input(series: list[ImporterSeries], name: str) -> dict[str, Any]:
    """The coverage of one input over the series (keys as the pendulum study's, plus the carried interval)."""
    rows = [s.results[name] for s in series if name in s.results]
    est = [r for r in rows if r["estimated"]]
    n = len(est)
    cov = sum(bool(r["covered"]) for r in est)
    with_par = [r for r in est if r["covered_with_parameters"] is not None]
    err = [r["error_deg"] for r in est]
    methods: dict[str, dict[str, Any]] = {}
    for r in est:
        for m, d in r["per_method"].items():
            e = methods.setdefault(m, {"series": 0, "covered": 0, "chosen": 0, "errors": []})
            e["series"] += 1
            e["covered"] += int(bool(d["covered"]))
            e["errors"].append(d["value_deg"] - (r["critical_slope_deg"] - r["error_deg"]))
        methods.setdefault(r["method"], {"series": 0, "covered": 0, "chosen": 0, "errors": []})["chosen"] += 1
    for e in methods.values():
        errs = e.pop("errors")
        e.update({k: v for k, v in _share(e["covered"], e["series"]).items() if k != "covered"})
        e["median_error_deg"] = _median(errs)
    why: dict[str, int] = {}
    for r in rows:
        if not r["estimated"]:
            key = str(r["why"]).split(":")[0][:80]
            why[key] = why.get(key, 0) + 1
    share = _share(cov, n)
    par = _share(sum(bool(r["covered_with_parameters"]) for r in with_par), len(with_par))
    return {
        "series": len(rows),
        "estimated": n,
        "covered": cov,
        "coverage": share["coverage"],
        "coverage_ci95": share["coverage_ci95"],
        "covered_with_parameters": par["covered"],
        "coverage_with_parameters": par["coverage"],
        "coverage_with_parameters_ci95": par["coverage_ci95"],
        "median_error_deg": _median(err),
        "median_abs_error_deg": _median([abs(e) for e in err]),
        "median_ci_width_deg": _median([r["ci_deg"][1] - r["ci_deg"][0] for r in est]),
        "median_ci_with_parameters_width_deg": _median(
            [r["ci_with_parameters_deg"][1] - r["ci_with_parameters_deg"][0] for r in with_par]
        ),
        "per_method": methods,
        "not_estimated": why,
        **summarise_parts(est),
        "inertia_ratio_from_trials": summarise_inertia(series, name),
    }


@dataclass
class ImporterCoverageResult:
    series: list[ImporterSeries]
    seed: int
    inputs: tuple[str, ...]
    cpu_s: float
    wall_s: float
    friction_n: tuple[float, float] = FRICTION_N

    def summary(self) -> dict[str, Any]:
        """The JSON of ``rimless trials coverage``: the first input's coverage at the top level (the keys of the
        pendulum study, same meaning), every input under ``inputs``, and each series under ``per_series``."""
        per_input = {name: summarise_input(self.series, name) for name in self.inputs}
        refused: dict[str, int] = {}
        for s in self.series:
            for r in s.refused:
                key = r.split(":")[0][:80]
                refused[key] = refused.get(key, 0) + 1
        first = per_input[self.inputs[0]]
        return {
            "truth": "importer",
            "truth_model": TRUTH_MODEL,
            "input": self.inputs[0],
            **{k: v for k, v in first.items() if k != "not_estimated"},
            "not_estimated": first["not_estimated"],
            "inputs": per_input,
            "imports": {
                "trials": sum(s.trials for s in self.series),
                "refused": sum(len(s.refused) for s in self.series),
                "reasons": refused,
            },
            "labs": {
                "y_up": sum(s.lab.up == "y" for s in self.series),
                "markers": sum(s.lab.markers for s in self.series),
            },
            "draws": {
                "mass_kg": [1.6, 3.0],
                "leg_m": [0.21, 0.26],
                "inertia_ratio": [0.3, 3.0],
                "friction_n": list(self.friction_n),
                "critical_slope_deg": [0.5, 4.0],
            },
            "per_series": [s.as_dict() for s in self.series],
            "seed": self.seed,
            "goal": [0.90, 0.98],
            "cpu_s": self.cpu_s,
            "wall_s": self.wall_s,
        }


def run_importer_coverage(
    n_series: int,
    seed: int,
    critical_slope: Callable[..., Any],
    *,
    inputs: Sequence[str] = INPUTS,
    ramp_steps: int = RAMP_STEPS,
    friction_n: tuple[float, float] = FRICTION_N,
    progress: Callable[[int, str], None] | None = None,
) -> ImporterCoverageResult:
    """``n_series`` series through the importer; ``critical_slope(trials, wheel, models=[], names=...)`` is the
    estimate (the public `rimless.analysis.critical_slope`); ``friction_n`` the guide friction's range (N; (0, 0):
    lossless truths); ``progress(i, stage)`` as it goes."""
    from rimless.analysis.kinematics.build import import_trial
    from rimless.errors import RimlessError
    from rimless.sim import Wheel

    bad = [i for i in inputs if i not in INPUTS]
    if bad or not inputs:
        raise ValueError(f"inputs must be among {', '.join(INPUTS)}, got {list(inputs)}")
    rng = np.random.default_rng(seed)
    cpu, wall = time.process_time(), time.perf_counter()
    done: list[ImporterSeries] = []
    with tempfile.TemporaryDirectory(prefix=f"rimless-coverage-{os.getpid()}-") as tmp:
        for i in range(n_series):
            wheel, crit = draw_wheel(rng, friction_n)
            lab = draw_lab(rng)
            folder = Path(tmp) / f"series{i}"
            folder.mkdir()
            if progress:
                progress(i, "walking and writing")
            written = write_series(rng, wheel, crit, lab, folder, ramp_steps=ramp_steps)
            if progress:
                progress(i, "importing")
            s = ImporterSeries(wheel, crit, lab, len(written), [])
            for name in inputs:
                if name == "table1":
                    user_wheel = Wheel()
                else:
                    params, sd = truth_input(wheel)
                    user_wheel = Wheel(params, uncertainty=sd)
                # imported with the wheel the user states, for its legs' drift (`import_trial(wheel=)`): Table 1's
                # compliant legs, or the measured wheel's rigid ones
                import_wheel = user_wheel if name == "table1" else user_wheel.with_model("rigid")
                trials, names, refused = [], [], []
                for st in written:
                    try:
                        trials.append(import_trial(st.path, wheel=import_wheel))
                        names.append(st.path.name)
                    except RimlessError as err:
                        refused.append(f"{err}".splitlines()[0])
                if not s.refused:
                    s.refused = refused
                if progress:
                    progress(i, f"critical slope, {name} wheel")
                if not trials:
                    s.results[name] = {"estimated": False, "why": "every import refused"}
                    continue
                try:
                    res = critical_slope(trials, user_wheel, models=[], names=names)
                except RimlessError as err:
                    s.results[name] = {"estimated": False, "why": f"{type(err).__name__}: {err}"}
                    continue
                s.results[name] = _result_row(res, crit, wheel)
            done.append(s)
            if progress:
                progress(i + 1, "done")
    return ImporterCoverageResult(
        done,
        seed,
        tuple(inputs),
        time.process_time() - cpu,
        time.perf_counter() - wall,
        (float(friction_n[0]), float(friction_n[1])),
    )
