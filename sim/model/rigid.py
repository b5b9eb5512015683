"""The rigid rimless wheel in closed form (Coleman 2010; paper eq. for g(phi), model.md section 7).

Mass conventions: `paper` uses M = m_H and inertia I_c (reproduces the paper's 2.80 deg); `eight-leg`
is the rigid wheel consistent with the eight-leg mass model: M = m_H + 8 m, inertia I_c + 8 m L0^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rimless.sim.model.params import SPOKE_ANGLE_RAD, WheelParams

ALPHA = SPOKE_ANGLE_RAD


@dataclass(frozen=True)
class RigidWheel:
    """Mass M (kg) and inertia I (kg m^2) about the hub of a rigid wheel of leg length L (m)."""

    mass_kg: float
    inertia_kg_m2: float
    leg_length_m: float
    gravity_m_s2: float
    convention: str

    @classmethod
    def from_params(cls, p: WheelParams, convention: str = "paper") -> RigidWheel:
        if convention == "paper":
            return cls(p.hub_mass_kg, p.inertia_kg_m2, p.leg_length_m, p.gravity_m_s2, "paper")
        if convention == "eight-leg":
            m8 = 8 * p.leg_mass_kg
            return cls(
                p.hub_mass_kg + m8,
                p.inertia_kg_m2 + m8 * p.leg_length_m**2,
                p.leg_length_m,
                p.gravity_m_s2,
                "eight-leg",
            )
        raise ValueError(f"unknown rigid-wheel convention {convention!r}")

    @property
    def beta(self) -> float:
        """Angular-velocity ratio across an impact, omega+ / omega-."""
        ml2 = self.mass_kg * self.leg_length_m**2
        return (self.inertia_kg_m2 + ml2 * math.cos(ALPHA)) / (self.inertia_kg_m2 + ml2)

    def coleman_g(self, slope_rad: float) -> float:
        """Coleman's g(phi): zero at the critical slope."""
        b2 = self.beta**2
        return (
            1
            - math.cos(slope_rad) * math.cos(ALPHA / 2)
            - (1 + b2) / (1 - b2) * math.sin(slope_rad) * math.sin(ALPHA / 2)
        )

    def critical_slope_rad(self) -> float:
        """Root of g(phi) on (0, alpha/2)."""
        from scipy.optimize import brentq

        return float(brentq(self.coleman_g, 1e-9, ALPHA / 2 - 1e-9, xtol=1e-15, rtol=1e-15))

    def _gain(self, slope_rad: float) -> float:
        """omega-^2 - omega+^2 over one step, rad^2/s^2."""
        ml = self.mass_kg * self.leg_length_m
        return (
            4
            * ml
            * self.gravity_m_s2
            * math.sin(slope_rad)
            * math.sin(ALPHA / 2)
            / (self.inertia_kg_m2 + ml * self.leg_length_m)
        )

    def step_map(self, omega_plus: float, slope_rad: float) -> float:
        """Next post-impact angular velocity (rad/s), or nan when the wheel cannot pass mid-stance."""
        if omega_plus**2 < self.barrier(slope_rad):
            return float("nan")
        return self.beta * math.sqrt(omega_plus**2 + self._gain(slope_rad))

    def barrier(self, slope_rad: float) -> float:
        """Smallest omega+^2 that carries the hub over the top (theta = -phi), rad^2/s^2."""
        ml = self.mass_kg * self.leg_length_m
        return (
            2
            * ml
            * self.gravity_m_s2
            * (1 - math.cos(ALPHA / 2 - slope_rad))
            / (self.inertia_kg_m2 + ml * self.leg_length_m)
        )

    def fixed_point_omega(self, slope_rad: float) -> float:
        """Post-impact angular velocity of the period-1 gait, rad/s."""
        b2 = self.beta**2
        return math.sqrt(b2 * self._gain(slope_rad) / (1 - b2))

    def eigenvalue(self) -> float:
        """Linearised step-to-step map d omega_{k+1} / d omega_k at the fixed point: beta^2."""
        return self.beta**2

    def step_period_s(self, slope_rad: float) -> float:
        """Time from theta = -alpha/2 to alpha/2 at the fixed point, s (quadrature of d theta / omega)."""
        from scipy.integrate import quad

        w0 = self.fixed_point_omega(slope_rad)
        ml = self.mass_kg * self.leg_length_m
        inertia = self.inertia_kg_m2 + ml * self.leg_length_m
        k = 2 * ml * self.gravity_m_s2 / inertia

        def inv_omega(th: float) -> float:
            return 1.0 / math.sqrt(w0**2 + k * (math.cos(slope_rad - ALPHA / 2) - math.cos(th + slope_rad)))

        val, _ = quad(inv_omega, -ALPHA / 2, ALPHA / 2, epsabs=1e-13, epsrel=1e-12)
        return val


def rigid_fixed_point_omega(p: WheelParams, consistent: bool = False) -> float:
    wheel = RigidWheel.from_params(p, "eight-leg" if consistent else "paper")
    return wheel.fixed_point_omega(p.slope_rad) if p.slope_rad > 0 else float("nan")
