"""The model choice's detection limit (`model_choice.detectable_above`, issue 31): the smallest extra parameter the
quasi-likelihood test finds with 80 % power, against closed forms and a simulation of the test written here."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm, t

from rimless.analysis.inference.model_choice import MODEL_CHOICE_P, choice_row, detectable_above, dispersion


def test_the_limit_against_the_normal_closed_forms():
    """chi^2_1 (dof None), phi 1: two-sided the power at delta is Phi(d - z) + Phi(-d - z) with z the normal
    quantile of p/2; on the bound (p halved, an estimate below the held value counts as 0) it is Phi(d - z1),
    z1 that of p: d = z1 + z_0.8 = 2.326 + 0.842. A dispersion phi scales the limit by sqrt(phi), se_model
    linearly."""
    d2 = detectable_above(1.0, 1.0, None, False)
    z = norm.isf(MODEL_CHOICE_P / 2)
    assert norm.cdf(d2 - z) + norm.cdf(-d2 - z) == pytest.approx(0.8, abs=1e-9)
    d1 = detectable_above(1.0, 1.0, None, True)
    assert d1 == pytest.approx(norm.isf(MODEL_CHOICE_P) + norm.isf(0.2), rel=1e-3)  # the far tail: < 1e-6
    assert detectable_above(0.05, 9.0, None, True) == pytest.approx(0.05 * 3.0 * d1, rel=1e-9)
    assert math.isnan(detectable_above(math.inf, 1.0, None, True))


def test_the_limit_with_an_estimated_dispersion_against_a_simulation():
    """dof 3 (the trial-clustered sandwich of four trials): the statistic is a squared noncentral t; simulated
    here (t's numerator normal at d / se, its denominator sqrt(chi^2_3 / 3)), the test on the bound finds the
    parameter at the stated limit in 80 % of draws (within the simulation's 1.3 % sd)."""
    rng = np.random.default_rng(7)
    d = detectable_above(1.0, 1.0, 3, True)
    n = 20000
    tt = (d + rng.normal(size=n)) / np.sqrt(rng.chisquare(3, n) / 3)
    found = np.mean(tt > t.isf(MODEL_CHOICE_P, 3))  # one-sided: p halved on the bound
    assert found == pytest.approx(0.8, abs=0.012)


def test_a_not_supported_statement_names_the_limit():
    """Hand-computed: se_model 0.05 N with the slopes' part 0.1 (phi 5), on the bound: the limit is
    0.05 sqrt(5) (2.326 + 0.842) = 0.354 N, named in the statement and the row."""
    row = choice_row("guide_friction_n", ["c"], 0.0, 100.0, 101.0, True, {"c": 11.0}, dispersion(0.05, 0.1))
    assert not row["supported"]
    assert row["detectable_above"] == pytest.approx(0.05 * math.sqrt(5) * 3.1680, rel=1e-3)
    assert "would find guide_friction_n only above 0 + 0.354" in row["statement"]
