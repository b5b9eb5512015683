"""The wheel's mechanics for one mass model: M, h, foot-a Jacobian, energies, geometry.

Wraps the generated code (rimless.sim.model.generated.*). Frame: slope-aligned, x down the slope, y the
outward normal; q = [x_b, y_b, theta, L1, L2]; world height of a point = -x sin(phi) + y cos(phi).
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from rimless.sim.model.params import SPOKE_ANGLE_RAD, WheelParams

ALPHA = SPOKE_ANGLE_RAD

_MODULES = {"eight-leg": "eight_leg", "sliding-leg": "sliding_leg", "active-feet": "active_feet"}


def generated_module(mass_model: str) -> ModuleType:
    """The generated module of a mass model."""
    return importlib.import_module(f"rimless.sim.model.generated.{_MODULES[mass_model]}")


@dataclass(frozen=True)
class Mechanics:
    """The numeric functions of one mass model bound to a parameter vector."""

    params: WheelParams
    gen: ModuleType
    p: np.ndarray

    @classmethod
    def of(cls, params: WheelParams) -> Mechanics:
        """p = WheelParams.as_vector() + (guide_friction_n,): the generated code reads the first eight, the
        compiled friction phases F_c (rimless.sim.model.friction.FRICTION_INDEX)."""
        return cls(
            params,
            generated_module(params.mass_model),
            np.array(params.as_vector() + (params.guide_friction_n,), dtype=float),
        )

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        return self.gen.mass_matrix(q, self.p)

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return self.gen.bias(q, qd, self.p)

    def jac_a(self, q: np.ndarray) -> np.ndarray:
        return self.gen.jac_a(q, self.p)

    def jdot_qd_a(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return self.gen.jdot_qd_a(q, qd, self.p)

    def kinetic(self, q: np.ndarray, qd: np.ndarray) -> float:
        return float(self.gen.kinetic(q, qd, self.p))

    def potential(self, q: np.ndarray) -> float:
        return float(self.gen.potential(q, self.p))

    def energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Total mechanical energy T + V in J (gravity of every modelled mass and both springs)."""
        return self.kinetic(q, qd) + self.potential(q)


# -------------------------------------------------------------------------------------------------
# Geometry (closed forms short enough to write by hand; the derivation uses the same definitions)


def hub_position(q: np.ndarray) -> np.ndarray:
    """Hub position in the slope frame, m."""
    return np.array([q[0] + q[3] * math.sin(q[2]), q[1] + q[3] * math.cos(q[2])])


def foot_a(q: np.ndarray) -> np.ndarray:
    """Trailing foot a position in the slope frame, m."""
    hub = hub_position(q)
    return hub - q[4] * np.array([math.sin(q[2] + ALPHA), math.cos(q[2] + ALPHA)])


def swing_height(q: np.ndarray, leg_length_m: float) -> float:
    """Height of the next swing foot (length L0) above the slope, m: L1 cos(theta) - L0 cos(alpha - theta) + y_b."""
    return q[1] + q[3] * math.cos(q[2]) - leg_length_m * math.cos(ALPHA - q[2])


def world_height(point: np.ndarray, slope_rad: float) -> float:
    """World (gravity-vertical) height of a slope-frame point, m."""
    return -point[0] * math.sin(slope_rad) + point[1] * math.cos(slope_rad)
