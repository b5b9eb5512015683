"""Shared, expensive fixtures of the simulator tests (computed once per session)."""

import numpy as np
import pytest

from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.params import WheelParams
from rimless.sim.step.poincare import PoincareMap, default_guess, solve_fixed_point

TIGHT = ScipyIntegrator(rtol=1e-12, atol=1e-13)


@pytest.fixture(scope="session")
def table1() -> WheelParams:
    return WheelParams()


@pytest.fixture(scope="session")
def er_fixed_point(table1):
    pmap = PoincareMap(table1, "er", TIGHT)
    return pmap, solve_fixed_point(pmap, default_guess(table1, "er"), diagnostics=True)


@pytest.fixture(scope="session")
def ve_fixed_point(table1):
    pmap = PoincareMap(table1, "ve", TIGHT)
    return pmap, solve_fixed_point(pmap, default_guess(table1, "ve"), diagnostics=True)


def random_states(rng: np.random.Generator, n: int):
    """Plausible configurations: theta within a step, legs compressed by up to 3 cm, random rates."""
    for _ in range(n):
        q = np.array([rng.uniform(-1, 1), rng.uniform(-0.01, 0.01), rng.uniform(-0.5, 0.5),
                      rng.uniform(0.2, 0.237), rng.uniform(0.2, 0.24)])
        qd = rng.normal(size=5) * np.array([0.5, 0.5, 3.0, 0.5, 0.5])
        yield q, qd
