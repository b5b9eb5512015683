"""The adequacy check on the errors an import makes that are not white noise (issue 31): it must not cry wolf.

Found through the importer on the simulator's ER truth (`rimless trials adequacy-coverage`): against the truth the
imported CoM height's error is white noise plus a once-a-turn sinusoid of the wheel's angle (an error of the hub's
offset in the wheel, which the importer fits from the height) and a tilt (the slope frame's); and the calibrated
model's first period after the release moves with the first impact's angle the calibration fits (the stance angle after the
touchdown before, set by the leg's compression), which the check moves with the calibration's shape, never excusing the first period
alone. Here the trials are generated apart from the code: the wheel's angle is a non-linear function of time
within each step (the stance speeds up), not the check's linear-between-impacts estimate; the noise levels are the
check's to find from the data. Expected (independent): with the model right, chi^2/dof near 1 and no alarm; a model
off by a per-step shape (a bump 35 % too large) or by a steady period (a stiffness off) is still flagged.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.inference import adequacy as adq

ALPHA = math.pi / 4  # the angle between legs, rad
SIGMA_H = 0.15e-3  # the markers' white noise on the CoM height, m
SIGMA_T = 0.3e-3  # the impact times' noise, s
HUB_ERROR_M = 0.35e-3  # the hub offset's error, m (0.05-0.43 mm measured through the importer)
BUMP_M = 2.5e-3  # the CoM's rise and fall within a step, m


def _trial(
    rng: np.random.Generator, name: str, *, bump_error: float = 0.0, period_error_s: float = 0.0, whole: bool = False
) -> dict:
    """One imported trial and the calibrated model's residuals at the truth (plus the misfit asked for); ``whole``:
    with the calibration's shapes of the release speed and time shift in both blocks (the trial judged as a whole)."""
    n_imp = 11
    period = 0.33 + 0.04 * 0.6 ** np.arange(n_imp - 1)  # a release slightly slow, converging to the gait
    impacts_true = np.concatenate([[0.0], np.cumsum(period)])
    t = np.arange(0.003, impacts_true[-1], 0.01)  # 100 Hz frames
    k = np.clip(np.searchsorted(impacts_true, t, side="right") - 1, 0, n_imp - 2)
    u = (t - impacts_true[k]) / period[k]  # the fraction of the step
    theta = ALPHA * (k + u + 0.05 * np.sin(2 * np.pi * u))  # the wheel turns faster mid-stance
    height = 0.3 - BUMP_M * (1.0 - np.sin(np.pi * u))  # cusps at the impacts
    phase = rng.uniform(0, 2 * np.pi)
    tilt = rng.normal(0.0, 2e-4) * theta * 0.11 / ALPHA  # a slope frame 0.2 mrad off, 0.11 m a step
    error = rng.normal(0.0, SIGMA_H, t.size) + HUB_ERROR_M * np.sin(theta + phase) + tilt
    keep = np.min(np.abs(t[:, None] - impacts_true[None, :]), axis=1) >= 0.015  # the cusps left out
    measured = (height + error)[keep]
    model = (height + bump_error * BUMP_M * np.sin(np.pi * u))[keep]
    impacts = impacts_true + rng.normal(0.0, SIGMA_T, n_imp)
    angle_shape = 1e-3 * 0.1 ** np.arange(period.size)  # per unit of the first impact's angle: the fast multiplier 0.1
    sim_periods = period + 2.5 * angle_shape  # that angle off: its first period 2.5 ms
    sim_periods = sim_periods + period_error_s * (1.0 - 0.6 ** np.arange(1, period.size + 1))
    out = {
        "trial": name,
        "com_t_s": t[keep],
        "com_m": measured,
        "com_res_m": model - measured,
        "impacts_s": impacts,
        "period_res_s": sim_periods - np.diff(impacts),
        "period_release_s": 1e-3 * 0.6 ** np.arange(period.size),  # the release speed's transient
        "period_angle_s": angle_shape,
        "com_angle_m": np.zeros(int(keep.sum())),  # (its CoM part left out here)
    }
    if whole:  # the model's CoM moved 1 ms later, and stretched in time as a faster release would
        rate = BUMP_M * np.pi / period[k] * np.cos(np.pi * u)
        out["com_shift_m"] = -1e-3 * rate[keep]
        out["com_release_m"] = (-1e-3 * t * rate)[keep]
    return out


def _series(seed: int, whole: bool = False, **misfit: float) -> list[dict]:
    rng = np.random.default_rng(seed)
    return [_trial(rng, f"t{i}", whole=whole, **misfit) for i in range(4)]


@pytest.mark.parametrize("whole", [False, True], ids=["blocks", "whole-trial"])
def test_the_model_s_own_truth_through_importer_like_errors_fits_with_chi_square_near_one(whole: bool):
    """Four trials, each with a hub offset 0.35 mm off (2.3 times the markers' noise), a tilted frame and a release
    angle off (first period 2.5 ms): the check of session 15 said "does not fit" (CoM chi^2/dof about 3.7, periods
    about 8); allowed for, the figures are near 1 and the model fits, in each of five draws."""
    for seed in range(5):
        out = adq.adequacy(_series(seed, whole), 2)
        assert out["fits"], out["statement"]
        assert out["overall"]["com"]["ratio"] == pytest.approx(1.0, abs=0.35), seed
        assert out["overall"]["periods"]["ratio"] == pytest.approx(1.0, abs=0.6), seed
        assert out["noise"]["com_mm"] == pytest.approx(SIGMA_H * 1e3, rel=0.25)
        assert "hub offset" in out["allowed"]["com"]


@pytest.mark.parametrize("whole", [False, True], ids=["blocks", "whole-trial"])
def test_a_first_period_off_is_not_excused_without_the_first_angle_s_shape(whole: bool):
    """The same trials without the calibration's shape of that angle: the first period 2.5 ms off (six times the
    period's noise of 0.42 ms) is no longer allowed at any amplitude (session 16's check excused it: ratio near 1).
    Judged block by block it does not fit (periods' chi^2/dof 6.8-8.5 on seeds 0, 1, 13); judged as a whole the
    release speed takes part of it (2.5-2.8, p 0.003-0.007 on four trials: material, not significant at 1e-3)."""
    series = _series(13, whole)
    for b in series:
        del b["period_angle_s"], b["com_angle_m"]
    out = adq.adequacy(series, 2)
    assert out["overall"]["periods"]["ratio"] > 2.0
    if not whole:
        assert not out["fits"] and "step periods" in out["statement"]
    assert "no longer excused" in out["allowed"]["periods"]


@pytest.mark.parametrize("whole", [False, True], ids=["blocks", "whole-trial"])
def test_a_per_step_shape_the_model_gets_wrong_is_still_flagged(whole: bool):
    """The model's bump 35 % too large (0.88 mm at mid-step, once a step: not a once-a-turn shape; about its mean
    an rms of 0.27 mm, 1.8 times the noise: chi^2/dof about 1 + 1.8^2 = 4.2 by hand): does not fit."""
    out = adq.adequacy(_series(11, whole, bump_error=0.35), 2)
    assert not out["fits"]
    assert "CoM height" in out["statement"]
    assert out["overall"]["com"]["ratio"] > 3.0


@pytest.mark.parametrize("whole", [False, True], ids=["blocks", "whole-trial"])
def test_a_steady_period_error_is_still_flagged(whole: bool):
    """Every simulated period 2 ms long once the release has died out (a stiffness held off): does not fit."""
    out = adq.adequacy(_series(12, whole, period_error_s=2e-3), 2)
    assert not out["fits"]
    assert "step periods" in out["statement"]


def test_the_free_shapes_cost_what_least_squares_says():
    """`block_chi2` with white noise and free columns is the least-squares residual sum of squares over sigma^2
    (numpy's lstsq, by hand), and each independent column is one degree of freedom."""
    rng = np.random.default_rng(4)
    n, sig = 60, 0.2e-3
    r = rng.normal(0.0, 0.5e-3, n)
    f = np.column_stack([np.sin(np.arange(n) / 9.0), np.arange(n) / n, 2.0 * np.arange(n) / n])  # rank 2
    coef, *_ = np.linalg.lstsq(f, r, rcond=None)
    c2, rank = adq.block_chi2(r, np.eye(n) * sig**2, None, f)
    assert rank == 2
    assert c2 == pytest.approx(float(np.sum((r - f @ coef) ** 2)) / sig**2, rel=1e-9)
