"""A held parameter at its physical bound (issue 31, "What is held, is carried"): F_c >= 0 held at Table 1's
0 +- 0.2 N can only be above the held value, so the fitted values it moves are carried by the moments of the
stated normal truncated at 0 (`rimless.analysis.inference.held.truncated_moments`, `carry_bounded`) and the
interval with the held parameters is re-centred by their mean shift (`held_response`, ``value_with_held``).

Checked against closed forms (the half-normal's mean sd sqrt(2/pi) and sd sqrt(1 - 2/pi)), against sampling
the truncated normal (numpy, independent of the closed form), and through `held_response` on a least squares
whose fitted value is exactly linear in the held parameters (its refits are then exact: the shift and the part
are the closed forms)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rimless.analysis.inference.calibrate import ParamEstimate, held_response
from rimless.analysis.inference.held import carry_bounded, truncated_moments
from rimless.sim.model.params import WheelParams


def test_at_the_bound_the_moments_are_the_half_normals() -> None:
    m, s = truncated_moments(0.0, 0.2)
    assert m == pytest.approx(math.sqrt(2.0 / math.pi), rel=1e-12)
    assert s == pytest.approx(math.sqrt(1.0 - 2.0 / math.pi), rel=1e-12)


def test_far_from_the_bound_the_normal_is_untouched() -> None:
    m, s = truncated_moments(1.892, 0.02 * 1.892)  # m_H +- 2 %: 50 sd from 0
    assert m == 0.0 and s == 1.0


@pytest.mark.parametrize("value", [0.0, 0.1, 0.3])
def test_moments_match_sampling_the_truncated_normal(value: float) -> None:
    sd = 0.2
    rng = np.random.default_rng(11)
    x = rng.normal(value, sd, 400_000)
    x = x[x >= 0.0]
    m, s = truncated_moments(value, sd)
    assert (x.mean() - value) / sd == pytest.approx(m, abs=4 * x.std() / sd / math.sqrt(x.size))
    assert x.std() / sd == pytest.approx(s, rel=0.01)


def test_carry_bounded_is_exact_for_a_linear_response() -> None:
    """y = 3 - 5 F with F ~ N(0.1, 0.2) truncated at 0: the mean shift of y from y(0.1) and its sd from the change
    at +1 sd equal sampling's (-1 sd = -0.1 N is no wheel)."""
    rng = np.random.default_rng(5)
    f = rng.normal(0.1, 0.2, 400_000)
    y = 3.0 - 5.0 * f[f >= 0.0]
    shift, part, how = carry_bounded(0.1, 0.2, np.array([-5.0 * 0.2]), None)
    assert 3.0 - 5.0 * 0.1 + shift[0] == pytest.approx(y.mean(), abs=4 * y.std() / math.sqrt(y.size))
    assert part[0] == pytest.approx(y.std(), rel=0.01)
    assert "truncated at its bound 0" in how and "one refit at +1 sd" in how


def test_carry_bounded_far_from_the_bound_is_the_central_half_difference() -> None:
    shift, part, how = carry_bounded(0.237, 0.001, np.array([0.02, -0.5]), np.array([-0.04, 0.3]))
    assert list(shift) == [0.0, 0.0]
    assert part == pytest.approx([0.03, 0.4])
    assert how.startswith("normal 0.237 +- 0.001: central refits")


class _LinearFit:
    """A least squares whose solution is c = 8 - 5 F_c + 10 (L0 - 0.237) at the held wheel `glob.base` (exact
    refits: the interface of `calibrate._Objective` that `held_response` uses)."""

    def __init__(self) -> None:
        self.glob = SimpleNamespace(base=WheelParams(), fields=["damping_ns_per_m"])

    def solution(self) -> float:
        b = self.glob.base
        return 8.0 - 5.0 * b.guide_friction_n + 10.0 * (b.leg_length_m - 0.237)

    def unpack(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.asarray(u[:1], float), np.zeros(0), np.zeros(0)

    def cost(self, u: np.ndarray) -> float:
        return float((u[0] - self.solution()) ** 2)

    def solve(self, u: np.ndarray, lo: np.ndarray, hi: np.ndarray, max_rounds: int) -> SimpleNamespace:
        return SimpleNamespace(x=np.array([self.solution()]), cost=0.0)


def test_held_response_recentres_on_the_bounded_parameters_mean_shift() -> None:
    """F_c held at 0 +- 0.2 N (Table 1's default) and L0 +- 1 mm: c's expected shift is -5 E[F_c] = -5 (0.2
    sqrt(2/pi)), its part from F_c 5 (0.2 sqrt(1 - 2/pi)), from L0 10 (0.001), no shift; the interval with the
    held parameters is centred on value + shift (before: 8 +- 1.96 hypot(se, 1.0), half of it below any truth)."""
    obj = _LinearFit()
    u = np.array([obj.solution()])
    est = [ParamEstimate("c", "damping_ns_per_m", "N s/m", 8.0, float(u[0]), 0.05, True)]
    held_response(obj, u, (np.array([-1e9]), np.array([1e9])), [("guide_friction_n", 0.2), ("leg_length_m", 1e-3)], est)  # type: ignore[arg-type]
    (c,) = est
    assert obj.glob.base == WheelParams()  # the held wheel is restored
    assert c.held_shifts == {"guide_friction_n": pytest.approx(-5.0 * 0.2 * math.sqrt(2.0 / math.pi))}
    assert c.held_shift == c.held_shifts["guide_friction_n"]
    assert c.held_contributions["guide_friction_n"] == pytest.approx(5.0 * 0.2 * math.sqrt(1.0 - 2.0 / math.pi))
    assert c.held_contributions["leg_length_m"] == pytest.approx(10.0 * 1e-3)
    assert c.se_held == pytest.approx(math.hypot(*c.held_contributions.values()))
    d = c.as_dict()
    centre = 8.0 - 5.0 * 0.2 * math.sqrt(2.0 / math.pi)
    half = 1.959963984540054 * math.hypot(0.05, c.se_held)
    assert d["value"] == 8.0 and d["value_with_held"] == pytest.approx(centre)
    assert d["ci95_with_held"] == pytest.approx([centre - half, centre + half])
    assert d["ci95"] == pytest.approx([8.0 - 1.959963984540054 * 0.05, 8.0 + 1.959963984540054 * 0.05])
    assert "truncated at its bound 0" in d["held_carried_as"]["guide_friction_n"]
    assert "central refits" in d["held_carried_as"]["leg_length_m"]
