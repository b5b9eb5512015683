"""Independent truths for the system cost of transport, written apart from rimless.sim.step.cot and
rimless.sim.model.electrical: the step's travel from the hub's world-frame displacement between the start and the
end of a recorded step (not from the touchdown geometry), the clutched time and the period from the recorded
trajectory segments (not from the phase records), and the system CoT from its definition."""

from __future__ import annotations

import math

import numpy as np

CLUTCHED_PHASE = 2  # rimless.sim.model.dynamics.SLSP_CLUTCHED: the phase index the segments carry


def _hub(q: np.ndarray) -> np.ndarray:
    # model.md section 2: p_H = p_b + L1 (sin theta, cos theta), slope frame
    return np.array([q[0] + q[3] * math.sin(q[2]), q[1] + q[3] * math.cos(q[2])])


def _world(p: np.ndarray, phi: float) -> tuple[float, float]:
    # slope frame (x down the slope, y its normal) to world (horizontal forward, vertical up)
    return p[0] * math.cos(phi) + p[1] * math.sin(phi), -p[0] * math.sin(phi) + p[1] * math.cos(phi)


def world_travel(step, phi: float) -> tuple[float, float]:
    """(horizontal distance s_x, vertical drop s_z) of the hub over one step, m: the post-impact state keeps the
    slope frame of the step (the new stance foot is not moved to the origin)."""
    x0, h0 = _world(_hub(step.y_start[:5]), phi)
    x1, h1 = _world(_hub(step.y_plus[:5]), phi)
    return x1 - x0, h0 - h1


def clutched_and_period_s(step) -> tuple[float, float]:
    """Clutched time and step period, s, from the recorded segments (first to last sample of each phase)."""
    clutched = sum(float(s.t[-1] - s.t[0]) for s in step.segments if s.phase == CLUTCHED_PHASE)
    period = float(step.segments[-1].t[-1] - step.segments[0].t[0])
    return clutched, period


def truth_system_cot(
    total_mass_kg: float,
    g: float,
    s_x: float,
    s_z: float,
    model: str,
    clutched_s: float,
    period_s: float,
    hold_w: float,
    switch_j: float,
    electronics_w: float,
    ve_electronics: bool,
) -> tuple[float, float]:
    """(E_el J, system CoT) from the definition: ER P_hold t_c + 2 E_sw + P_el T; VE P_el T only if it carries the
    electronics; CoT = (M g s_z + E_el) / (M g s_x)."""
    if model == "er":
        e = hold_w * clutched_s + 2.0 * switch_j + electronics_w * period_s
    else:
        e = electronics_w * period_s if ve_electronics else 0.0
    return e, (total_mass_kg * g * s_z + e) / (total_mass_kg * g * s_x)
