"""A simulated leg for `rimless robot leg-test --fake`: the wheel held up, one leg hanging free, an operator's
hand, the leg's clutch, and the leg's free motion (spring, damper, Coulomb guide friction, gravity).

Coordinates: `x` is the leg's compression (m, positive into the leg, along the guide), 0 at the spring's free
length; gravity pulls the hanging foot out (force -m g), so the leg rests near x = -m g / k, anywhere in the
friction band |k x + m g| <= F_c. Times in seconds on the fake's clock (monotonic by default).

The story the fake plays: the leg rests; from `press_start_s` the hand compresses it by `compression_m`
(a half-cosine ramp over `press_s`, so the hand stops at the peak), then lets it come back as slowly; the leg
follows the hand until the clutch holds it. The clutch is read from its output (`clutch_engaged()`, the mock
pin): it holds the leg `engage_delay_s` after the pin goes on and lets go `release_delay_s` after it goes off
(an electromagnetic clutch is not instantaneous; the pin is seen when the fake is next read, at the read
rate). Once let go, the leg moves freely: m x'' = -k x - c x'
- F_c sign(x') - m g, with stiction (a leg at rest whose spring and gravity force is within F_c stays at rest),
integrated with a semi-implicit Euler step of `step_s` (10 us: under 0.3 % of the natural period's radian).

A `FakeLeg` is a trajectory for `FakeAdns3080` (a callable of time returning the compression); the sensor
fake adds counts, quantisation and noise. Pure Python: the firmware imports nothing heavy.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class FakeLegParams:
    """The simulated leg (SI). Defaults: the paper's k and c, the leg mass of Table 1 as the moving mass, a
    guide friction of 0.4 N, a 2 mm compression by hand (after the release: peak speed about 0.3 m/s, peak
    acceleration k x / m = 14.6 g, inside the ADNS-3080's rating of 1 m/s and 15 g)."""

    stiffness_n_per_m: float = 2700.0
    damping_n_s_per_m: float = 8.0
    friction_n: float = 0.4
    moving_mass_kg: float = 0.0378
    gravity_m_s2: float = 9.81
    compression_m: float = 0.002
    press_start_s: float = 0.3
    press_s: float = 0.25
    engage_delay_s: float = 0.003
    release_delay_s: float = 0.004
    step_s: float = 1e-5

    def validated(self) -> FakeLegParams:
        """Return self, or raise ValueError naming the field."""
        for name, value in asdict(self).items():
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"fake leg {name} must be a finite number, got {value!r}")
        for name in ("stiffness_n_per_m", "moving_mass_kg", "press_s", "step_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"fake leg {name} must be > 0, got {getattr(self, name)!r}")
        for name in (
            "damping_n_s_per_m",
            "friction_n",
            "gravity_m_s2",
            "compression_m",
            "press_start_s",
            "engage_delay_s",
            "release_delay_s",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"fake leg {name} must be >= 0, got {getattr(self, name)!r}")
        return self

    def to_json(self) -> dict[str, Any]:
        """The truth, as written into the leg-test log of a fake run."""
        return asdict(self)


class FakeLeg:
    """The leg's compression (m) at time `t` (s): call it with non-decreasing times.

    :param clutch_engaged: True while the clutch output is on (read at every call).
    :param t0_s: the fake's time zero (the hand's schedule counts from it).
    :param clutch_changed_s: the clock time (s) of the clutch output's last change, if known: the clutch then acts
        from the edge even when the fake is sampled late (a loaded machine).
    """

    HAND, HELD, FREE = "hand", "held", "free"

    def __init__(
        self,
        params: FakeLegParams,
        clutch_engaged: Callable[[], bool],
        *,
        t0_s: float | None = None,
        clock: Callable[[], float] = time.monotonic,
        clutch_changed_s: Callable[[], float | None] | None = None,
    ) -> None:
        self.p = params.validated()
        self.clutch_engaged = clutch_engaged
        self.clutch_changed_s = clutch_changed_s
        self.t0_s = clock() if t0_s is None else t0_s
        p = self.p
        self.rest_m = -p.moving_mass_kg * p.gravity_m_s2 / p.stiffness_n_per_m  # the middle of the friction band
        self.x = self.rest_m
        self.v = 0.0
        self.t = 0.0  # seconds since t0_s, how far the state has been advanced
        self.phase = self.HAND
        self._switch_at: float | None = None  # when the clutch's pending change takes effect (s since t0)
        self.held_at_s: float | None = None  # when the clutch took hold (s since t0)
        self.free_at_s: float | None = None  # when it let go

    # --- the hand ---------------------------------------------------------------------------------
    def hand_m(self, u: float) -> float:
        """Where the hand puts the leg at `u` s since t0 (m): rest, a half-cosine press, a half-cosine return."""
        p = self.p
        tau = u - p.press_start_s
        if tau <= 0 or tau >= 2 * p.press_s:
            return self.rest_m
        return self.rest_m + p.compression_m * 0.5 * (1.0 - math.cos(math.pi * tau / p.press_s))

    # --- the clutch and the free motion -----------------------------------------------------------
    def __call__(self, t_s: float) -> float:
        u = t_s - self.t0_s
        if u < self.t:
            return self.x  # time never runs backwards here
        engaged = bool(self.clutch_engaged())
        wants_hold = engaged and self.phase != self.HELD
        wants_free = not engaged and self.phase == self.HELD
        if (wants_hold or wants_free) and self._switch_at is None:
            edge = self._edge_s(u)
            self._switch_at = edge + (self.p.engage_delay_s if wants_hold else self.p.release_delay_s)
        elif not (wants_hold or wants_free):
            self._switch_at = None  # the output went back before the clutch acted
        if self._switch_at is not None and self._switch_at <= u:
            self._advance(self._switch_at)
            if wants_hold:
                self.phase, self.v, self.held_at_s = self.HELD, 0.0, self._switch_at
            else:
                self.phase, self.v, self.free_at_s = self.FREE, 0.0, self._switch_at
            self._switch_at = None
        self._advance(u)
        return self.x

    def _edge_s(self, u: float) -> float:
        """When the clutch output changed (s since t0): its recorded time when known (the coil acts on the pin's
        edge, not when this fake is next sampled), else `u`; never before the state already advanced."""
        changed = self.clutch_changed_s() if self.clutch_changed_s is not None else None
        if changed is None:
            return u
        return min(u, max(self.t, changed - self.t0_s))

    def _advance(self, u: float) -> None:
        """Advance the state from `self.t` to `u` (s since t0)."""
        if u <= self.t:
            return
        if self.phase == self.HAND:
            self.x = self.hand_m(u)
        elif self.phase == self.FREE:
            self._integrate(u)
        self.t = u

    def _integrate(self, u: float) -> None:
        p = self.p
        k, c, fc, m, g = p.stiffness_n_per_m, p.damping_n_s_per_m, p.friction_n, p.moving_mass_kg, p.gravity_m_s2
        x, v, t = self.x, self.v, self.t
        while t < u:
            dt = min(p.step_s, u - t)
            f = -k * x - m * g  # spring and gravity
            if v == 0.0:
                if abs(f) <= fc:  # stuck: it stays until something changes (nothing does here)
                    t = u
                    break
                a = (f - math.copysign(fc, f)) / m
            else:
                a = (f - c * v - math.copysign(fc, v)) / m
            v_new = v + a * dt
            if v != 0.0 and (v_new > 0.0) != (v > 0.0):
                v_new = 0.0  # the velocity reached zero in this step: stop there, stick or turn next step
            x += v_new * dt
            v = v_new
            t += dt
        self.x, self.v = x, v
