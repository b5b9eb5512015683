"""The hub offset's 2 x 2 covariance: its misfit part's test, and where the covariance is carried.

Truth (`tests.support.rolling_wheel`, written apart from the fit): a rigid wheel rolling down a 4 deg slope, its
speed changing (2 -> 3.2 rad/s over 1.6 turns), tracked at a body point 36 mm off the hub with white noise of 0.3 mm.
A rigid wheel's hub height is a function of its angle within the step, so the fit's height model (a line plus a
bump that repeats every step, plus the offset) holds exactly: whatever the misfit part adds is a false alarm.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.kinematics import hub as kin_hub
from rimless.analysis.kinematics.slope_evidence import Z95, _hub_offset_sd, slope_evidence
from tests.support.rolling_wheel import ALPHA_RAD, rolling_wheel

ORIGIN_BODY_M = np.array([0.03, -0.02, 0.0])
DRAWS = 200
#: chi^2 with 2 degrees of freedom: 95 % below
CHI2_2_95 = -2.0 * math.log(0.05)


def _speeding_walk():
    t = np.arange(0.0, 4.0, 0.01)
    beta = 2.0 * t + 0.1 * np.sin(3.0 * t) + 0.15 * t**2  # the body's turn, rad: 1.6 turns, speeding up
    return rolling_wheel(beta, ORIGIN_BODY_M)


def test_the_misfit_part_fires_at_its_stated_false_alarm_rate_where_the_model_fits() -> None:
    """`DRAWS` noise draws on the speeding walk: the misfit part may fire on about `MISFIT_FALSE_ALARM` (5 %) of
    them (at most 10 %: a binomial(200, 0.05) passes 20 with probability 0.1 %); main's rule (the offset's move
    beyond once its noise's mean square) fired on about a third (exp(-1) for a chi^2_2 move). The test's p-value
    is about uniform where the model fits (35-65 % below 0.5), and the stated covariance covers the offset's error
    (e^T C^+ e below the chi^2_2 95 % point in at least 90 %; its mean over 2, the rms z per axis, 0.75-1.15:
    1 for an honest covariance; measured 0.88 when written, the noise's level at once a turn a little over)."""
    assert kin_hub.MISFIT_FALSE_ALARM == 0.05
    rot, tracked = _speeding_walk()
    clean = kin_hub.fit_hub_offset(rot, tracked, harmonics=6)
    assert clean is not None and np.linalg.norm(clean.offset_m + ORIGIN_BODY_M) < 1e-5
    rng = np.random.default_rng(11)
    fired, below_half, z2 = 0, 0, []
    for _ in range(DRAWS):
        fit = kin_hub.fit_hub_offset(rot, tracked + rng.normal(0.0, 0.3e-3, tracked.shape), harmonics=6)
        assert fit is not None
        fired += fit.misfit_sd_m > 0
        below_half += fit.misfit_p_value < 0.5
        e = fit.offset_m - clean.offset_m
        z2.append(float(e @ np.linalg.pinv(fit.cov_m2, rcond=1e-10) @ e))
    z2a = np.array(z2)
    assert fired <= 0.10 * DRAWS, fired
    assert 0.35 * DRAWS <= below_half <= 0.65 * DRAWS, below_half
    assert (z2a < CHI2_2_95).mean() >= 0.90, (z2a < CHI2_2_95).mean()
    assert 0.75 <= math.sqrt(z2a.mean() / 2.0) <= 1.15, math.sqrt(z2a.mean() / 2.0)


def test_the_covariance_has_two_axes_and_sd_is_the_worst() -> None:
    """``sd_axes_m`` are the square roots of the covariance's eigenvalues in the wheel plane, largest first, and
    ``sd_m`` (the contract: the worst axis) the first; ``sd_per_axis_m`` their rms."""
    rot, tracked = _speeding_walk()
    fit = kin_hub.fit_hub_offset(rot, tracked + np.random.default_rng(3).normal(0, 0.3e-3, tracked.shape))
    assert fit is not None
    big, small = fit.sd_axes_m
    w = np.linalg.eigvalsh(fit.cov_m2)
    assert w[0] == pytest.approx(0.0, abs=1e-15)  # rank 2: nothing along the wheel axis
    assert (big, small) == pytest.approx((math.sqrt(w[2]), math.sqrt(w[1])), rel=1e-9)
    assert big == pytest.approx(fit.sd_m, rel=1e-12) and small <= big
    assert fit.sd_per_axis_m == pytest.approx(math.hypot(big, small) / math.sqrt(2.0), rel=1e-9)


def _impact_rows(k: int) -> np.ndarray:
    """(k, 3) z^T R at k impacts one step apart on the truth's wheel (the height of an offset error e: row @ e)."""
    beta = np.arange(k) * ALPHA_RAD + 0.3
    rot, _ = rolling_wheel(beta, ORIGIN_BODY_M)
    return rot[:, 2, :]


def test_the_impact_lines_slope_carries_the_offsets_covariance_exactly() -> None:
    """Seven impacts 0.18 m apart; an offset covariance with axes of 0.1 and 0.02 mm along body directions v1, v2
    in the wheel plane. Independent expectation: an error e = a v1 + b v2 puts heights row_k @ e at the impacts,
    whose least-squares slope (np.polyfit) is linear in (a, b): its variance is the sum over the axes of
    (sd_j x the slope of row_k @ v_j)^2. The worst-axis sd on each axis (the isotropic term) bounds it."""
    k, step = 7, 0.18
    along = step * np.arange(k)
    g = _impact_rows(k)
    v1 = np.array([math.cos(0.4), math.sin(0.4), 0.0])
    v2 = np.array([-math.sin(0.4), math.cos(0.4), 0.0])
    sds = (0.1e-3, 0.02e-3)
    cov = sds[0] ** 2 * np.outer(v1, v1) + sds[1] ** 2 * np.outer(v2, v2)
    expected = math.sqrt(sum((sd * np.polyfit(along, g @ v, 1)[0]) ** 2 for sd, v in zip(sds, (v1, v2))))
    height_cov = g @ cov @ g.T
    got = _hub_offset_sd(along, sds[0], step, ALPHA_RAD, height_cov)
    assert got == pytest.approx(expected, rel=1e-9)
    assert got <= _hub_offset_sd(along, sds[0], step, ALPHA_RAD) * (1 + 1e-12)
    from rimless.analysis.kinematics.slope import SlopeFrame

    line = SlopeFrame(math.radians(2.0), np.array([1.0, 0.0, 0.0]), np.zeros(3), 1e-4, "line through the hub", k, 1e-5)
    args = (None, None, None, None, None, line, line, k)
    common = {"travel_m": 1.0, "step_m": step, "impact_along_m": along}
    ev = slope_evidence(*args, **common, hub_sd_m=sds[0], hub_height_cov_m2=height_cov)
    without = slope_evidence(*args, **common)
    assert ev[0].half_rad ** 2 - without[0].half_rad ** 2 == pytest.approx((Z95 * expected) ** 2, rel=1e-9)


def test_the_import_carries_the_height_fits_covariance_to_the_slope(tmp_path, monkeypatch) -> None:
    """A rigid walk of `critical_truth` recorded as a Tracker object (`hub_offset_study` draw 103: Z-up, the height
    fit places the hub): `import_trial` hands the impact line the heights' covariance from the fit's 2 x 2,
    (k, k) for its k impacts, positive semi-definite, whose slope term is at most the worst-axis one."""
    from rimless.analysis.kinematics import build
    from rimless.analysis.validation.hub_offset_study import hub_offset_draw

    seen = []
    inner = build.slope_evidence

    def spy(*args, **kwargs):
        seen.append(kwargs)
        return inner(*args, **kwargs)

    monkeypatch.setattr(build, "slope_evidence", spy)
    row = hub_offset_draw("rigid", 103, tmp_path)
    assert "centre of rotation fitted" in row["hub_source"], row["hub_source"]
    kw = seen[-1]
    cov, along = kw["hub_height_cov_m2"], kw["impact_along_m"]
    assert cov is not None and cov.shape == (along.size, along.size)
    assert np.linalg.eigvalsh(cov).min() >= -1e-20
    sd = kw["hub_sd_m"]
    assert sd == pytest.approx(row["hub_sd_mm"] * 1e-3)
    carried = _hub_offset_sd(along, sd, kw["step_m"], kw["alpha_rad"], cov)
    assert 0.0 < carried <= _hub_offset_sd(along, sd, kw["step_m"], kw["alpha_rad"]) * 1.001


def test_the_study_reads_the_offsets_error_against_its_covariance(tmp_path) -> None:
    """`hub_offset_study`'s ``offset_z_cov`` (the offset's error in the body frame against the 2 x 2) for a
    height-fitted Tracker walk (draw 103): the error's length from the once-a-turn regression (``offset_error_mm``,
    another route) over the covariance's largest and smallest axes brackets it (within 5 %, the two routes'
    difference)."""
    from rimless.analysis.validation.hub_offset_study import hub_offset_draw

    row = hub_offset_draw("rigid", 103, tmp_path)
    big, small = row["offset_sd_axes_mm"]
    z, err = row["offset_z_cov"], row["offset_error_mm"]
    assert 0.95 * err / big <= z <= 1.05 * err / small, (z, err, big, small)


def test_the_trial_states_the_offsets_two_axes(tmp_path) -> None:
    """The imported trial (draw 103, the height fit placed the hub) states both axes of the offset's covariance,
    the worst first and equal to ``hub_offset_sd_m`` (to rounding; the contract's worst axis), in its JSON in mm, and reads them
    back."""
    from rimless.analysis.io.trial import TrialMeta
    from rimless.analysis.kinematics.build import import_trial
    from rimless.analysis.validation.hub_offset_study import hub_offset_draw

    trials = []

    def importer(path):
        trials.append(import_trial(path))
        return trials[-1]

    row = hub_offset_draw("rigid", 103, tmp_path, importer=importer)
    meta = trials[-1].meta
    big, small = meta.hub_offset_sd_axes_m
    assert big == pytest.approx(meta.hub_offset_sd_m, rel=1e-12) and 0.0 < small <= big
    assert [v * 1e-3 for v in row["offset_sd_axes_mm"]] == pytest.approx([big, small], rel=1e-12)
    assert trials[-1].summary()["hub_offset_sd_axes_mm"] == pytest.approx([big * 1e3, small * 1e3])
    assert TrialMeta.from_json(meta.to_json()).hub_offset_sd_axes_m == (big, small)
