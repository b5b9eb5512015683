"""Truth model: a mass on a spring with Coulomb friction (no damper), solved piecewise in closed form.

m x'' + k x = -F_c sign(x') with x(0) = x0, x'(0) = 0. Each half-cycle is a harmonic oscillation of angular
frequency w = sqrt(k/m) about the offset +F_c/k (moving down) or -F_c/k (moving up); every half-cycle the
amplitude drops by 2 F_c / k (4 F_c / k per cycle); the mass sticks for good at the first turning point with
|x| <= F_c / k. Written apart from the simulator (no import of rimless).
"""

from __future__ import annotations

import math

import numpy as np


def turning_points(x0: float, k: float, F: float) -> list[float]:
    """The successive turning points x_0, x_1, ... (m) up to the one where the mass sticks."""
    xs = [x0]
    d = F / k
    while abs(xs[-1]) > d:
        x = xs[-1]
        centre = d if x > 0 else -d  # moving towards the origin, friction pushes back
        xs.append(2.0 * centre - x)
    return xs


def position(t: np.ndarray, x0: float, k: float, m: float, F: float) -> np.ndarray:
    """x(t) (m) of the oscillator released at rest from x0 at t = 0."""
    w = math.sqrt(k / m)
    half = math.pi / w
    xs = turning_points(x0, k, F)
    out = np.empty_like(np.asarray(t, dtype=float))
    for i, ti in enumerate(np.asarray(t, dtype=float)):
        n = int(ti // half)
        if n >= len(xs) - 1:
            out[i] = xs[-1]
            continue
        x = xs[n]
        centre = F / k if x > 0 else -F / k
        out[i] = centre + (x - centre) * math.cos(w * (ti - n * half))
    return out
