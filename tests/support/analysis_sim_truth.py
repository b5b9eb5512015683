"""Synthetic trials from the simulator with a chosen damping, with marker noise, as trial-like objects."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from tests.support.analysis_rigid_truth import DuckTrial


def sim_trial(
    params,
    slope_deg: float,
    release: float,
    rng: np.random.Generator,
    *,
    name: str,
    n_steps: int = 9,
    rate_hz: float = 100.0,
    noise_m: float = 0.3e-3,
    timing_noise_s: float = 0.5e-3,
) -> DuckTrial:
    """ER wheel released at theta = -alpha/2 with theta' = release; the recording starts inside step 1;
    CoM height sampled at rate_hz with Gaussian noise, impact times with timing noise."""
    from rimless.sim.step.backend import make_integrator
    from rimless.sim.step.gait import simulate_steps

    p = params.replace(slope_rad=math.radians(slope_deg))
    g = simulate_steps(
        p, "er", np.array([-math.pi / 8, release]), n_steps, make_integrator("auto", rtol=1e-9), record_dt=1e-3
    )
    assert g.failure is None, g.failure
    ts, order = np.unique(np.asarray(g.table["t_s"]), return_index=True)
    com = np.asarray(g.table["com_height_normal_m"])[order]
    periods = np.array([s.period_s for s in g.steps])
    impacts = np.cumsum(periods)
    t = np.arange(0.5 * periods[0], impacts[-1] + 0.3 * periods[-1], 1.0 / rate_hz)
    t = t[t <= ts[-1]]
    y = np.interp(t, ts, com) + rng.normal(0.0, noise_m, t.size) - 0.2  # heights from the impact line
    imp = impacts[:-1] + rng.normal(0.0, timing_noise_s, impacts.size - 1)
    meta = SimpleNamespace(
        slope_deg=slope_deg,
        source_file=name,
        rate_hz=rate_hz,
        slope_source="given",
        com_height_reference="impact line",
        step_refused=None,
    )
    gap = np.zeros(t.size, bool)
    return DuckTrial(
        time_s=t,
        impact_time_s=imp,
        step_period_s=np.diff(imp),
        meta=meta,
        series={"com_height": y, "gap": gap, "interpolated": gap},
    )
