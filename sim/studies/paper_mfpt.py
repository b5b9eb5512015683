"""Metastability in `rimless paper` (issue 33): the mean first-passage time against the terrain's roughness for
the three wheels, and the ER wheel against the VE wheel per k.

Every MFPT is rimless.sim.studies.mfpt.mesh_mfpt (Byl and Tedrake's Markov chain on a discretised section,
with a coarser mesh for its discretisation error): each step's slope drawn independently from N(slope, S^2)
about the wheel's slope (Table 1: 2.865 deg), the wheel starting at its period-1 gait z*.

- `mfpt_terrain.csv`: for S in `sds_deg`, the rigid wheel (RigidWheel, paper convention: M = m_H, I_c; its
  closed-form map in the section coordinates, `RigidSlopeMap`), the ER and the VE wheel at the wheel's k. The
  rigid wheel's post-impact theta+ is -alpha/2 whatever came before, so its mesh has one theta+ node.
- `mfpt_per_k.csv`: ER and VE at S = `per_k_sd_deg` for each k of the paper's grid.
- `fig_mfpt.png` (and `.csv` = both tables) and `mfpt.json` (the settings, both tables).

Row keys (units in the names): wheel, k_n_per_m (None for the rigid wheel), slope_deg, terrain_sd_deg,
mfpt_steps, mfpt_discretisation_error_steps (2 |fine - coarse|), mfpt_extrapolated_steps, lambda2,
mfpt_quasi_stationary_steps, gait_theta_plus_rad, gait_theta_dot_plus_rad_s (the z* the walks start from; for VE
the gait `rimless sim fixed-point` finds, which may be one of several branches), nodes_theta, nodes_theta_dot,
slopes, map_evaluations, failure (None, or why there is no number: no gait at that k, ...). A missing number is
None, never NaN.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rimless.errors import RimlessError
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.params import SPOKE_ANGLE_RAD, WheelParams
from rimless.sim.model.rigid import RigidWheel

WHEELS = ("rigid", "er", "ve")
SDS_DEG = (1.0, 2.0, 3.0)  # the terrain's standard deviations of the MFPT-against-S table, deg
PER_K_SD_DEG = 2.0  # the terrain of the ER-against-VE-per-k table, deg
TERRAIN_CSV = "mfpt_terrain.csv"
PER_K_CSV = "mfpt_per_k.csv"
FIGURE = "fig_mfpt"
COLOURS = {"rigid": "#7f7f7f", "er": "#1f77b4", "ve": "#ff7f0e"}


@dataclass(frozen=True)
class Mesh:
    """The fine mesh of every MFPT: section nodes (theta+, theta'+) and slope values per node (the coarse mesh
    for the error estimate is about 2/3 of each)."""

    nodes_theta: int = 9
    nodes_theta_dot: int = 30
    slopes: int = 24


PAPER_MESH = Mesh()  # coarser than `rimless sim mfpt`'s 15 x 60 x 48: 22 MFPTs on the default k grid
CHEAP_MESH = Mesh(3, 10, 8)  # for tests: seconds, with its (larger) discretisation error reported


class RigidSlopeMap:
    """P(z, slope_rad) of the rigid wheel in closed form, in the compliant wheels' section coordinates (z =
    (theta+ rad from the slope normal, theta'+ rad/s)): over a stance 1/2 I_p w^2 + M g L cos(theta + phi) is
    conserved (I_p = I + M L^2 about the foot), the stance ends at theta = alpha/2 and the impact gives
    w+ = beta w-, theta+ = -alpha/2. A step fails by a stall (does not pass the top theta = -phi, or w <= 0)
    or by lift-off (the foot's normal force M g cos(theta + phi) - M L w^2 below 0 during the stance)."""

    def __init__(self, wheel: RigidWheel) -> None:
        self.wheel = wheel
        ip = wheel.inertia_kg_m2 + wheel.mass_kg * wheel.leg_length_m**2
        self.c = wheel.mass_kg * wheel.gravity_m_s2 * wheel.leg_length_m / ip  # 1/s^2
        self.g_over_l = wheel.gravity_m_s2 / wheel.leg_length_m

    def __call__(self, z: np.ndarray, slope_rad: float) -> np.ndarray:
        theta, w = float(z[0]), float(z[1])
        e = w * w + 2 * self.c * math.cos(theta + slope_rad)  # w(theta)^2 + 2 c cos(theta + phi)
        if w <= 0 or (theta < -slope_rad and e < 2 * self.c):
            raise StepFailure(FailureReason.STALL, "the rigid wheel does not pass over the top")
        lowest_cos = min(math.cos(theta + slope_rad), math.cos(SPOKE_ANGLE_RAD / 2 + slope_rad))
        if e > (2 * self.c + self.g_over_l) * lowest_cos:
            raise StepFailure(FailureReason.STANCE_LIFT_OFF, "the rigid wheel's foot loses contact")
        w_minus = math.sqrt(e - 2 * self.c * math.cos(SPOKE_ANGLE_RAD / 2 + slope_rad))
        return np.array([-SPOKE_ANGLE_RAD / 2, self.wheel.beta * w_minus])


def _row(wheel: str, k: float | None, params: WheelParams, sd_deg: float, res: dict[str, Any] | None) -> dict[str, Any]:
    row: dict[str, Any] = {
        "wheel": wheel,
        "k_n_per_m": k,
        "slope_deg": params.slope_deg,
        "terrain_sd_deg": sd_deg,
    }
    keys = (
        "mfpt_steps",
        "mfpt_discretisation_error_steps",
        "mfpt_extrapolated_steps",
        "lambda2",
        "mfpt_quasi_stationary_steps",
    )
    if res is None or "failure" in res:
        row.update({key: None for key in keys})
        row.update(gait_theta_plus_rad=None, gait_theta_dot_plus_rad_s=None, map_evaluations=0)
        row["failure"] = (res or {}).get("failure", "not computed")
        return row
    row.update({key: float(res[key]) for key in keys})
    row.update(
        gait_theta_plus_rad=float(res["start"]["theta_plus_rad"]),
        gait_theta_dot_plus_rad_s=float(res["start"]["theta_dot_plus_rad_s"]),
        nodes_theta=int(res["fine"]["nodes"][0]),
        nodes_theta_dot=int(res["fine"]["nodes"][1]),
        slopes=int(res["fine"]["slopes"]),
        map_evaluations=int(res["map_evaluations"]),
        failure=None,
    )
    return row


def wheel_mfpt(
    params: WheelParams, wheel: str, sd_deg: float, mesh: Mesh, *, backend: str, rtol: float
) -> dict[str, Any]:
    """The mesh MFPT of one wheel ("rigid", "er", "ve") at `params` on terrain of standard deviation sd_deg:
    mfpt_study's result, or {"failure": why} when the wheel has no gait there."""
    from rimless.sim.studies.mfpt import mesh_mfpt, mfpt_study

    sd = math.radians(sd_deg)
    if wheel != "rigid":
        try:
            return mfpt_study(
                params,
                wheel,
                sd,
                nodes=(mesh.nodes_theta, mesh.nodes_theta_dot),
                slopes=mesh.slopes,
                backend=backend,
                rtol=rtol,
            )
        except RimlessError as err:  # no gait at this k, a failed mesh: a classified row, not a crash
            return {"failure": f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"}
    rigid = RigidWheel.from_params(params, "paper")
    slope = params.slope_rad
    w_star = rigid.fixed_point_omega(slope) if slope > 0 else 0.0
    if not w_star**2 > rigid.barrier(slope):
        return {"failure": f"no rigid gait at {params.slope_deg:g} deg (below its critical slope)"}
    z_star = np.array([-SPOKE_ANGLE_RAD / 2, w_star])
    res = mesh_mfpt(RigidSlopeMap(rigid), slope, sd, z_star, nodes=(1, mesh.nodes_theta_dot), slopes=mesh.slopes)
    return {**res, "start": {"theta_plus_rad": float(z_star[0]), "theta_dot_plus_rad_s": float(z_star[1])}}


def metastability_table(
    params: WheelParams,
    ks: tuple[float, ...],
    *,
    sds_deg: tuple[float, ...] = SDS_DEG,
    per_k_sd_deg: float = PER_K_SD_DEG,
    mesh: Mesh = PAPER_MESH,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: Callable[[str], None] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """{"terrain": MFPT against S for the three wheels at `params`, "per_k": ER and VE per k at per_k_sd_deg}
    (rows as in the module doc)."""
    say = progress or (lambda msg: None)
    done: dict[tuple[str, float | None, float], dict[str, Any]] = {}  # a (wheel, k, S) of both tables once

    def row(wheel: str, k: float | None, sd: float) -> dict[str, Any]:
        if (wheel, k, sd) not in done:
            say(f"MFPT: {wheel} wheel{'' if k is None else f' at k = {k:g} N/m'}, terrain sd {sd:g} deg")
            p = params if k is None else params.replace(stiffness_n_per_m=k)
            done[(wheel, k, sd)] = _row(wheel, k, p, sd, wheel_mfpt(p, wheel, sd, mesh, backend=backend, rtol=rtol))
        return dict(done[(wheel, k, sd)])

    terrain = [
        row(wheel, None if wheel == "rigid" else float(params.stiffness_n_per_m), float(sd))
        for wheel in WHEELS
        for sd in sds_deg
    ]
    per_k = [row(wheel, float(k), float(per_k_sd_deg)) for k in ks for wheel in ("er", "ve")]
    return {"terrain": terrain, "per_k": per_k}


def figure_mfpt(table: dict[str, list[dict[str, Any]]], out: Path) -> Path:
    """MFPT (steps, log) against S for the three wheels, and against k for ER and VE, with the discretisation
    error as bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rimless.sim.studies.figures import save_figure

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    for ax, rows, x_key, groups in (
        (ax1, table["terrain"], "terrain_sd_deg", WHEELS),
        (ax2, table["per_k"], "k_n_per_m", ("er", "ve")),
    ):
        for wheel in groups:
            pts = [r for r in rows if r["wheel"] == wheel and r["mfpt_steps"] is not None and r["mfpt_steps"] > 0]
            if pts:
                ax.errorbar(
                    [r[x_key] for r in pts],
                    [r["mfpt_steps"] for r in pts],
                    yerr=[r["mfpt_discretisation_error_steps"] for r in pts],
                    marker="o",
                    capsize=3,
                    color=COLOURS[wheel],
                    label=wheel.upper() if wheel != "rigid" else "rigid",
                )
        ax.set_yscale("log")
        ax.set_ylabel("mean first-passage time (steps)")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    slope = (table["terrain"] or table["per_k"] or [{"slope_deg": float("nan")}])[0]["slope_deg"]
    ax1.set_xlabel("terrain slope standard deviation S (deg)")
    ax1.set_title(f"MFPT against S at {slope:.3f} deg (mesh; bars: discretisation error)", fontsize=9)
    ax2.set_xlabel("leg stiffness k (N/m)")
    sd_k = table["per_k"][0]["terrain_sd_deg"] if table["per_k"] else float("nan")
    ax2.set_title(f"ER and VE per k, S = {sd_k:g} deg", fontsize=9)
    return Path(save_figure(fig, out / f"{FIGURE}.png", option="--out"))


def metastability_paper(
    out: Path,
    params: WheelParams,
    ks: tuple[float, ...],
    *,
    backend: str = "auto",
    rtol: float = 1e-10,
    progress: Callable[[str], None] | None = None,
    mesh: Mesh = PAPER_MESH,
    sds_deg: tuple[float, ...] = SDS_DEG,
) -> dict[str, Any]:
    """Write mfpt_terrain.csv, mfpt_per_k.csv, fig_mfpt.png (+ .csv) and mfpt.json into `out`; returns
    {"files", "terrain", "per_k"}."""
    import json

    import pandas as pd

    from rimless.output import atomic_file
    from rimless.sim.studies.paper_figures import write_csv

    table = metastability_table(params, ks, sds_deg=sds_deg, mesh=mesh, backend=backend, rtol=rtol, progress=progress)
    files = [
        write_csv(pd.DataFrame(table["terrain"]), out / TERRAIN_CSV),
        write_csv(pd.DataFrame(table["per_k"]), out / PER_K_CSV),
        write_csv(pd.DataFrame(table["terrain"] + table["per_k"]), out / f"{FIGURE}.csv"),
        figure_mfpt(table, out),
    ]
    meta = {
        "method": "mesh (rimless.sim.studies.mfpt.mesh_mfpt; Byl and Tedrake)",
        "terrain": "each step's slope drawn independently from N(slope, S^2); the section point carries over",
        "slope_deg": params.slope_deg,
        "params": params.to_dict(),
        "rigid_wheel": "closed form, paper convention (M = m_H, inertia I_c)",
        "mesh": {"nodes_theta": mesh.nodes_theta, "nodes_theta_dot": mesh.nodes_theta_dot, "slopes": mesh.slopes},
        "per_k_terrain_sd_deg": table["per_k"][0]["terrain_sd_deg"] if table["per_k"] else None,
        **table,
    }
    path = out / "mfpt.json"
    with atomic_file(path, option="--out") as tmp:
        Path(tmp).write_text(json.dumps(meta, indent=1))
    files.append(path)
    return {"files": files, **table}
