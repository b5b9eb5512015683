"""How much of a once-a-turn sinusoid the importer's hub offset leaves in the CoM height, against truths that know the hub.

A body point off the hub by e rises and falls by e once a turn; the importer fits the offset
(`rimless.analysis.kinematics.hub.fit_hub_offset`, or the centre of the stance feet when that is better determined)
and takes it out. Each draw walks a truth wheel, writes it as a Vicon export in a drawn lab
(`importer_coverage.draw_lab`: Z-up or Y-up, any heading, a Tracker object 36 mm off the hub or four uneven markers
whose centroid is 14 mm off it; 0.3 mm and 1 mrad of noise, 100 Hz; `critical_truth.record`), imports it
(`import_trial`, defaults) and compares with the truth:

- ``sinusoid_mm``: the CoM height's error (the truth's hub height along the slope's normal minus the imported
  ``com_height``, over the walking window) regressed on a constant, the distance down the slope and sin/cos of the
  truth's wheel angle: the amplitude of the sin/cos part;
- ``noise_share_mm``: what white noise of the residual's sigma gives such a coefficient, sigma sqrt(2 / n);
- ``hub_error_mm``: the rotating part of the imported minus the true hub (the offset's in-plane error, |e|, plus
  the tracked point's own noise's share of once a turn), and ``hub_sd_mm`` the standard error the import states
  for the offset (``hub_offset_sd_m``); ``z`` = |e| / sd (for a 2-D normal error of that sd on each axis, |e| <
  2.45 sd 95 % of the time);
- ``offset_error_mm`` and ``offset_z``: the same with the tracked point's noise taken out (the noise the recording
  added, drawn again from its seed: the object's translation noise, or the mean of the markers' noise, which is
  the noise of the markers' centroid the importer carries), so the offset's own error against its stated sd;
- ``offset_z_cov``: that error against the offset's 2 x 2 covariance (`HubOffsetFit.cov_m2`, of the height fit the
  import used), sqrt(e^T C^+ e) with e in the body frame (least squares of the hub difference, the noise taken out,
  on the import's rotations plus a constant; in the import's Z-up lab): chi with 2 degrees of freedom for an honest
  covariance; with the feet's sd, |e| / sd. ``offset_sd_axes_mm`` the covariance's two axes, ``misfit_sd_mm`` and
  ``misfit_p_value`` its misfit part and that part's test.

Truths (`TRUTHS`): ``er``, the ER wheel (k 1500-4000 N/m, c 2-20 N s/m, released at its gait's speed times
U(0.95, 1.08), 2-3.5 deg, 10 impacts: the adequacy study's walks), ``er-speed``, the same wheels released at U(1.3,
1.6) times the gait's speed (they slow down by 20-45 % over the walk: the speed, and with it the legs'
compression, changes a lot), and ``rigid``, the rigid wheel of `critical_truth` (mass 1.6-3 kg, legs 0.21-0.26 m,
inertia ratio 0.3-3, 2-4 deg, released at 1.2-2 times the speed that tops the first stance, 10 impacts). ``er`` at
Table 1 is drawn with ``table1=True``. The ER wheel is walked by the truth model ``truth_model`` (`TRUTH_MODELS`):
``independent`` (the default), `er_truth.er_truth_walk`, written apart from the simulator; ``simulator``,
`floquet_truth.er_walk` (the study's truth before session 23). The draws are the same for both (the same random
numbers; the walks differ by what the two models differ, 1e-8 in the step map).

Run: ``python -m rimless.analysis.validation.hub_offset_study --draws 10 --seed 0 [--sets er,er-speed]
[--truth-model simulator]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from rimless.analysis.validation.critical_truth import Y_UP_FROM_Z_UP, LossyWheel, record, recorded_frames, walk
from rimless.analysis.validation.floquet_truth import er_walk, slope_to_lab
from rimless.analysis.validation.importer_coverage import draw_lab

__all__ = ["SETS", "TRUTHS", "TRUTH_MODELS", "hub_offset_draw", "run_hub_offset_study"]

TRUTHS = ("er", "er-speed", "rigid")
#: the models that walk the ER wheel (`hub_offset_draw`'s ``truth_model``), the default first, and what each is
TRUTH_MODELS = {
    "independent": "er_truth.er_truth_walk, the ER wheel of docs/model.md written apart from rimless.sim",
    "simulator": "floquet_truth.er_walk, the simulator's ER wheel",
}
#: the release speed of ``er-speed`` walks, times the gait's
FAST_RELEASE = (1.3, 1.6)
#: the sets of draws `run_hub_offset_study` makes
SETS = ("er", "er-table1", "er-speed", "rigid")
STEPS = 10
#: 95 % of a 2-D normal error's length lies within this many sd (sqrt(-2 ln 0.05))
RAYLEIGH_95 = math.sqrt(-2.0 * math.log(0.05))


def _truth_walk(kind: str, rng: np.random.Generator, table1: bool, truth_model: str = "independent") -> tuple[Any, str]:
    if kind in ("er", "er-speed"):
        from rimless.analysis.validation.er_truth import er_truth_walk
        from rimless.sim.model.params import WheelParams

        walker = er_truth_walk if truth_model == "independent" else er_walk
        k = 2700.0 if table1 else float(rng.uniform(1500.0, 4000.0))
        c = 8.0 if table1 else float(rng.uniform(2.0, 20.0))
        slope = float(rng.uniform(2.0, 3.5))
        release = float(rng.uniform(*((0.95, 1.08) if kind == "er" else FAST_RELEASE)))
        wk = walker(WheelParams(stiffness_n_per_m=k, damping_ns_per_m=c), slope, 0.0, STEPS, rng, release=release)
        speeds = np.asarray(wk.post_impact_speed, float)
        return wk, f"ER k {k:.0f} N/m, c {c:.1f} N s/m" + (" (Table 1)" if table1 else "") + (
            f", released at {release:.2f} x the gait's speed (speed {speeds[0]:.2f} -> {speeds[-1]:.2f} rad/s)"
            if kind == "er-speed"
            else ""
        )
    mass, leg = float(rng.uniform(1.6, 3.0)), float(rng.uniform(0.21, 0.26))
    ratio = float(np.exp(rng.uniform(math.log(0.3), math.log(3.0))))
    wheel = LossyWheel(mass_kg=mass, inertia_hub_kg_m2=ratio * mass * leg**2, leg_m=leg)
    slope = float(rng.uniform(2.0, 4.0))
    top = math.sqrt(wheel.top_threshold(math.radians(slope)))
    return walk(
        wheel, slope, top * float(rng.uniform(1.2, 2.0)), STEPS
    ), f"rigid, inertia ratio {ratio:.2f}, L {leg:.3f} m"


def _tracked_noise(rec_seed: int, lab: Any, frames: int) -> np.ndarray:
    """(frames, 3) the noise `critical_truth.record` added to the tracked point (lab frame, m), drawn again from its
    seed in its order: the sub-frame offset, then the object's rotation and translation noise, or the markers'
    noise (the importer carries the markers' centroid: their mean)."""
    from rimless.analysis.validation.critical_truth import MARKERS_BODY_M

    rng = np.random.default_rng(rec_seed)
    rng.uniform(0, 1.0 / lab.rate_hz)
    if lab.markers:
        return rng.normal(0.0, lab.noise_m, (frames, len(MARKERS_BODY_M), 3)).mean(axis=1)
    rng.normal(0, lab.angle_noise_rad, (frames, 3))
    return rng.normal(0, lab.noise_m, (frames, 3))


@contextlib.contextmanager
def _recording_height_fits(fits: list[Any]):
    """Within: every hub offset height fit the importer makes (`kinematics.build`'s `fit_hub_offset`) is appended
    to ``fits`` with the rotations it was given, (fit, rotations) (read only; the import is unchanged)."""
    from rimless.analysis.kinematics import build

    inner = build.fit_hub_offset

    def recorded(*args: Any, **kwargs: Any) -> Any:
        fit = inner(*args, **kwargs)
        fits.append((fit, args[0]))
        return fit

    build.fit_hub_offset = recorded
    try:
        yield fits
    finally:
        build.fit_hub_offset = inner


def _offset_error_in_body(rot: np.ndarray, dh_m: np.ndarray) -> np.ndarray:
    """(3,) the offset's error in the body frame, m, from the imported minus the true hub with the tracked point's
    noise taken out, ``dh_m`` (k, 3) lab frame, and the import's world-from-body rotations ``rot`` (k, 3, 3) on the
    same frames: least squares of dh = R e + c (c a constant in the lab, e the same in the body)."""
    k = rot.shape[0]
    design = np.concatenate([rot, np.broadcast_to(np.eye(3), (k, 3, 3))], axis=2).reshape(3 * k, 6)
    sol, *_ = np.linalg.lstsq(design, dh_m.reshape(3 * k), rcond=None)
    return sol[:3]


def hub_offset_draw(
    kind: str,
    seed: int,
    folder: Path,
    *,
    table1: bool = False,
    importer: Any = None,
    truth_model: str = "independent",
) -> dict[str, Any]:
    """One draw (see the module doc): the truth, the lab, the import's hub source and the figures, in mm; the ER
    wheel walked by ``truth_model`` (`TRUTH_MODELS`)."""
    if truth_model not in TRUTH_MODELS:
        raise ValueError(f"truth_model must be one of {', '.join(TRUTH_MODELS)}, got {truth_model!r}")
    rng = np.random.default_rng(seed)
    wk, wheel = _truth_walk(kind, rng, table1, truth_model)
    lab = draw_lab(rng)
    rec_seed = int(rng.integers(1 << 31))
    path = folder / f"{kind}{seed}.csv"
    record(wk, path, np.random.default_rng(rec_seed), lab)
    # the frames `record` wrote, from its sub-frame offset (its first draw)
    tf, xs, hs, bs = recorded_frames(
        wk, lab.rate_hz, float(np.random.default_rng(rec_seed).uniform(0, 1.0 / lab.rate_hz))
    )
    if importer is None:
        from rimless.analysis.kinematics.build import import_trial as importer
    with _recording_height_fits([]) as fits:
        trial = importer(path)
    n = min(trial.time_s.size, tf.size)
    com = np.asarray(trial.series.data["com_height"])[:n]
    t0, t1 = trial.meta.window_s
    sel = (trial.time_s[:n] >= t0) & (trial.time_s[:n] <= t1) & np.isfinite(com)
    basis = np.column_stack(
        [np.ones(sel.sum()), xs[:n][sel] - xs[:n][sel].mean(), np.sin(bs[:n][sel]), np.cos(bs[:n][sel])]
    )
    err = hs[:n][sel] - com[sel]
    coef, *_ = np.linalg.lstsq(basis, err, rcond=None)
    sigma = float(np.std(err - basis @ coef))
    hub_t, _ = slope_to_lab(xs, hs, bs, wk.slope_deg, lab.heading_deg)
    if lab.up == "y":
        hub_t = hub_t @ Y_UP_FROM_Z_UP.T
    dh = np.asarray(trial.series.data["hub"])[:n][sel] - hub_t[:n][sel]
    hc, *_ = np.linalg.lstsq(basis[:, [0, 2, 3]], dh, rcond=None)
    hub_error = math.sqrt(float(np.sum(hc[1:] ** 2)) / 2.0)
    dh_own = dh - _tracked_noise(rec_seed, lab, tf.size)[:n][sel]
    oc, *_ = np.linalg.lstsq(basis[:, [0, 2, 3]], dh_own, rcond=None)
    offset_error = math.sqrt(float(np.sum(oc[1:] ** 2)) / 2.0)
    sd = getattr(trial.meta, "hub_offset_sd_m", None)
    last, rot = fits[-1] if fits else (None, None)
    height = last if last is not None and sd is not None and last.sd_m == sd else None
    sd_axis = height.sd_per_axis_m if height is not None else sd  # the feet's sd: one for both axes
    z2 = None  # the offset's own error against the stated covariance: e^T C^+ e (chi^2 with 2 dof when honest)
    if height is not None and rot is not None:
        from rimless.analysis.kinematics.vertical import is_z_up, rotation_to_z_up, up_vector

        up = trial.meta.up_axis  # the import fits in its lab turned Z up (p' = Q p); dh is in the file's frame
        q = np.eye(3) if is_z_up(up) else rotation_to_z_up(up_vector(up))
        e = _offset_error_in_body(np.asarray(rot[np.flatnonzero(sel)]), dh_own @ q.T)
        z2 = float(e @ np.linalg.pinv(height.cov_m2, rcond=1e-10) @ e)
    elif sd:
        z2 = (offset_error / sd) ** 2
    return {
        "truth": kind,
        "truth_model": truth_model if kind != "rigid" else "critical_truth",
        "seed": seed,
        "wheel": wheel,
        "lab": lab.describe(),
        "hub_source": trial.meta.hub_source,
        "sinusoid_mm": math.hypot(coef[2], coef[3]) * 1e3,
        "noise_share_mm": sigma * math.sqrt(2.0 / sel.sum()) * 1e3,
        "hub_error_mm": hub_error * 1e3,
        "hub_sd_mm": None if sd is None else sd * 1e3,
        "z": None if not sd else hub_error / sd,
        "offset_error_mm": offset_error * 1e3,
        "offset_z": None if not sd else offset_error / sd,
        "offset_sd_axis_mm": None if sd_axis is None else sd_axis * 1e3,
        "offset_z_axis": None if not sd_axis else offset_error / sd_axis,
        "noise_power": None if height is None else height.noise_power,
        "offset_z_cov": None if z2 is None else math.sqrt(z2),
        "offset_sd_axes_mm": None if height is None else [v * 1e3 for v in height.sd_axes_m],
        "misfit_sd_mm": None if height is None else height.misfit_sd_m * 1e3,
        "misfit_p_value": None if height is None else height.misfit_p_value,
        "noise_model": None if height is None else getattr(height, "noise_model", None),
        "turns": float(np.ptp(bs[:n][sel])) / (2 * math.pi),
    }


def run_hub_offset_study(
    draws: int = 10,
    seed: int = 0,
    *,
    importer: Any = None,
    sets: tuple[str, ...] | None = None,
    truth_model: str = "independent",
) -> dict[str, Any]:
    """``draws`` draws of each truth (and of the ER truth at Table 1: ``er-table1``), seeds ``seed`` up, of the
    ``sets`` named (default all of `SETS`); the rows and per set the median and largest sinusoid, the median noise
    share, how often |e| < 2.45 sd with the rms of |e| / sd / sqrt(2) (1 for an honest sd of an isotropic error),
    and the same for the offset's own error (``offset_held_95``, ``offset_rms_z``), against the per-axis sd
    (``offset_axis_held_95``, ``offset_axis_rms_z``) and against the 2 x 2 covariance (``offset_cov_held_95``,
    ``offset_cov_rms_z``: within the chi^2_2 95 % region, rms over 2 of e^T C^+ e). The ER wheel is walked by
    ``truth_model`` (`TRUTH_MODELS`; the output's ``truth_model`` says which)."""
    sets = SETS if sets is None else tuple(sets)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in sets:
            kind, table1 = name.removesuffix("-table1"), name.endswith("-table1")
            for i in range(draws):
                rows.append(
                    hub_offset_draw(
                        kind, seed + i, Path(tmp), table1=table1, importer=importer, truth_model=truth_model
                    )
                )
                rows[-1]["table1"] = table1
                rows[-1]["set"] = name
    summary: dict[str, dict[str, Any]] = {}
    for name in (*sets, "all"):
        sub = [r for r in rows if name in ("all", r["set"])]
        amp = np.array([r["sinusoid_mm"] for r in sub])
        summary[name] = {
            "trials": len(sub),
            "sinusoid_median_mm": float(np.median(amp)),
            "sinusoid_max_mm": float(np.max(amp)),
            "noise_share_median_mm": float(np.median([r["noise_share_mm"] for r in sub])),
        }
        for prefix, key in (
            ("", "z"),
            ("offset_", "offset_z"),
            ("offset_axis_", "offset_z_axis"),
            ("offset_cov_", "offset_z_cov"),
        ):
            zs = np.array([r[key] for r in sub if r[key] is not None])
            summary[name][prefix + "held_95"] = f"{int((zs < RAYLEIGH_95).sum())}/{zs.size}" if zs.size else None
            summary[name][prefix + "rms_z"] = float(np.sqrt(np.mean(zs**2) / 2.0)) if zs.size else None
    return {
        "rows": rows,
        "summary": summary,
        "draws": draws,
        "seed": seed,
        "truth_model": f"{truth_model}: {TRUTH_MODELS[truth_model]}",
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sets", default=",".join(SETS), help="comma-separated, of " + ", ".join(SETS))
    ap.add_argument(
        "--truth-model",
        default="independent",
        help="the model that walks the ER wheel: " + "; ".join(f"{k} ({v})" for k, v in TRUTH_MODELS.items()),
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    sets = tuple(args.sets.split(","))
    bad = [n for n in sets if n not in SETS]
    if args.truth_model not in TRUTH_MODELS or bad:
        what = (
            f"--sets: unknown set {bad[0]!r}, of {', '.join(SETS)}"
            if bad
            else (f"--truth-model: {args.truth_model!r} is not one of {', '.join(TRUTH_MODELS)}")
        )
        print(f"error: {what}", file=sys.stderr)
        raise SystemExit(2)
    out = run_hub_offset_study(args.draws, args.seed, sets=sets, truth_model=args.truth_model)
    if args.json:
        print(json.dumps(out, indent=1))
        return
    for r in out["rows"]:
        sd = "-" if r["hub_sd_mm"] is None else f"{r['hub_sd_mm']:.3f}"
        print(
            f"{r['truth']:5s} {r['seed']:3d} {r['lab']:34s} sinusoid {r['sinusoid_mm']:.3f} mm (noise share "
            f"{r['noise_share_mm']:.3f}), hub error {r['hub_error_mm']:.3f} mm (offset's own "
            f"{r['offset_error_mm']:.3f}), sd {sd}"
        )
    print("truth model:", out["truth_model"])
    for k, v in out["summary"].items():
        print(k, v)


if __name__ == "__main__":
    main()
