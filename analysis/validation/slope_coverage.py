"""How honest is the importer's slope interval (``rimless trials slope-coverage``): truth walks on a known slope,
recorded as Vicon exports in drawn labs, imported as a user would (`import_trial`, no ramp, no ``--slope-deg``);
per evidence the importer found (the line through the stance-foot contacts, the line through the hub at the
impacts, the whole hub path) and for the slope it used (``slope_ci_rad``): how often the 95 % interval holds the
true slope (Wilson binomial interval), the median error, and z = error / sd with sd = half width / 1.96 (an
honest interval has rms z near 1).

Two truths, each with wheels away from Table 1:

* ``rigid``: `critical_truth.LossyWheel` drawn as `importer_coverage.draw_wheel` (M 1.6-3.0 kg, L 0.21-0.26 m,
  inertia ratio 0.3-3, guide friction 0-0.6 N), a slope 0.3 deg below to 1.2 deg above its critical slope, a
  release over the top by 1.1-2.3 in speed, up to `STEPS` impacts (a stall below the critical slope ends the trial);
* ``er``: a compliant ER wheel with k 1500-4000 N/m, c 2-20 N s/m (Table 1: 2700, 8), 1.3-3.0 deg, released at
  its gait's speed times 0.8-1.4, `STEPS` impacts, walked by the ER truth model (`ER_TRUTH_MODELS`, the JSON's
  ``truth`` and ``truth_model``): ``independent`` (default), `er_truth.er_truth_walk` (the ER wheel of
  docs/model.md written apart from `rimless.sim`), or ``simulator``, the simulator's own (`floquet_truth.er_walk`).
  The same seed draws the same wheel, slope, release and lab under both (the walks draw alike) unless one finds no
  gait where the other does.

Labs (`importer_coverage.draw_lab`): Z-up or Y-up, any ramp heading, a Tracker object off the hub or four markers;
100 Hz, 0.3 mm and 1 mrad of noise; in `HIDDEN_SHARE` of the trials the middle 20-60 % of every stance but two is
hidden (the impacts stay in view, most stance feet do not).

Each recording is imported twice: as a user who does not say what wheel it is (no ``wheel=``: the importer
bounds the legs' drift, `slope_evidence.UNKNOWN_LEG_TIME_S`; the keys ``truths`` and ``used``), and as one who
states it (``wheel_given``: `told_wheel`, a rigid model for the rigid truth, the ER wheel's k with Table 1's
stated 10 % for the ER truth).

The study sees every evidence, not only the one used, by wrapping the importer's `slope_evidence` and
`choose_slope` while it imports (`captured_evidence`).
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from rimless.analysis.validation.coverage import wilson_interval
from rimless.analysis.validation.critical_truth import MARKERS_BODY_M, Y_UP_FROM_Z_UP, Lab, recorded_frames, walk
from rimless.analysis.validation.floquet_truth import Walk, er_walk, slope_to_lab
from rimless.analysis.validation.importer_coverage import draw_lab, draw_wheel
from rimless.analysis.validation.vicon_writer import markers_section, objects_section, write

__all__ = [
    "ER_TRUTH_MODELS",
    "TRUTHS",
    "STEPS",
    "HIDDEN_SHARE",
    "Z95",
    "SlopeDraw",
    "SlopeCoverageResult",
    "captured_evidence",
    "draw_trial",
    "measure_draw",
    "run_slope_coverage",
]

TRUTHS = ("rigid", "er")
#: the models that walk the ``er`` truth (``truth_model``); the first is the default
ER_TRUTH_MODELS = ("independent", "simulator")
#: what each is (the JSON's ``truth_model`` starts with it)
ER_TRUTH_MEANING = {
    "independent": "er_truth, the ER wheel of docs/model.md written apart from rimless.sim (hub coordinates, "
    "Newton-Euler, scipy events)",
    "simulator": "the simulator's ER wheel (floquet_truth.er_walk)",
}
STEPS = 11
HIDDEN_SHARE = 0.4
Z95 = 1.959964
#: the evidence kinds reported (``used`` is the slope the importer used: ``slope_ci_rad``)
KINDS = ("contacts", "impact line", "path", "used")


@dataclass
class SlopeDraw:
    """One truth walk and its recording: the truth's name, its parameters (JSON-ready), the walk, the lab and the
    hidden stance middles (walk time, s)."""

    truth: str
    wheel: dict[str, float]
    walk: Walk
    lab: Lab
    gaps: tuple[tuple[float, float], ...] = ()
    truth_model: str | None = None  # the ER truth's model (`ER_TRUTH_MODELS`); None for the rigid truth

    @property
    def lab_kind(self) -> str:
        return f"{self.lab.up.upper()}-up, {'markers' if self.lab.markers else 'object'}"


def _er_draw(rng: np.random.Generator, model: str = "independent") -> tuple[dict[str, float], Walk]:
    from rimless.analysis.validation.er_truth import er_truth_walk
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams

    walker = er_truth_walk if model == "independent" else er_walk
    while True:
        k, c = float(rng.uniform(1500.0, 4000.0)), float(rng.uniform(2.0, 20.0))
        slope, release = float(rng.uniform(1.3, 3.0)), float(rng.uniform(0.8, 1.4))
        try:
            wk = walker(WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c), slope, 0.0, STEPS, rng, release=release)
        except (StepFailure, RuntimeError, ValueError):  # no gait there (too shallow for this c; er_truth's
            # TruthFailure is a RuntimeError): draw again
            continue
        if wk.impacts.size >= 4:
            return {"k_n_per_m": k, "c_ns_per_m": c, "release_factor": release}, wk


def _rigid_draw(rng: np.random.Generator) -> tuple[dict[str, float], Walk]:
    while True:
        wheel, crit = draw_wheel(rng)
        slope = crit + float(rng.uniform(-0.3, 1.2))
        if slope <= 0.2:
            continue
        top = math.sqrt(wheel.top_threshold(math.radians(slope)))
        wk = walk(wheel, slope, top * float(rng.uniform(1.1, 2.3)), STEPS)
        if wk.impacts.size >= 4:
            desc = {
                "mass_kg": wheel.mass_kg,
                "leg_m": wheel.leg_m,
                "inertia_ratio": wheel.inertia_ratio,
                "friction_n": wheel.friction_n,
                "critical_slope_deg": crit,
            }
            return desc, wk


def _mid_stance_gaps(wk: Walk, rng: np.random.Generator) -> tuple[tuple[float, float], ...]:
    """The middle 20-60 % of every stance but two drawn ones hidden (walk time, s)."""
    bounds = np.concatenate([[0.0], wk.impacts])
    n = bounds.size - 1
    keep = set(rng.choice(n, size=min(2, n), replace=False).tolist())
    f = float(rng.uniform(0.2, 0.6)) / 2
    return tuple(
        (float(a + (0.5 - f) * (b - a)), float(a + (0.5 + f) * (b - a)))
        for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:]))
        if j not in keep
    )


def _check_model(truth_model: str) -> None:
    if truth_model not in ER_TRUTH_MODELS:
        raise ValueError(f"truth_model must be one of {', '.join(ER_TRUTH_MODELS)}, got {truth_model!r}")


def draw_trial(rng: np.random.Generator, truth: str, *, truth_model: str = "independent") -> SlopeDraw:
    """One walk of ``truth`` (rigid | er) on a drawn wheel and slope, in a drawn lab, maybe with hidden stances;
    the er truth walked by ``truth_model`` (`ER_TRUTH_MODELS`)."""
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {', '.join(TRUTHS)}, got {truth!r}")
    _check_model(truth_model)
    wheel, wk = _rigid_draw(rng) if truth == "rigid" else _er_draw(rng, truth_model)
    lab = draw_lab(rng)
    gaps = _mid_stance_gaps(wk, rng) if rng.random() < HIDDEN_SHARE else ()
    return SlopeDraw(truth, wheel, wk, lab, gaps, truth_model if truth == "er" else None)


def record(draw: SlopeDraw, path: Path, rng: np.random.Generator, *, hold_s: float = 0.4) -> str:
    """Write the walk as a Vicon export in its lab: a hold at the release pose, the walk, a rest of 1.5 s after a
    stall; frames inside the hidden stance middles are empty (as `critical_truth.record`, plus the occlusions)."""
    wk, lab = draw.walk, draw.lab
    tf, xs, hs, bs = recorded_frames(wk, lab.rate_hz, float(rng.uniform(0, 1.0 / lab.rate_hz)), hold_s)
    hidden = np.zeros(tf.size, bool)
    for a, c in draw.gaps:
        hidden |= (tf - hold_s >= a) & (tf - hold_s <= c)
    hub, rot = slope_to_lab(xs, hs, bs, wk.slope_deg, lab.heading_deg)
    if lab.up == "y":
        m = Rotation.from_matrix(Y_UP_FROM_Z_UP)
        hub, rot = m.apply(hub), m * rot
    if lab.markers:
        pts = hub[:, None, :] + np.einsum("nij,kj->nki", rot.as_matrix(), MARKERS_BODY_M)
        pts = pts + rng.normal(0.0, lab.noise_m, pts.shape)
        pts[hidden] = np.nan
        return write(path, markers_section({f"Wheel:M{i}": pts[:, i] for i in range(pts.shape[1])}))
    trans = hub + rot.apply(np.array([0.03, -0.02, 0.01]))
    noisy = Rotation.from_rotvec(rng.normal(0, lab.angle_noise_rad, (tf.size, 3))) * rot
    pose = np.column_stack([noisy.as_rotvec(), trans + rng.normal(0, lab.noise_m, trans.shape)])
    pose[hidden] = np.nan
    return write(path, objects_section({"Wheel": pose}))


@contextlib.contextmanager
def captured_evidence() -> Iterator[dict[str, Any]]:
    """While open, every `import_trial` leaves its slope evidence (``evidence``: the list of `SlopeEvidence`)
    and the one used (``used``) in the yielded dict."""
    from rimless.analysis.kinematics import build

    seen: dict[str, Any] = {}
    evidence, choose = build.slope_evidence, build.choose_slope

    def slope_evidence(*args: Any, **kwargs: Any) -> Any:
        out = evidence(*args, **kwargs)
        seen["evidence"] = list(out)
        return out

    def choose_slope(ev: Any) -> Any:
        out = choose(ev)
        seen["used"] = out[0][0] if out[0] else None
        return out

    build.slope_evidence, build.choose_slope = slope_evidence, choose_slope  # type: ignore[assignment]
    try:
        yield seen
    finally:
        build.slope_evidence, build.choose_slope = evidence, choose


def _row(e: Any, truth_rad: float) -> dict[str, Any]:
    half = e.half_rad
    err = e.slope_rad - truth_rad
    return {
        "kind": e.kind,
        "slope_deg": math.degrees(e.slope_rad),
        "error_deg": math.degrees(err),
        "half_width_deg": math.degrees(half),
        "z": err / (half / Z95) if half > 0 else None,
        "covered": bool(e.ci_rad[0] <= truth_rad <= e.ci_rad[1]),
        "method": e.method,
    }


def told_wheel(draw: SlopeDraw) -> Any:
    """The wheel a user who knows the truth's wheel would state (`rimless.sim.Wheel`): a rigid model for the
    rigid truth; the simulator's ER wheel with the truth's k and c (and Table 1's default sd of k, 10 %)."""
    from rimless.sim import Wheel

    if draw.truth == "rigid":
        return Wheel(model="rigid")
    return Wheel(stiffness_n_per_m=draw.wheel["k_n_per_m"], damping_ns_per_m=draw.wheel["c_ns_per_m"])


def _import(path: Path, truth_rad: float, wheel: Any) -> dict[str, Any]:
    """Import one recording (``wheel=``) and compare its evidence and the slope used with the truth."""
    from rimless.analysis.kinematics.build import import_trial
    from rimless.errors import RimlessError

    with captured_evidence() as seen:
        try:
            trial = import_trial(path, wheel=wheel)
        except RimlessError as err:
            return {"refused": str(err).splitlines()[0]}
    est = [e for e in seen.get("evidence", []) if e.source == "estimated"]
    used = _row(seen["used"], truth_rad) if seen.get("used") is not None else None
    if used is not None:  # the slope used, as the trial's meta states it (``slope_ci_rad``)
        lo, hi = trial.meta.slope_ci_rad
        used["covered"] = bool(lo <= truth_rad <= hi)
    return {"evidence": [_row(e, truth_rad) for e in est], "used": used}


def measure_draw(draw: SlopeDraw, folder: Path, rng: np.random.Generator) -> dict[str, Any]:
    """Record, import and compare one draw (JSON-ready): per evidence and for the slope used, without the wheel
    (``evidence``, ``used``) and with it (``wheel_given``)."""
    path = folder / "trial.csv"
    record(draw, path, rng)
    out: dict[str, Any] = {
        "truth": draw.truth,
        **({"truth_model": draw.truth_model} if draw.truth_model else {}),
        "wheel": draw.wheel,
        "slope_deg": draw.walk.slope_deg,
        "impacts": int(draw.walk.impacts.size),
        "ending": "stalled" if draw.walk.stalled else "walked",
        "lab": draw.lab_kind,
        "heading_deg": draw.lab.heading_deg,
        "hidden_stances": len(draw.gaps),
    }
    truth_rad = math.radians(draw.walk.slope_deg)
    unknown = _import(path, truth_rad, None)
    if "refused" in unknown:
        return {**out, **unknown}
    return {**out, **unknown, "wheel_given": _import(path, truth_rad, told_wheel(draw))}


def _group(rows: list[dict[str, Any]]) -> dict[str, Any]:
    n = len(rows)
    k = sum(r["covered"] for r in rows)
    lo, hi = wilson_interval(k, n)
    z = np.array([r["z"] for r in rows if r["z"] is not None], float)
    err = np.array([r["error_deg"] for r in rows], float)
    half = np.array([r["half_width_deg"] for r in rows], float)
    return {
        "n": n,
        "covered": k,
        "coverage": k / n if n else None,
        "coverage_ci95": [lo, hi] if n else None,
        "rms_z": float(np.sqrt(np.mean(z**2))) if z.size else None,
        "median_error_deg": float(np.median(err)) if n else None,
        "median_abs_error_deg": float(np.median(np.abs(err))) if n else None,
        "median_half_width_deg": float(np.median(half)) if n else None,
    }


@dataclass
class SlopeCoverageResult:
    draws: list[dict[str, Any]]
    seed: int
    cpu_s: float
    wall_s: float
    truths: tuple[str, ...] = field(default=TRUTHS)
    truth_model: str = "independent"  # the ER truth's model (`ER_TRUTH_MODELS`)

    def rows(self, kind: str, *, wheel_given: bool = False, **where: Any) -> list[dict[str, Any]]:
        """The comparison rows of one evidence ``kind`` (or ``used``) over the draws matching ``where``
        (``truth``, ``lab``, ``hidden``: True for draws with hidden stances, ``ending``); ``wheel_given``: of the
        imports told the wheel."""
        out = []
        for d0 in self.draws:
            if "refused" in d0:
                continue
            if any((bool(d0["hidden_stances"]) if key == "hidden" else d0[key]) != v for key, v in where.items()):
                continue
            d = d0.get("wheel_given", {}) if wheel_given else d0
            if "refused" in d or "used" not in d:
                continue
            if kind == "used":
                if d["used"] is not None:
                    out.append(d["used"])
            else:
                out.extend(r for r in d["evidence"] if r["kind"] == kind)
        return out

    def summary(self) -> dict[str, Any]:
        """The JSON of ``rimless trials slope-coverage``: per truth, per evidence kind (``used``: the slope the
        importer used, ``slope_ci_rad``) and per lab kind."""

        def per_truth(told: bool) -> dict[str, Any]:
            per: dict[str, Any] = {}
            for truth in self.truths:
                kinds = {k: _group(self.rows(k, wheel_given=told, truth=truth)) for k in KINDS}
                labs = {
                    lab: _group(self.rows("used", wheel_given=told, truth=truth, lab=lab))
                    for lab in sorted({d["lab"] for d in self.draws if d["truth"] == truth})
                }
                labs["hidden stances"] = _group(self.rows("used", wheel_given=told, truth=truth, hidden=True))
                labs["all stances seen"] = _group(self.rows("used", wheel_given=told, truth=truth, hidden=False))
                per[truth] = {"evidence": kinds, "labs": labs}
            return per

        refused = [d["refused"] for d in self.draws if "refused" in d]
        return {
            "truths": per_truth(False),
            "used": _group(self.rows("used")),
            "wheel_given": {
                "truths": per_truth(True),
                "used": _group(self.rows("used", wheel_given=True)),
                "wheel": "told_wheel: rigid model for the rigid truth, the ER truth's k (sd 10 %) and c",
            },
            "truth": self.truth_model,
            "truth_model": f"er: {ER_TRUTH_MEANING[self.truth_model]}; rigid: critical_truth's rigid wheel",
            "draws": len(self.draws),
            "refused": len(refused),
            "refused_reasons": refused,
            "per_draw": self.draws,
            "seed": self.seed,
            "goal": [0.90, 0.98],
            "sd_from_half_width": "sd = half width / 1.96",
            "cpu_s": self.cpu_s,
            "wall_s": self.wall_s,
        }


def run_slope_coverage(
    n_draws: int,
    seed: int,
    *,
    truths: tuple[str, ...] = TRUTHS,
    progress: Callable[[int, str], None] | None = None,
    truth_model: str = "independent",
) -> SlopeCoverageResult:
    """``n_draws`` truth walks of each truth (draw i of truth j from the seed sequence (seed, j, i)), recorded,
    imported and compared; the er truth walked by ``truth_model`` (`ER_TRUTH_MODELS`); ``progress(done,
    stage)`` as it goes."""
    bad = [t for t in truths if t not in TRUTHS]
    if bad or not truths:
        raise ValueError(f"truths must be among {', '.join(TRUTHS)}, got {list(truths)}")
    _check_model(truth_model)
    cpu, wall = time.process_time(), time.perf_counter()
    draws: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix=f"rimless-slope-coverage-{os.getpid()}-") as tmp:
        for i in range(n_draws):
            for truth in truths:
                rng = np.random.default_rng([seed, TRUTHS.index(truth), i])
                if progress:
                    progress(len(draws), f"{truth} walk {i + 1}")
                draws.append(measure_draw(draw_trial(rng, truth, truth_model=truth_model), Path(tmp), rng))
        if progress:
            progress(len(draws), "done")
    return SlopeCoverageResult(
        draws, seed, time.process_time() - cpu, time.perf_counter() - wall, tuple(truths), truth_model
    )
