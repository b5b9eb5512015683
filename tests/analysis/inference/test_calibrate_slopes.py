"""The trials' measured slopes are carried into the calibration's intervals (`rimless.analysis.inference.trial_slopes`).

Truth: the simulator's ER wheel walked by `floquet_truth.er_walk` (c = 19.3 N s/m, k = 3450 N/m, away from
Table 1's 8 and 2700), written as Vicon exports (`critical_truth.record`) and imported. Each trial is then given
its true slope, except the first, given one of its stated standard deviations too steep: a slope the importer's
own interval allows (it is 0.01-0.02 deg; the importer's slopes were off by 0.009 deg rms on the calibration
coverage study's 160 trials). Without the slopes' part, c's interval missed the truth by 2.2-2.7 of its
standard errors (seeds 1-3; c absorbs the energy the steeper slope adds).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rimless.analysis.inference.calibrate import calibrate
from rimless.analysis.inference.sustained import trial_slope_sigma_deg
from rimless.analysis.inference.trial_slopes import slope_response
from rimless.analysis.kinematics.build import import_trial
from rimless.analysis.validation.critical_truth import record
from rimless.analysis.validation.floquet_truth import er_walk
from rimless.analysis.validation.importer_coverage import Lab
from rimless.sim.model.params import WheelParams

TRUTH = WheelParams(stiffness_n_per_m=3450.0, damping_ns_per_m=19.3)
SLOPES_DEG = (2.2, 2.8, 3.4)


def _trials(tmp_path, seed: int, sd_off: float) -> list:
    rng = np.random.default_rng(seed)
    lab = Lab(up="z", heading_deg=30.0, markers=False)
    out = []
    for j, slope in enumerate(SLOPES_DEG):
        wk = er_walk(TRUTH, slope, 0.0, 10, rng, release=1.03)
        tr = import_trial(record(wk, tmp_path / f"t{j}.csv", rng, lab, rest_s=0.0))
        sd = trial_slope_sigma_deg(tr.meta)[0]
        meas = slope + (sd_off * sd if j == 0 else 0.0)
        out.append(dataclasses.replace(tr, meta=dataclasses.replace(tr.meta, slope_deg=meas)))
    return out


@pytest.mark.parametrize("seed", [1, 2])
def test_c_interval_holds_the_truth_when_a_slope_is_off_by_its_stated_sd(tmp_path, seed: int) -> None:
    trials = _trials(tmp_path, seed, 1.0)
    res = calibrate(trials, ["t0", "t1", "t2"], ("c",), params=TRUTH)
    (c,) = res.params
    lo, hi = c.ci95
    assert lo <= TRUTH.damping_ns_per_m <= hi, (c.value, c.se, c.se_slope)
    # the slope's part is what holds it: the data's own errors (model, sandwich over trials) would not
    old = max(c.se_model, c.se_sandwich)
    assert abs(c.value - TRUTH.damping_ns_per_m) > 1.96 * old
    assert c.se_slope > old and c.se >= math.hypot(c.se_model, c.se_slope) - 1e-12
    assert c.slope_contributions["t0"] == max(c.slope_contributions.values())  # the first trial's slope moved c most
    d = c.as_dict()
    assert d["se_slope"] == c.se_slope and set(d["slope_contributions"]) == {"t0", "t1", "t2"}
    # the value moved by about one t0 part: 1.3 and 1.5 of it on seeds 1 and 2 (the noise's own error and
    # what the linear response leaves out: it read 81-87 % of whole recalibrations at +-0.5-1.5 sd on seed 1)
    shift = c.value - TRUTH.damping_ns_per_m
    assert 0.7 < shift / c.slope_contributions["t0"] < 1.8


def test_slope_response_is_the_linear_least_squares_response() -> None:
    """A linear model y = a x + b_i (per-trial offsets) + s_i z: the slope s_i held at 0 with sd sigma_i; the
    exact response of a to s_i is -(x_i . z_i') / |x'|^2 over the centred columns, in closed form."""
    rng = np.random.default_rng(3)
    n, nt = 20, 3
    x = rng.normal(size=(nt, n))
    z = rng.normal(size=(nt, n))
    sig = [0.5, 0.0, 2.0]
    offs = np.arange(0, nt * n + 1, n)
    J = np.zeros((nt * n, 1 + nt))
    J[:, 0] = x.ravel()
    for i in range(nt):
        J[offs[i] : offs[i + 1], 1 + i] = 1.0
    se, parts = slope_response(J, 1, np.ones(1 + nt), sig, lambda i, ds: z[i] * ds, offs)
    xc = x - x.mean(axis=1, keepdims=True)
    zc = z - z.mean(axis=1, keepdims=True)
    ref = [-(xc[i] @ zc[i]) / float(np.sum(xc**2)) * sig[i] for i in range(nt)]
    assert [p[0] for p in parts] == pytest.approx(ref, rel=1e-10)
    assert parts[1][0] == 0.0  # no uncertainty, no part
    assert se[0] == pytest.approx(math.sqrt(sum(r * r for r in ref)), rel=1e-10)
