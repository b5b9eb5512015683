"""The held-exact probe's one-sided reach (issue 31, "A model that does not fit makes its parameters effective
only, never identifiable"): when the freed friction comes out above its held 0, a fitted parameter depends on the
held value if it moves by more than 1 se at the freed fit or at 1 se of friction above it
(`rimless.analysis.inference.calibrate._reach_one_sided`). It caught the friction-misfit series (truth 0.40 N)
whose freed fit stopped at 0.13 N, moving c by 0.7 se only (docs/trials.md).

Hand-computed case: c held-fit value 10 +- 0.5 N s/m; the freed fit c = 9.65 (-0.7 se), F_c = 0.13 N with carried
se 0.2 N; the freed fit's model covariance has corr(c, F_c) = -0.9, se_model 0.3 and 0.15, so c's regression
slope on F_c is -0.9 * 0.3 / 0.15 = -1.8 N s/m per N, and at F_c = 0.33 N c is 9.65 - 0.36 = 9.29: (9.29 - 10) /
0.5 = -1.42 se."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.analysis.inference.calibrate import ParamEstimate, _reach_one_sided


def _c(value: float = 10.0, se: float = 0.5) -> ParamEstimate:
    return ParamEstimate("c", "damping_ns_per_m", "N s/m", 5.0, value, se, True)


CORR = np.array([[1.0, -0.9], [-0.9, 1.0]])
SE_M = np.array([0.3, 0.15])


def test_the_reach_is_the_hand_computed_one() -> None:
    reach = _reach_one_sided(np.array([9.65, 0.13]), SE_M, CORR, [0.35, 0.2], 0.0, True, [_c()])
    assert reach["c"] == pytest.approx((9.65 - 1.8 * 0.2 - 10.0) / 0.5, rel=1e-12)
    assert reach["c"] == pytest.approx(-1.42, rel=1e-12)


@pytest.mark.parametrize(
    ("xg", "converged", "why"),
    [
        ([10.0, 0.0], True, "freed fit at the held value (the bound): the trials lean nowhere"),
        ([9.65, 0.13], False, "freed fit stopped on its budget: its value is no result"),
    ],
)
def test_no_reach_unless_the_freed_fit_converged_above_the_held_value(xg: list, converged: bool, why: str) -> None:
    assert _reach_one_sided(np.array(xg), SE_M, CORR, [0.35, 0.2], 0.0, converged, [_c()]) == {}, why


def test_an_unknown_se_gives_no_reach_rather_than_nan() -> None:
    reach = _reach_one_sided(np.array([9.65, 0.13]), SE_M, CORR, [0.35, 0.2], 0.0, True, [_c(se=float("inf"))])
    assert reach == {"c": None}
