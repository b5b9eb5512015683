"""Random plausible states of the wheel, for the simulator's mechanics tests."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np


def random_states(rng: np.random.Generator, n: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Plausible configurations: theta within a step, legs compressed by up to 3 cm, random rates (SI)."""
    for _ in range(n):
        q = np.array(
            [
                rng.uniform(-1, 1),
                rng.uniform(-0.01, 0.01),
                rng.uniform(-0.5, 0.5),
                rng.uniform(0.2, 0.237),
                rng.uniform(0.2, 0.24),
            ]
        )
        qd = rng.normal(size=5) * np.array([0.5, 0.5, 3.0, 0.5, 0.5])
        yield q, qd
