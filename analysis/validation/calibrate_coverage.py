"""Coverage of `rimless.analysis.calibrate`'s per-parameter intervals through the importer.

Each series draws a compliant ER wheel away from Table 1 (k 1500-4000 N/m, c 2-20 N s/m; Table 1: 2700, 8; with
``friction_n`` the guide friction F_c too, uniform in that range), walks it with the truth model ``truth``
(`TRUTHS`; no slope wander) on ``trials`` slopes of 2-3.5 deg,
each released at its gait's speed times U(0.95, 1.08), writes each walk as a Vicon export in a lab drawn per
series (`importer_coverage.draw_lab`, `critical_truth.record`), imports it (the refusals) and hands the exports
to the calibration as a user would: it imports them told the wheel input (k fitted: the importer's bound, then
again told the fitted k, `rimless.analysis.api.slope_passes`; ``slope_passes`` counts the passes) and fits
``fit`` (default c and k) with each wheel input of ``inputs`` (`INPUTS`):

- ``exact`` (default): the held parameters at the truth's values, exact (``uncertainty`` 0: the intervals are
  the data's; the held parameters' part is not exercised). The truth's held parameters are Table 1's.
- ``table1``: Table 1 with its default uncertainties (`rimless.sim.model.uncertain.DEFAULT_SD`; the user who does
  not know the wheel), while the truth's held parameters are drawn from those stated uncertainties
  (`draw_held`: m_H, m, I_c, L0 normal about Table 1 with their default sd; F_c, stated 0 +- 0.2 N at its bound
  0, half-normal |N(0, 0.2)|; g exact): each interval must then include the held parameters' part
  (``se_held``, `rimless.analysis.inference.calibrate.held_response`).
- ``truth``: the truth's parameters as a wheel file would state them, with the default uncertainties at those
  values (F_c +- 0.2 N): the held part is carried but the held values are right (it should over-cover).

With ``table1`` or ``truth`` among the inputs every series' truth has drawn held parameters (from their own
random stream, so k, c, the labs and the slopes are those of the ``exact`` run of the same seed).

``wheels`` (`WHEELS`) says where the truth's held parameters come from: ``table1`` (default) as above (Table 1's,
or drawn from its stated uncertainties); ``away`` (`draw_away`, with the ``exact`` and ``truth`` inputs only)
draws each truth away from Table 1 as `importer_coverage.draw_wheel` draws the rigid wheel: total mass
M = m_H + 8 m U(1.6, 3.0) kg, leg (foot) mass m U(0.02, 0.05) kg (Table 1: 0.0378), L0 U(0.21, 0.26) m and the
inertia ratio r = (I_c + 8 m L0^2) / (M L0^2) log-uniform in 0.3-3 (`stance_inertia.inertia_ratio`'s; Table 1:
0.43), so I_c = r M L0^2 - 8 m L0^2 > 0. A drawn wheel is kept only if the truth model finds its period-1 gait
at both ends of the slopes walked (2 and 3.5 deg, `gait_refusal`); else it is redrawn, k, c (and F_c) with it,
the reason counted (the JSON's ``draws.redrawn``; the kept wheels are the walkable part of the ranges). ``friction_n`` (lo, hi) N draws every truth's F_c U(lo, hi) with any input and
wheels (``table1`` then states 0 +- 0.2 N, ``truth`` the drawn value +- 0.2 N, ``exact`` it exactly). Reported per
input and parameter: how often the 95 % interval holds the truth (Wilson interval) with the held part
(``ci95_with_held``, where it was computed) and with the data's alone (``ci95``), the median relative error, the
rms of (estimate - truth) / se (``rms_z``: 1 for an honest se; with ``se_with_held``, about ``value_with_held``,
where computed), the median held shift (a held parameter at its bound: F_c), the median
parts of the se (the data's, the trial-clustered sandwich's, the measured slopes',
`rimless.analysis.inference.trial_slopes`, and the held parameters', per held parameter too), how often the
parameter was called identifiable (or effective only), the optimiser's end states, and every refused import and
failed fit with its reason.

The truth models (``truth``, the JSON's ``truth`` and ``truth_model``):

- ``independent`` (default): `rimless.analysis.validation.er_truth`, the ER wheel of docs/model.md written apart
  from `rimless.sim` (its own equations of motion, events and stick/slip friction; it meets the simulator only in
  its test, where the step maps agree to 1e-8), each walk released from that truth's own gait
  (`er_truth.er_truth_walk`).
- ``simulator``: the calibration's own model (`floquet_truth.er_walk`, the simulator's ER wheel), as before.

Both are the same physics (model.md's ER wheel), so this checks the importer, the fit and its intervals, not the
model's adequacy (`critical_truth` does that for the critical slope); the independent truth guards against a
defect shared by the simulator and the fit that calls it.
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
from rimless.analysis.validation.critical_truth import record
from rimless.analysis.validation.floquet_truth import er_walk
from rimless.analysis.validation.importer_coverage import draw_lab

Z95 = 1.959963984540054

__all__ = [
    "K_RANGE",
    "C_RANGE",
    "TRUTHS",
    "INPUTS",
    "HELD_DRAWN",
    "WHEELS",
    "AWAY_RANGES",
    "WalkedSeries",
    "draw_away",
    "away_line",
    "draw_held",
    "gait_refusal",
    "run_calibrate_coverage",
    "walk_and_import",
]

K_RANGE = (1500.0, 4000.0)
C_RANGE = (2.0, 20.0)
FIELDS = {"c": "damping_ns_per_m", "k": "stiffness_n_per_m"}
#: the wheel inputs the calibration can be given (see the module doc); ``exact`` is the default
INPUTS = ("exact", "table1", "truth")
#: the truth's held parameters drawn for the ``table1`` and ``truth`` inputs (`draw_held`)
HELD_DRAWN = ("hub_mass_kg", "leg_mass_kg", "inertia_kg_m2", "leg_length_m", "guide_friction_n")
#: the stream of the held draws beside the seed (the other draws keep the ``exact`` run's stream)
HELD_STREAM = 31
#: the truth models (`walk_and_import`'s ``truth``); the first is the default
TRUTHS = ("independent", "simulator")
#: what each truth is (the JSON's ``truth_model`` starts with it)
TRUTH_MEANING = {
    "independent": "er_truth, the ER wheel of docs/model.md written apart from rimless.sim (hub coordinates, "
    "Newton-Euler, scipy events; its step map meets the simulator's to 1e-8 in its test)",
    "simulator": "the simulator's ER wheel (the calibration's own model)",
}
#: the stream of the guide-friction draws (``friction_n``) beside the seed
FRICTION_STREAM = 32
#: where the truths' held parameters come from (``wheels``; see the module doc); ``table1`` is the default
WHEELS = ("table1", "away")
#: the ``away`` draw's ranges (`draw_away`): M = m_H + 8 m (kg) and m uniform, L0 (m) uniform, r log-uniform
AWAY_RANGES = {
    "total_mass_kg": (1.6, 3.0),
    "leg_mass_kg": (0.02, 0.05),
    "leg_length_m": (0.21, 0.26),
    "inertia_ratio": (0.3, 3.0),
}
#: the stream of the ``away`` draws (and their redraws) beside the seed
AWAY_STREAM = 33
#: the slopes the walks are drawn on (deg, uniform); the ``away`` draw's gait check is made at both ends
SLOPES_DEG = (2.0, 3.5)
#: the ``away`` draw's tries before it gives up (a ValueError naming the reasons)
AWAY_TRIES = 50


@dataclass
class WalkedSeries:
    """One series' trials: the exports written (``paths``), the true slope of each by file name (deg), the walks
    that stalled, what was refused (truth walks that failed, imports refused) and the imported trials."""

    paths: list[Path] = field(default_factory=list)
    slopes_deg: dict[str, float] = field(default_factory=dict)
    stalled: int = 0
    refused: list[str] = field(default_factory=list)
    loaded: list[Any] = field(default_factory=list)
    names: list[str] = field(default_factory=list)

    @property
    def imported(self) -> list[Path]:
        """The exports that imported, in the order of ``names`` (what a user hands `calibrate`: it imports them
        with the wheel input's legs, and again with the fitted k when k is fitted)."""
        by_name = {p.name: p for p in self.paths}
        return [by_name[n] for n in self.names]


def walk_and_import(
    truth: Any,
    lab: Any,
    rng: np.random.Generator,
    folder: Path,
    prefix: str,
    trials: int,
    steps: int,
    *,
    importing: Callable[[], None] | None = None,
    model: str = "simulator",
) -> WalkedSeries:
    """``trials`` walks of the ER wheel ``truth`` on sorted slopes U(2, 3.5) deg, each released at its gait's
    speed times U(0.95, 1.08) by the truth model ``model`` (`TRUTHS`: ``simulator``, `floquet_truth.er_walk`, the
    default here for the callers that check the simulator's own walks; ``independent``,
    `er_truth.er_truth_walk`), written as Vicon exports ``folder/{prefix}t{j}.csv`` in ``lab``
    (`critical_truth.record`), then imported (`import_trial`, defaults); ``importing`` is called between."""
    from rimless.analysis.kinematics.build import import_trial
    from rimless.analysis.validation.er_truth import TruthFailure, er_truth_walk
    from rimless.errors import RimlessError
    from rimless.sim.model.failures import StepFailure

    if model not in TRUTHS:
        raise ValueError(f"model must be one of {', '.join(TRUTHS)}, got {model!r}")
    walker = er_truth_walk if model == "independent" else er_walk
    out = WalkedSeries()
    for j, slope in enumerate(np.sort(rng.uniform(*SLOPES_DEG, trials))):
        try:
            wk = walker(truth, float(slope), 0.0, steps, rng, release=float(rng.uniform(0.95, 1.08)))
        except (StepFailure, TruthFailure) as err:
            out.refused.append(f"truth walk failed: {err}")
            continue
        out.stalled += wk.stalled
        out.paths.append(Path(record(wk, folder / f"{prefix}t{j}.csv", rng, lab, rest_s=0.0)))
        out.slopes_deg[out.paths[-1].name] = float(slope)
    if importing:
        importing()
    for p in out.paths:
        try:
            out.loaded.append(import_trial(p))
            out.names.append(p.name)
        except RimlessError as err:
            out.refused.append(str(err).splitlines()[0])
    return out


def draw_held(rng: np.random.Generator) -> dict[str, float]:
    """The truth's held parameters (`HELD_DRAWN`) drawn from the uncertainties Table 1 is stated with
    (`rimless.sim.model.uncertain.default_sd` at Table 1's values): normal about Table 1, except F_c, stated
    0 +- 0.2 N at its bound 0, drawn half-normal |N(0, sd)|."""
    from rimless.sim.model.params import WheelParams
    from rimless.sim.model.uncertain import default_sd

    t1 = WheelParams()
    out = {}
    for name in HELD_DRAWN:
        v = float(getattr(t1, name))
        d = float(rng.normal(0.0, default_sd(name, v)))
        out[name] = abs(d) if name == "guide_friction_n" else v + d
    return out


def gait_refusal(wheel: Any, model: str = "independent") -> str | None:
    """Why the truth model ``model`` (`TRUTHS`) cannot walk ``wheel`` (WheelParams) on the slopes drawn: the
    first end of `SLOPES_DEG` at which it finds no period-1 gait, as ``"no gait at 2 deg: <reason>"``; else None.
    The independent truth's own gait search (`er_truth.fixed_point`) or the simulator's (`solve_fixed_point`)."""
    from rimless.errors import RimlessError

    for slope in SLOPES_DEG:
        try:
            if model == "independent":
                from rimless.analysis.validation.er_truth import ERWheel, TruthFailure, fixed_point

                try:
                    fixed_point(ERWheel.of(wheel, slope_rad=math.radians(slope)), rtol=1e-9)
                except TruthFailure as err:
                    return f"no gait at {slope:g} deg: {err.reason}"
            else:
                from rimless.sim.step.backend import make_map
                from rimless.sim.step.poincare import default_guess, solve_fixed_point

                p = wheel.replace(slope_rad=math.radians(slope))
                solve_fixed_point(make_map(p, "er", rtol=1e-9), default_guess(p, "er"), record=False)
        except (RimlessError, np.linalg.LinAlgError) as err:
            return f"no gait at {slope:g} deg: {type(err).__name__}"
    return None


def draw_away(
    rng: np.random.Generator,
    refusal: Callable[[dict[str, float]], str | None] | None = None,
    *,
    friction_n: tuple[float, float] | None = None,
) -> tuple[dict[str, float], dict[str, int]]:
    """The truth's held parameters m_H, m, I_c, L0 (kg, kg, kg m^2, m) drawn away from Table 1 (`AWAY_RANGES`:
    M = m_H + 8 m and m uniform, L0 uniform, r = (I_c + 8 m L0^2) / (M L0^2) log-uniform), redrawn while
    ``refusal(held)`` gives a reason (`gait_refusal` on the series' wheel). A redraw draws k and c too (`K_RANGE`,
    `C_RANGE`, uniform) and, with ``friction_n`` (lo, hi) N, F_c U(lo, hi): a k, c, F_c without a gait at the
    shallowest slope for any masses is not kept (the first try keeps the series' own k, c, F_c). Returns (held,
    with the redrawn k, c, F_c where redrawn; the redraws' reasons counted); raises ValueError after `AWAY_TRIES`
    refusals."""
    redrawn: dict[str, int] = {}
    again: dict[str, float] = {}
    for _ in range(AWAY_TRIES):
        mass = float(rng.uniform(*AWAY_RANGES["total_mass_kg"]))
        leg_mass = float(rng.uniform(*AWAY_RANGES["leg_mass_kg"]))
        length = float(rng.uniform(*AWAY_RANGES["leg_length_m"]))
        lo, hi = AWAY_RANGES["inertia_ratio"]
        ratio = float(np.exp(rng.uniform(math.log(lo), math.log(hi))))
        held = {
            "hub_mass_kg": mass - 8.0 * leg_mass,
            "leg_mass_kg": leg_mass,
            "inertia_kg_m2": (ratio * mass - 8.0 * leg_mass) * length**2,
            "leg_length_m": length,
            **again,
        }
        why = refusal(held) if refusal else None
        if why is None:
            return held, redrawn
        redrawn[why] = redrawn.get(why, 0) + 1
        again = {"stiffness_n_per_m": float(rng.uniform(*K_RANGE)), "damping_ns_per_m": float(rng.uniform(*C_RANGE))}
        if friction_n is not None:
            again["guide_friction_n"] = float(rng.uniform(*friction_n))
    raise ValueError(f"no wheel drawn away from Table 1 walks in {AWAY_TRIES} tries: {redrawn}")


def _user_wheel(name: str, truth: Any) -> Any:
    """The wheel input ``name`` (`INPUTS`) a user would give for the truth's wheel ``truth``."""
    from rimless.sim import Wheel
    from rimless.sim.model.uncertain import UNCERTAIN_FIELDS, default_sd

    if name == "exact":
        return Wheel(truth, uncertainty={f: 0.0 for f in UNCERTAIN_FIELDS})
    if name == "table1":
        return Wheel()
    return Wheel(truth, uncertainty={f: default_sd(f, float(getattr(truth, f))) for f in UNCERTAIN_FIELDS})


def _param_row(pe: Any, t: float) -> dict[str, Any]:
    """What one estimate says about its truth ``t`` (JSON-ready): the interval with the held part (``ci95``
    widened by ``se_held`` and moved by ``held_shift`` where computed: ``ci95_with_held``) and the data's alone, z
    with each (the former about ``value_with_held``), and the se's parts. Both intervals are the estimate's own,
    cut at the parameter's bound as `trials calibrate` prints them (``ci_at_bound``, ``ci_with_held_at_bound``);
    the linearised ones beside (``*_linear``). Coverage is the same either way: a truth is never below its
    bound."""
    finite = math.isfinite(pe.se)
    se_all = pe.se_with_held if pe.se_with_held is not None else pe.se
    centre = pe.value_with_held if pe.se_held is not None else pe.value
    ci = list(pe.ci95) if finite else None
    ci_held = list(c) if finite and (c := pe.ci95_with_held) is not None else None
    ci_all = ci_held if pe.se_held is not None else ci  # the interval the coverage counts
    return {
        "value": pe.value,
        "value_with_held": centre if pe.se_held is not None else None,
        "held_shift": pe.held_shift,
        "held_shifts": dict(pe.held_shifts),
        "se": pe.se if finite else None,
        "ci95": ci,
        "ci95_linear": list(pe.ci95_linear) if finite else None,
        "ci_at_bound": bool(pe.ci_at_bound),
        "covered_data": bool(ci is not None and ci[0] <= t <= ci[1]),
        "se_with_held": pe.se_with_held,
        "ci95_with_held": ci_held,
        "ci95_with_held_linear": list(c) if finite and (c := pe.ci95_with_held_linear) is not None else None,
        "ci_with_held_at_bound": bool(pe.ci_with_held_at_bound),
        "covered": bool(ci_all is not None and ci_all[0] <= t <= ci_all[1]),
        # None where the truth is 0 (a held F_c at its bound; never c or k): no relative error exists there
        "relative_error": pe.value / t - 1.0 if t != 0 else None,
        "identifiable": bool(pe.identifiable),
        "effective_only": bool(pe.effective_only),
        "z": (centre - t) / se_all if finite and se_all > 0 else None,
        "z_data": (pe.value - t) / pe.se if finite and pe.se > 0 else None,
        "se_model": pe.se_model,
        "se_sandwich": pe.se_sandwich,
        "se_slope": pe.se_slope,
        "se_held": pe.se_held,
        "held_contributions": dict(pe.held_contributions),
    }


def _fit_row(calibrate: Callable[..., Any], loaded: list[Any], names: list[str], fit: tuple[str, ...], wheel: Any,
             truth: dict[str, float]) -> dict[str, Any]:  # fmt: skip
    """One calibration of a series' trials (``loaded``: the exports' paths, imported by ``calibrate`` as a
    user's would be, or `Trial`s) with the wheel input ``wheel``: its optimiser's end, the slope passes
    (``slope_passes``: how many calibrations, whether the slopes were re-imported with the fitted k) and, per
    fitted parameter, `_param_row`; or ``failed`` with the reason."""
    from rimless.errors import RimlessError

    try:
        if len(loaded) < 2:
            raise RimlessError(f"{len(loaded)} trial(s) imported")
        res = calibrate(loaded, fit=fit, wheel=wheel, names=names)
    except RimlessError as err:
        return {"failed": f"{type(err).__name__}: {str(err).splitlines()[0]}"}
    row: dict[str, Any] = {
        "converged": bool(res.converged),
        "optimizer": {
            k: res.optimizer.get(k)
            for k in ("status", "message", "best_start", "several_minima", "polish", "above_optimum_chi2")
        },
        "params": {},
    }
    passes = getattr(res, "slope_passes", None)
    if passes:
        row["slope_passes"] = {k: passes.get(k) for k in ("passes", "reimported_with_fitted_k", "stable", "legs_k")}
    for pe in res.params:
        key = next((n for n, f in FIELDS.items() if f == pe.field), pe.name)
        if key in truth:
            row["params"][key] = _param_row(pe, truth[key])
    return row


def run_calibrate_coverage(
    n_series: int,
    seed: int,
    calibrate: Callable[..., Any],
    *,
    fit: Sequence[str] = ("c", "k"),
    trials: int = 4,
    steps: int = 10,
    inputs: Sequence[str] = ("exact",),
    progress: Callable[[int, str], None] | None = None,
    truth: str = "independent",
    friction_n: tuple[float, float] | None = None,
    wheels: str = "table1",
) -> dict[str, Any]:
    """``n_series`` series; ``calibrate(trials, fit=..., wheel=..., names=...)`` is the fit (the public
    `rimless.analysis.calibrate`), called once per series and wheel input of ``inputs`` (`INPUTS`), on walks of
    the truth model ``truth`` (`TRUTHS`; for each the same seed draws the same first wheel, lab and slopes, but
    the walks' releases and recordings draw from the same stream, so a recording one frame longer under one truth
    moves every later draw: the two truths' series are paired only up to there). With
    ``friction_n`` (lo, hi) N each truth's guide friction is drawn U(lo, hi) from its own stream (with any input:
    it replaces the drawn held parameters' half-normal F_c); the ``exact`` input states it exactly, ``truth`` with
    its default sd, ``table1`` as 0 +- 0.2 N. ``wheels`` (`WHEELS`): ``away`` draws each truth's m_H, m, I_c, L0
    away from Table 1 (`draw_away`, from its own stream, redrawn while `gait_refusal` gives a reason; the
    ``exact`` and ``truth`` inputs only). Returns the JSON-ready summary:
    the first input's figures at the top level (the keys as before), each input's under ``inputs``, and
    ``per_series``."""
    from rimless.sim.model.params import WheelParams

    bad = [f for f in fit if f not in FIELDS]
    if bad or not fit:
        raise ValueError(f"fit takes {', '.join(FIELDS)}, got {list(fit)}")
    bad = [i for i in inputs if i not in INPUTS]
    if bad or not inputs or len(set(inputs)) != len(inputs):
        raise ValueError(f"inputs must be distinct among {', '.join(INPUTS)}, got {list(inputs)}")
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {', '.join(TRUTHS)}, got {truth!r}")
    if friction_n is not None and not (0.0 <= friction_n[0] <= friction_n[1] and math.isfinite(friction_n[1])):
        raise ValueError(f"friction_n must be a range 0 <= lo <= hi (N), got {friction_n}")
    if wheels not in WHEELS:
        raise ValueError(f"wheels must be one of {', '.join(WHEELS)}, got {wheels!r}")
    if wheels == "away" and "table1" in inputs:
        raise ValueError("wheels away goes with the exact and truth inputs (table1 states Table 1's wheel)")
    away = wheels == "away"
    drawn = any(i != "exact" for i in inputs) and not away
    rng = np.random.default_rng(seed)
    held_rng = np.random.default_rng((seed, HELD_STREAM))
    friction_rng = np.random.default_rng((seed, FRICTION_STREAM))
    away_rng = np.random.default_rng((seed, AWAY_STREAM))
    redrawn_all: dict[str, int] = {}
    cpu, wall = time.process_time(), time.perf_counter()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix=f"rimless-calcov-{os.getpid()}-") as tmp:
        for i in range(n_series):
            held = draw_held(held_rng) if drawn else {}
            if friction_n is not None:
                held["guide_friction_n"] = float(friction_rng.uniform(*friction_n))
            wheel = WheelParams(
                stiffness_n_per_m=float(rng.uniform(*K_RANGE)), damping_ns_per_m=float(rng.uniform(*C_RANGE))
            ).replace(**held)
            redrawn: dict[str, int] = {}
            if away:
                if progress:
                    progress(i, "drawing a wheel away from Table 1")

                def refusal(h: dict[str, float], base: Any = wheel) -> str | None:
                    return gait_refusal(base.replace(**h), truth)

                away_held, redrawn = draw_away(away_rng, refusal, friction_n=friction_n)
                wheel = wheel.replace(**away_held)
                for why, k in redrawn.items():
                    redrawn_all[why] = redrawn_all.get(why, 0) + k
            lab = draw_lab(rng)
            if progress:
                progress(i, "walking and writing")

            def importing(i: int = i) -> None:
                if progress:
                    progress(i, "importing")

            series = walk_and_import(
                wheel, lab, rng, Path(tmp), f"s{i}_", trials, steps, importing=importing, model=truth
            )
            row: dict[str, Any] = {
                "truth": {n: getattr(wheel, FIELDS[n]) for n in fit},
                "truth_held": {n: float(getattr(wheel, n)) for n in HELD_DRAWN},
                "truth_inertia_ratio": _inertia_ratio(wheel),
                "redrawn": redrawn,
                "lab": {"up": lab.up, "heading_deg": lab.heading_deg, "markers": lab.markers},
                "trials": len(series.paths),
                "refused": series.refused,
                "stalled_walks": series.stalled,
                "inputs": {},
            }
            for name in inputs:
                if progress:
                    progress(i, f"calibrating, {name} wheel")
                row["inputs"][name] = _fit_row(
                    calibrate, series.imported, series.names, tuple(fit), _user_wheel(name, wheel), row["truth"]
                )
            row.update(row["inputs"][inputs[0]])  # the first input's fit at the row's top level (as before)
            rows.append(row)
            if progress:
                progress(i + 1, "done")
    out = _summary(
        rows,
        tuple(fit),
        tuple(inputs),
        seed,
        trials,
        steps,
        time.process_time() - cpu,
        time.perf_counter() - wall,
        drawn=drawn,
    )
    out["truth"] = truth
    out["truth_model"] = TRUTH_MEANING[truth] + ": " + out["truth_model"]
    draws = out["draws"]
    draws["wheels"] = wheels
    fc = "F_c drawn uniform in draws.guide_friction_n (N)" if friction_n is not None else "F_c 0"
    if away:
        draws.update({k: list(v) for k, v in AWAY_RANGES.items()})
        draws["held"] = (
            "away from Table 1 (draw_away): M = m_H + 8 m and m uniform in draws.total_mass_kg, draws.leg_mass_kg; "
            "L0 uniform in draws.leg_length_m; r = (I_c + 8 m L0^2) / (M L0^2) log-uniform in draws.inertia_ratio; "
            f"g exact; {fc}; a wheel without a gait at {SLOPES_DEG[0]:g} or {SLOPES_DEG[1]:g} deg redrawn, k, c "
            "(and F_c) with it (draws.redrawn)"
        )
        draws["redrawn"] = redrawn_all
        out["truth_model"] = out["truth_model"].replace(
            "; the rest Table 1's",
            "; m_H, m, I_c, L0 drawn away from Table 1" + ", F_c drawn" * (friction_n is not None),
        )
    if friction_n is not None:
        draws["guide_friction_n"] = list(friction_n)
        if not drawn and not away:
            draws["held"] = "Table 1's, exact; F_c drawn uniform in draws.guide_friction_n (N), stated exactly"
        elif drawn:
            draws["held"] = draws["held"].replace(
                "F_c half-normal, sd 0.2 N", "F_c uniform in draws.guide_friction_n (N), not the half-normal"
            )
    return out


def away_line(draws: dict[str, Any]) -> str:
    """The text's line for the JSON's ``draws`` of a ``wheels="away"`` run (with its leading newline), else ""."""
    if draws.get("wheels") != "away":
        return ""
    r, m, L = draws["inertia_ratio"], draws["total_mass_kg"], draws["leg_length_m"]
    redrawn = ", ".join(f"{k} x{v}" for k, v in draws["redrawn"].items()) or "none"
    return f"\nwheels away from Table 1: inertia ratio {r[0]:g}-{r[1]:g}, M {m[0]:g}-{m[1]:g} kg, L0 {L[0]:g}-{L[1]:g} m; redrawn: {redrawn}"


def _inertia_ratio(w: Any) -> float:
    """r = (I_c + 8 m L0^2) / ((m_H + 8 m) L0^2) of a WheelParams (`stance_inertia.inertia_ratio`'s, written here)."""
    m8 = 8.0 * w.leg_mass_kg
    return float((w.inertia_kg_m2 + m8 * w.leg_length_m**2) / ((w.hub_mass_kg + m8) * w.leg_length_m**2))


def _rel(got: list[dict[str, Any]], truths: list[float], part: str) -> list[float]:
    """Each series' ``part`` of the standard error over its truth (the finite ones)."""
    out = []
    for g, t in zip(got, truths):
        v = g.get(part)
        if v is not None and math.isfinite(v) and t != 0:
            out.append(v / t)
    return out


def _median(v: list[float]) -> float | None:
    return float(np.median(v)) if v else None


def _rms(v: list[float]) -> float | None:
    return float(np.sqrt(np.mean(np.square(v)))) if v else None


def _per_parameter(rows: list[dict[str, Any]], fits: list[dict[str, Any]], name: str) -> dict[str, Any]:
    """One parameter's figures over the series of one input (``fits``: each series' fit row, beside ``rows``)."""
    pairs = [(r, f["params"][name]) for r, f in zip(rows, fits) if name in f.get("params", {})]
    got = [g for _, g in pairs]
    truths = [r["truth"][name] for r, _ in pairs]
    k = sum(g["covered"] for g in got)
    k_data = sum(g["covered_data"] for g in got)
    lo, hi = wilson_interval(k, len(got))
    lo_d, hi_d = wilson_interval(k_data, len(got))
    errs = [g["relative_error"] for g in got if g["relative_error"] is not None]
    held_names = sorted({h for g in got for h in g["held_contributions"]})
    return {
        "fitted": len(got),
        "covered": k,
        "coverage": k / len(got) if got else None,
        "coverage_ci95": [lo, hi] if got else None,
        "covered_data_only": k_data,
        "coverage_data_only": k_data / len(got) if got else None,
        "coverage_data_only_ci95": [lo_d, hi_d] if got else None,
        "held_carried": sum(g["se_held"] is not None for g in got),
        "identifiable": sum(g["identifiable"] for g in got),
        "median_relative_error": _median(errs),
        "median_abs_relative_error": _median([abs(e) for e in errs]),
        "rms_z": _rms([g["z"] for g in got if g.get("z") is not None]),
        "rms_z_data_only": _rms([g["z_data"] for g in got if g.get("z_data") is not None]),
        "median_relative_se": {
            part: _median(_rel(got, truths, part)) for part in ("se_model", "se_sandwich", "se_slope", "se_held")
        },
        "median_relative_held_shift": _median([g.get("held_shift", 0.0) / t for g, t in zip(got, truths) if t != 0]),
        "median_relative_held_contributions": {
            h: _median(
                [g["held_contributions"][h] / t for g, t in zip(got, truths) if h in g["held_contributions"] and t != 0]
            )
            for h in held_names
        },
        "effective_only": sum(bool(g.get("effective_only")) for g in got),
        "median_relative_half_width": _median(
            # of the linearised intervals (1.96 se): a precision figure, not shortened where an interval is cut
            [
                ((c := g["ci95_with_held_linear"] or g["ci95_linear"])[1] - c[0]) / 2 / g["value"]
                for g in got
                if g["ci95"] and g["value"] != 0
            ]
        ),
    }


def _per_input(rows: list[dict[str, Any]], name: str, fit: tuple[str, ...]) -> dict[str, Any]:
    """One wheel input's figures: per parameter, the fits' end states and the failures."""
    fits = [r["inputs"][name] for r in rows]
    fitted = [f for f in fits if "params" in f]
    statuses: dict[str, int] = {}
    for f in fitted:
        key = str((f.get("optimizer") or {}).get("status"))
        statuses[key] = statuses.get(key, 0) + 1
    failed: dict[str, int] = {}
    for f in fits:
        if "failed" in f:
            failed[f["failed"][:80]] = failed.get(f["failed"][:80], 0) + 1
    return {
        "fitted": len(fitted),
        "converged": sum(bool(f.get("converged")) for f in fitted),
        "parameters": {n: _per_parameter(rows, fits, n) for n in fit},
        "optimizer_status": statuses,
        "failed": failed,
        "slope_passes": _passes(fitted),
    }


def _passes(fitted: list[dict[str, Any]]) -> dict[str, Any]:
    """How the fits' slopes were imported: how many fits re-imported them with the fitted k, how many passes
    (calibrations) they ran, and how many ended with the slopes' intervals no longer changing."""
    rows = [f["slope_passes"] for f in fitted if f.get("slope_passes")]
    count: dict[str, int] = {}
    for r in rows:
        count[str(r["passes"])] = count.get(str(r["passes"]), 0) + 1
    return {
        "reimported_with_fitted_k": sum(bool(r["reimported_with_fitted_k"]) for r in rows),
        "passes": count,
        "stable": sum(bool(r["stable"]) for r in rows),
    }


#: what each input tells the calibration (the JSON's ``inputs.<name>.wheel``)
INPUT_MEANING = {
    "exact": "the truth's held parameters, exact (the data's intervals)",
    "table1": "Table 1 with its default uncertainties (the truth's held parameters drawn from them)",
    "truth": "the truth's held parameters with the default uncertainties at their values",
}


def _summary(
    rows: list[dict[str, Any]],
    fit: tuple[str, ...],
    inputs: tuple[str, ...],
    seed: int,
    trials: int,
    steps: int,
    cpu_s: float,
    wall_s: float,
    *,
    drawn: bool,
) -> dict[str, Any]:
    per = {name: {"wheel": INPUT_MEANING[name], **_per_input(rows, name, fit)} for name in inputs}
    first = per[inputs[0]]
    return {
        "truth_model": "the ER wheel (k, c drawn"
        + ("; m_H, m, I_c, L0 and F_c drawn from Table 1's stated uncertainties" if drawn else "; the rest Table 1's")
        + "), recorded as Vicon exports in drawn labs and imported",
        "fit": list(fit),
        "input": inputs[0],
        "series": len(rows),
        **{k: first[k] for k in ("fitted", "converged", "parameters", "optimizer_status", "failed", "slope_passes")},
        "inputs": per,
        "draws": {
            "k_n_per_m": list(K_RANGE),
            "c_ns_per_m": list(C_RANGE),
            "held": (
                "normal about Table 1 with the default sd (m_H, m 2 %, I_c 10 %, L0 1 mm); F_c half-normal, sd "
                "0.2 N; g exact"
                if drawn
                else "Table 1's, exact"
            ),
        },
        "imports": {
            "trials": sum(r["trials"] for r in rows),
            "refused": sum(len(r["refused"]) for r in rows),
        },
        "trials_per_series": trials,
        "steps": steps,
        "seed": seed,
        "cpu_s": cpu_s,
        "wall_s": wall_s,
        "per_series": rows,
    }
