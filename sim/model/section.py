"""The Poincaré section just after impact: z = (theta+, theta'+) <-> the full post-impact state.

In double support the wheel has one degree of freedom: with foot b at the origin, L1 = L0, L2 follows
from y_a = 0, and q' is the null vector of J_c scaled by theta' (model.md section 6).
"""

from __future__ import annotations

import math

import numpy as np

from rimless.sim.model.mechanics import ALPHA, Mechanics


def trailing_length(theta: float, leg_length_m: float) -> float:
    """L2 that puts foot a on the slope when L1 = L0: L0 cos(theta) / cos(theta + alpha), m."""
    return leg_length_m * math.cos(theta) / math.cos(theta + ALPHA)


def double_support_velocity(mech: Mechanics, q: np.ndarray) -> np.ndarray:
    """The q' of unit theta' satisfying both feet's constraints (null vector of J_c)."""
    Ja = mech.jac_a(q)
    rates = np.linalg.solve(Ja[:, 3:5], -Ja[:, 2])
    return np.array([0.0, 0.0, 1.0, rates[0], rates[1]])


def state_from_section(mech: Mechanics, z: np.ndarray) -> np.ndarray:
    """Full post-impact state y = [q, q'] (10,) from z = (theta+ rad, theta'+ rad/s)."""
    theta, theta_dot = float(z[0]), float(z[1])
    L0 = mech.params.leg_length_m
    q = np.array([0.0, 0.0, theta, L0, trailing_length(theta, L0)])
    qd = theta_dot * double_support_velocity(mech, q)
    return np.concatenate((q, qd))


def section_from_state(y: np.ndarray) -> np.ndarray:
    """z = (theta, theta') of a post-impact state."""
    return np.array([y[2], y[7]])
