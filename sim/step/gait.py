"""Several consecutive steps with their trajectory: the gait a user looks at or exports.

Only this path records samples; the Poincaré/fixed-point path never does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rimless.sim.integrate.reference import Integrator
from rimless.sim.model import friction as fr
from rimless.sim.model.dynamics import PHASE_NAMES, accel
from rimless.sim.model.failures import StepFailure
from rimless.sim.model.mechanics import Mechanics, foot_a, hub_position, world_height
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.hybrid import ClutchPolicy, StepResult, simulate_step

COLUMNS = [
    "t_s",
    "step",
    "phase",
    "x_b_m",
    "y_b_m",
    "theta_rad",
    "L1_m",
    "L2_m",
    "dx_b_m_s",
    "dy_b_m_s",
    "dtheta_rad_s",
    "dL1_m_s",
    "dL2_m_s",
    "hub_x_m",
    "hub_y_m",
    "com_height_normal_m",
    "com_height_world_m",
    "foot_a_y_m",
]
FORCE_COLUMNS = ["lambda_b_x_N", "lambda_b_y_N", "lambda_a_x_N", "lambda_a_y_N", "lambda_clutch_N"]


@dataclass
class GaitTrajectory:
    """Consecutive steps and their samples. `table` columns: COLUMNS (+ FORCE_COLUMNS with forces)."""

    params: WheelParams
    model: str
    steps: list[StepResult]
    table: dict[str, np.ndarray]
    failure: StepFailure | None

    def to_frame(self):
        import pandas as pd

        return pd.DataFrame(self.table)


def simulate_steps(
    params: WheelParams,
    model: str,
    z0: np.ndarray,
    n_steps: int,
    integrator: Integrator,
    *,
    clutch: ClutchPolicy | None = None,
    record_dt: float = 1e-3,
    forces: bool = False,
    progress: Callable[[int], None] | None = None,
) -> GaitTrajectory:
    """Simulate n_steps from section point z0, recording samples every record_dt seconds.

    The post-impact state of each step starts the next one as it is (feet keep their positions on the
    slope), so the samples form one continuous walk. A failing step ends the walk; it is returned in
    `failure` with the steps done so far.
    """
    mech = Mechanics.of(params)
    y = state_from_section(mech, np.asarray(z0, dtype=float))
    t = 0.0
    steps: list[StepResult] = []
    rows: dict[str, list[np.ndarray]] = {name: [] for name in COLUMNS + (FORCE_COLUMNS if forces else [])}
    failure = None
    for k in range(n_steps):
        try:
            res = simulate_step(mech, model, y, integrator, t0=t, clutch=clutch, record_dt=record_dt)
        except StepFailure as err:
            failure = err
            break
        steps.append(res)
        for seg in res.segments or []:
            _append_segment(mech, rows, seg.t, seg.y, k, seg.phase, forces)
        y, t = res.y_plus, t + res.period_s
        if progress:
            progress(k + 1)
    table = {name: (np.concatenate(v) if v else np.empty(0)) for name, v in rows.items()}
    return GaitTrajectory(params, model, steps, table, failure)


def _append_segment(
    mech: Mechanics,
    rows: dict[str, list[np.ndarray]],
    t: np.ndarray,
    y: np.ndarray,
    step: int,
    phase: int,
    forces: bool,
) -> None:
    n = len(t)
    phi = mech.params.slope_rad
    hub = np.array([hub_position(yi[:5]) for yi in y])
    rows["t_s"].append(t)
    rows["step"].append(np.full(n, step))
    rows["phase"].append(np.full(n, PHASE_NAMES[phase]))
    for j, name in enumerate(COLUMNS[3:13]):
        rows[name].append(y[:, j])
    rows["hub_x_m"].append(hub[:, 0])
    rows["hub_y_m"].append(hub[:, 1])
    rows["com_height_normal_m"].append(hub[:, 1] - y[:, 1])
    rows["com_height_world_m"].append(np.array([world_height(h, phi) for h in hub]))
    rows["foot_a_y_m"].append(np.array([foot_a(yi[:5])[1] for yi in y]))
    if forces:
        lam_all = np.full((n, 5), np.nan)
        for i, yi in enumerate(y):
            _, lam = (
                fr.sample_accel(mech, phase, yi)
                if mech.params.guide_friction_n > 0.0
                else accel(mech, phase, yi[:5], yi[5:])
            )
            lam_all[i, 0:2] = lam[0:2]
            if phase == 0:
                lam_all[i, 2:4] = lam[2:4]
            elif phase == 2:
                lam_all[i, 4] = lam[2]
        for j, name in enumerate(FORCE_COLUMNS):
            rows[name].append(lam_all[:, j])


def trajectory_metadata(traj: GaitTrajectory, extra: dict | None = None) -> dict:
    """What a trajectory file must say about itself: model, wheel parameters (SI), units, steps."""
    return {
        "model": traj.model,
        "params": traj.params.to_dict(),
        "units": "SI (m, s, rad, N); slope in rad",
        "steps": len(traj.steps),
        "failure": None if traj.failure is None else str(traj.failure),
        **(extra or {}),
    }


def write_trajectory(traj: GaitTrajectory, path, extra: dict | None = None) -> None:
    """Write the samples as Parquet (the model and wheel parameters in the schema metadata under b"rimless")
    or CSV, to a temporary name renamed when complete."""
    import json
    from pathlib import Path

    import pyarrow as pa
    import pyarrow.parquet as pq

    from rimless.output import atomic_file

    path = Path(path)
    frame = traj.to_frame()
    with atomic_file(path) as tmp:  # an interrupted write leaves neither the file nor its temporary
        if path.suffix.lower() == ".parquet":
            table = pa.Table.from_pandas(frame, preserve_index=False)
            meta = dict(table.schema.metadata or {})
            meta[b"rimless"] = json.dumps(trajectory_metadata(traj, extra)).encode()
            pq.write_table(table.replace_schema_metadata(meta), tmp)
        else:
            frame.to_csv(tmp, index=False)
