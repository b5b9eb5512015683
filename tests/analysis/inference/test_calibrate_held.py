"""The held parameters' uncertainty in the calibration: `held_response` (warm refits from the solution, the
residual sigmas kept) against whole calibrations from scratch with the held parameter moved by +-1 sd (their own
start, profile and sigmas: an independent computation of the same sensitivity)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.inference.calibrate import calibrate
from rimless.sim.model.params import WheelParams
from tests.support.analysis_sim_truth import sim_trial

SD_I = 0.0036  # kg m^2: the default 10 % of Table 1's inertia


@pytest.fixture(scope="module")
def trials():
    rng = np.random.default_rng(3)
    truth = WheelParams(damping_ns_per_m=11.0)
    return [sim_trial(truth, s, w, rng, name=f"sim_{s}deg_{w}") for s in (1.5, 2.0) for w in (1.9, 2.2)]


@pytest.mark.slow
def test_se_held_matches_refits_at_plus_minus_sd(trials):
    names = [t.meta.source_file for t in trials]
    res = calibrate(trials, names, ["c"], held=[("inertia_kg_m2", SD_I), ("gravity_m_s2", 0.0)])
    (c,) = res.params
    assert set(c.held_contributions) == {"inertia_kg_m2"}  # sd 0: nothing to carry
    assert c.se_held == pytest.approx(c.held_contributions["inertia_kg_m2"])
    refit = {
        s: calibrate(trials, names, ["c"], params=WheelParams(inertia_kg_m2=0.036 + s * SD_I)).params[0].value
        for s in (1.0, -1.0)
    }
    actual = abs(refit[1.0] - refit[-1.0]) / 2
    assert actual > c.se  # the held inertia matters at this precision
    assert c.se_held == pytest.approx(actual, rel=0.25)
    d = c.as_dict()
    assert d["se_with_held"] == pytest.approx(math.hypot(c.se, c.se_held))
    lo, hi = d["ci95_with_held"]
    assert lo < d["ci95"][0] and hi > d["ci95"][1]
    assert d["se"] == c.se and d["ci95"] == list(c.ci95)  # the data's interval keeps its meaning
