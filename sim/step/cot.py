"""Cost of transport of one step from its record: how far the wheel went, how long the clutch held, and the
mechanical, electrical and system CoT (rimless.sim.model.electrical).

Distances come from the pre-impact state of the step: the new stance foot is the swing foot at touchdown, so
one step moves every mass of a period-1 gait by d = x_swing - x_b along the slope (m), i.e. s_x = d cos(phi)
horizontally and s_z = d sin(phi) down. The clutched time is the recorded `slsp_clutched` phase duration (the
clutch is locked from maximum compression to the impact, where it is released).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from rimless.sim.model.electrical import ClutchPower, system_cot
from rimless.sim.model.mechanics import ALPHA
from rimless.sim.model.params import WheelParams


@dataclass(frozen=True)
class StepTransport:
    """One step's travel and timing: along-slope step length d (m), period (s), clutched time (s)."""

    step_length_m: float
    period_s: float
    clutched_s: float
    slope_rad: float

    @property
    def s_x_m(self) -> float:
        """Horizontal distance travelled, m."""
        return self.step_length_m * math.cos(self.slope_rad)

    @property
    def s_z_m(self) -> float:
        """Vertical drop, m."""
        return self.step_length_m * math.sin(self.slope_rad)


def step_length_m(y_minus: np.ndarray, leg_length_m: float) -> float:
    """Along-slope distance from the stance foot b to the swing foot at touchdown, m (pre-impact state)."""
    x_b, _, theta, l1 = (float(v) for v in y_minus[:4])
    x_hub = x_b + l1 * math.sin(theta)
    x_swing = x_hub - leg_length_m * math.sin(theta - ALPHA)
    return x_swing - x_b


def clutched_time_s(step: Any) -> float:
    """Time the stance leg's clutch held during the step, s (0 for VE)."""
    return float(step.phase_durations_s.get("slsp_clutched", 0.0))


def step_transport(step: Any, params: WheelParams) -> StepTransport:
    """The travel and timing of a recorded step (rimless.sim.step.hybrid.StepResult)."""
    return StepTransport(
        step_length_m(step.y_minus, params.leg_length_m), float(step.period_s), clutched_time_s(step), params.slope_rad
    )


def cot_of(tr: StepTransport, params: WheelParams, model: str, power: ClutchPower) -> dict[str, float]:
    """mechanical_cot, electrical_energy_per_step_j and system_cot of one period-1 step, with its travel.

    M = params.total_mass_kg (m_H + 8 m); mechanical CoT = M g s_z / (M g s_x) = tan(phi)."""
    M, g = params.total_mass_kg, params.gravity_m_s2
    e_el = power.energy_per_step_j(model, tr.clutched_s, tr.period_s)
    return {
        "mechanical_cot": system_cot(M, g, tr.s_x_m, tr.s_z_m, 0.0),
        "electrical_energy_per_step_j": e_el,
        "system_cot": system_cot(M, g, tr.s_x_m, tr.s_z_m, e_el),
        "clutched_time_s": tr.clutched_s,
        "step_length_m": tr.step_length_m,
        "cot_mass_kg": M,
    }


def step_cot(step: Any, params: WheelParams, model: str, power: ClutchPower) -> dict[str, float]:
    """cot_of for a recorded step."""
    return cot_of(step_transport(step, params), params, model, power)
