"""Scripted walks for the fake sensor, with their truth: which leg is on the ground at every instant.

A `FakeWalk` is the compression displacement (m) the stance-leg mechanism shows on the fake's clock (s):
one pulse per step, `compression_m * sin(pi * tau / (2 * compression_s))` for tau in [0, 2 compression_s]
after each touchdown, touchdowns every `step_period_s` from `start_s`. Its variations are the fault
scenarios of `rimless robot run --fake --fake-fault`: a first step too gentle for the touchdown test
(`first_compression_m`), and a bounce of the foot of step `bounce_step` (`bounce_after_s` after its touchdown:
the same foot lifts and comes down again; a bounce is not a step). The truth (`steps_before`, `stance_leg`) is written from this
description alone, independently of the detector, so a lock can be judged against it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class FakeWalk:
    """A walk of touchdowns every `step_period_s` from `start_s` (s, on the fake's clock)."""

    start_s: float
    step_period_s: float = 0.4
    compression_m: float = 0.008
    compression_s: float = 0.06
    first_compression_m: float | None = None  # the first step's compression (None: as the others)
    bounce_after_s: float | None = None  # step `bounce_step`'s foot comes down again this long after its touchdown
    bounce_compression_m: float = 0.004
    bounce_compression_s: float = 0.04
    bounce_step: int = 0  # which step's foot bounces (0: the first)

    def touchdown_s(self, k: int) -> float:
        """True time of the k-th step's touchdown (s)."""
        return self.start_s + k * self.step_period_s

    def steps_before(self, t: float) -> int:
        """Number of true touchdowns (steps; a bounce is none) at or before `t`."""
        if t < self.start_s:
            return 0
        return int((t - self.start_s) // self.step_period_s) + 1

    def stance_leg(self, t: float, legs: Sequence[int], start_index: int) -> int:
        """The clutch index of the leg on the ground at `t`: `legs[start_index]` before the first touchdown,
        the next leg of `legs` after each one."""
        return legs[(start_index + self.steps_before(t)) % len(legs)]

    def __call__(self, t: float) -> float:
        u = t - self.start_s
        if u < 0:
            return 0.0
        k = int(u // self.step_period_s)
        tau = u - k * self.step_period_s
        x = 0.0
        if tau < 2 * self.compression_s:
            amp = self.first_compression_m if (k == 0 and self.first_compression_m is not None) else self.compression_m
            x += amp * math.sin(math.pi * tau / (2 * self.compression_s))
        if self.bounce_after_s is not None:
            b = t - self.touchdown_s(self.bounce_step) - self.bounce_after_s
            if 0.0 <= b < 2 * self.bounce_compression_s:
                x += self.bounce_compression_m * math.sin(math.pi * b / (2 * self.bounce_compression_s))
        return x


def airborne_locks(
    walk: FakeWalk, engages: Sequence[tuple[float, int]], legs: Sequence[int], start_index: int
) -> list[tuple[float, int, int]]:
    """The engages `(t_s, leg)` that locked a leg not on the ground by the truth: `(t_s, leg, stance_leg)`."""
    out = []
    for t, leg in engages:
        stance = walk.stance_leg(t, legs, start_index)
        if leg != stance:
            out.append((t, leg, stance))
    return out
