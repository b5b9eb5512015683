"""Touchdown: leg relabelling and the perfectly inelastic impact (model.md section 5)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rimless.sim.model.mechanics import ALPHA, Mechanics


def relabel(q: np.ndarray, qd: np.ndarray, leg_length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The paper's leg exchange: the swing foot becomes stance foot b (L = L0, L' = 0), the old stance
    leg becomes the trailing leg with its length and rate; the old trailing leg joins the rigid set."""
    x, y, th, L1, _ = q
    dx, dy, dth, dL1, _ = qd
    L0 = leg_length_m
    q_new = np.array(
        [
            x + L1 * math.sin(th) + L0 * math.sin(ALPHA - th),
            y + L1 * math.cos(th) - L0 * math.cos(ALPHA - th),
            th - ALPHA,
            L0,
            L1,
        ]
    )
    qd_new = np.array(
        [
            dx + (L1 * math.cos(th) - L0 * math.cos(ALPHA - th)) * dth + dL1 * math.sin(th),
            dy - (L1 * math.sin(th) + L0 * math.sin(ALPHA - th)) * dth + dL1 * math.cos(th),
            dth,
            0.0,
            dL1,
        ]
    )
    return q_new, qd_new


def double_support_jacobian(mech: Mechanics, q: np.ndarray) -> np.ndarray:
    """J_c (4x5): rows x_b, y_b, then foot a's position Jacobian (the paper's J33, J35, J43, J45)."""
    Jc = np.zeros((4, 5))
    Jc[0, 0] = 1.0
    Jc[1, 1] = 1.0
    Jc[2:4] = mech.jac_a(q)
    return Jc


@dataclass(frozen=True)
class ImpactResult:
    """Post-impact state and the impact's diagnostics (impulses in N s, energies in J)."""

    q_plus: np.ndarray
    qd_plus: np.ndarray
    impulse: np.ndarray  # (b_x, b_y, a_x, a_y), N s, ground on foot
    kinetic_minus: float  # T(q-, q'-) in the pre-impact labels
    kinetic_relabelled: float  # T(q~, q~') after relabelling, before the impulse
    kinetic_plus: float  # T(q~, q'+)
    relabel_loss: float  # E(q-, q'-) - E(q~, q~'): energy removed by snapping the old trailing leg to L0, J

    @property
    def relabel_snap_J(self) -> float:
        """Energy the relabelling adds by snapping the old trailing leg to L0 with zero rate, J (= -relabel_loss;
        > 0 adds energy, < 0 removes it)."""
        return -self.relabel_loss

    @property
    def energy_ratio(self) -> float:
        """E+/E- with E- in the pre-impact labels (model.md section 6)."""
        return self.kinetic_plus / self.kinetic_minus

    @property
    def energy_ratio_relabelled(self) -> float:
        """E+/E- with E- taken after relabelling."""
        return self.kinetic_plus / self.kinetic_relabelled

    @property
    def friction_required(self) -> tuple[float, float]:
        """|tangential| / normal impulse at feet b and a: the friction coefficient the impact needs."""
        return (abs(self.impulse[0]) / self.impulse[1], abs(self.impulse[2]) / self.impulse[3])


def impact_projection(mech: Mechanics, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, G): q'+ = P q'~ and the impulse Lambda = G q'~ at the relabelled configuration q."""
    M = mech.mass_matrix(q)
    Jc = double_support_jacobian(mech, q)
    Minv_JT = np.linalg.solve(M, Jc.T)
    S = Jc @ Minv_JT
    G = -np.linalg.solve(S, Jc)
    P = np.eye(5) + Minv_JT @ G
    return P, G


def impact(mech: Mechanics, q_minus: np.ndarray, qd_minus: np.ndarray) -> ImpactResult:
    """Relabel, then apply the inelastic double-support impact."""
    L0 = mech.params.leg_length_m
    q_t, qd_t = relabel(q_minus, qd_minus, L0)
    P, G = impact_projection(mech, q_t)
    qd_plus = P @ qd_t
    impulse = G @ qd_t
    return ImpactResult(
        q_plus=q_t,
        qd_plus=qd_plus,
        impulse=impulse,
        kinetic_minus=mech.kinetic(q_minus, qd_minus),
        kinetic_relabelled=mech.kinetic(q_t, qd_t),
        kinetic_plus=mech.kinetic(q_t, qd_plus),
        relabel_loss=mech.energy(q_minus, qd_minus) - mech.energy(q_t, qd_t),
    )
