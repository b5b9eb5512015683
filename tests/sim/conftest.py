"""Shared, expensive fixtures of the simulator tests (computed once per session)."""

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
