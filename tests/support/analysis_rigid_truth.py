"""An independent truth model for the critical-slope tests: a rigid rimless wheel rolling over its feet.

Written apart from rimless.sim and rimless.analysis: the stance is a pendulum integrated with scipy's
solve_ivp (world angle of the stance leg theta + phi), the impact keeps the angular momentum about the new
foot (omega+ = beta omega-), and the critical slope is Coleman's closed form, solved here by bisection.
Trials end at the end of a ramp of `ramp_steps` steps, or in a stall (the hub rocks back and comes to rest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
from scipy.integrate import solve_ivp

ALPHA = math.pi / 4
G = 9.81


@dataclass(frozen=True)
class RigidTruth:
    mass_kg: float = 2.0  # total mass, at the hub
    inertia_hub_kg_m2: float = 0.2  # about the hub
    leg_m: float = 0.237

    @property
    def inertia_foot(self) -> float:
        return self.inertia_hub_kg_m2 + self.mass_kg * self.leg_m**2

    @property
    def beta(self) -> float:
        ml2 = self.mass_kg * self.leg_m**2
        return (self.inertia_hub_kg_m2 + ml2 * math.cos(ALPHA)) / self.inertia_foot

    def critical_slope_deg(self) -> float:
        """Coleman: 1 - cos(phi) cos(alpha/2) - (1 + b^2)/(1 - b^2) sin(phi) sin(alpha/2) = 0, by bisection."""
        b2 = self.beta**2

        def g(phi: float) -> float:
            return 1 - math.cos(phi) * math.cos(ALPHA / 2) - (1 + b2) / (1 - b2) * math.sin(phi) * math.sin(ALPHA / 2)

        lo, hi = 1e-9, ALPHA / 2 - 1e-9
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if g(mid) > 0:
                lo = mid
            else:
                hi = mid
        return math.degrees(0.5 * (lo + hi))

    def wheel_params(self):
        """WheelParams describing this wheel for rimless (tiny legs: M = m_H + 8 m, I_hub = I_c + 8 m L^2)."""
        from rimless.sim.model.params import WheelParams

        m = 1e-4
        return WheelParams(
            hub_mass_kg=self.mass_kg - 8 * m,
            leg_mass_kg=m,
            inertia_kg_m2=self.inertia_hub_kg_m2 - 8 * m * self.leg_m**2,
            leg_length_m=self.leg_m,
        )

    def walk(self, slope_deg: float, omega0: float, ramp_steps: int = 11, dt: float = 0.002):
        """Release at theta = -alpha/2 with theta' = omega0; returns (t, hub_x, hub_y, angle, impacts, stalled).

        hub_x along the slope, hub_y normal to it (slope frame), angle the wheel's turn since the release.
        """
        phi = math.radians(slope_deg)
        k = self.mass_kg * G * self.leg_m / self.inertia_foot

        def rhs(_t, y):
            return [y[1], k * math.sin(y[0] + phi)]

        def touchdown(_t, y):
            return y[0] - ALPHA / 2

        touchdown.terminal, touchdown.direction = True, 1

        def rollback(_t, y):
            return y[1]

        rollback.terminal, rollback.direction = True, -1

        t0, w, foot_x, turned = 0.0, omega0, 0.0, 0.0
        ts, xs, ys, angs, impacts = [], [], [], [], []
        stalled = False
        for _step in range(ramp_steps):
            sol = solve_ivp(
                rhs,
                (0, 20.0),
                [-ALPHA / 2, w],
                events=(touchdown, rollback),
                rtol=1e-11,
                atol=1e-12,
                dense_output=True,
                max_step=0.01,
            )
            t_end = sol.t[-1]
            tt = np.arange(0.0, t_end, dt)
            th = sol.sol(tt)[0]
            ts.append(t0 + tt)
            xs.append(foot_x + self.leg_m * np.sin(th))
            ys.append(self.leg_m * np.cos(th))
            angs.append(turned + th + ALPHA / 2)
            if sol.t_events[1].size:  # rolls back: rocks on the rear leg and comes to rest (damped)
                stalled = True
                t_back = np.arange(0.0, 1.5, dt)
                amp = abs(th.max() + ALPHA / 2)
                thb = -ALPHA / 2 + amp * np.exp(-3 * t_back) * np.abs(np.cos(4 * t_back + math.acos(1.0)))
                ts.append(t0 + t_end + t_back)
                xs.append(foot_x + self.leg_m * np.sin(thb))
                ys.append(self.leg_m * np.cos(thb))
                angs.append(turned + thb + ALPHA / 2)
                break
            w = self.beta * sol.y[1, -1]
            t0 += t_end
            impacts.append(t0)
            foot_x += 2 * self.leg_m * math.sin(ALPHA / 2)
            turned += ALPHA
        if not stalled:  # ramp ends: the wheel is caught half a step later (recording stops)
            sol = solve_ivp(
                rhs,
                (0, 20.0),
                [-ALPHA / 2, w],
                events=(touchdown, rollback),
                rtol=1e-11,
                atol=1e-12,
                dense_output=True,
                max_step=0.01,
            )
            tt = np.arange(0.0, 0.5 * sol.t[-1], dt)
            th = sol.sol(tt)[0]
            ts.append(t0 + tt)
            xs.append(foot_x + self.leg_m * np.sin(th))
            ys.append(self.leg_m * np.cos(th))
            angs.append(turned + th + ALPHA / 2)
        return (
            np.concatenate(ts),
            np.concatenate(xs),
            np.concatenate(ys),
            np.concatenate(angs),
            np.array(impacts),
            stalled,
        )


@dataclass
class DuckTrial:
    """The public fields of an imported trial, built straight from the truth (impact times with noise)."""

    time_s: np.ndarray
    impact_time_s: np.ndarray
    step_period_s: np.ndarray
    meta: SimpleNamespace
    series: dict = field(default_factory=dict)


def duck_trial(
    truth: RigidTruth,
    slope_deg: float,
    omega0: float,
    rng: np.random.Generator,
    *,
    name: str,
    ramp_steps: int = 11,
    timing_noise_s: float = 1e-3,
    rate_hz: float = 100.0,
) -> DuckTrial:
    t, x, y, _ang, imp, stalled = truth.walk(slope_deg, omega0, ramp_steps)
    # the first impact seen is the release's end: the recording starts after the hand lets go
    imp = imp + rng.normal(0.0, timing_noise_s, imp.size)
    meta = SimpleNamespace(
        slope_deg=slope_deg + rng.normal(0.0, 0.01),
        source_file=name,
        rate_hz=rate_hz,
        outcome="stalled" if stalled else "walked",
        slope_source="given",
    )
    return DuckTrial(time_s=t, impact_time_s=imp, step_period_s=np.diff(imp), meta=meta, series={"com_height": y})
