"""Can a calibration tell the leg damping from a constant loss per step (`loss_separation`)? Checked on
Jacobians built here with a known answer: trials at one leg speed cannot separate the two (the friction-like
column is c's own), trials at very different speeds can; residuals laid along the friction-like direction are
found by the score test, pure noise is not. The effective leg speed against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rimless.analysis.inference.loss_separation import effective_leg_speed, loss_separation


def test_effective_leg_speed_closed_forms():
    t = np.linspace(0.0, 1.0, 20001)
    assert effective_leg_speed(t, np.full(t.size, -0.2)) == pytest.approx(0.2)  # constant speed: itself
    # v = a sin(pi t) on [0, 1]: int v^2 = a^2 / 2, int |v| = 2 a / pi -> a pi / 4
    assert effective_leg_speed(t, 0.3 * np.sin(np.pi * t)) == pytest.approx(0.3 * math.pi / 4, rel=1e-6)
    assert math.isnan(effective_leg_speed(t, np.zeros(t.size)))


def _design(v_eff, rng, n_rows=40):
    """A Jacobian of n trials: one global column (c), then per trial a release column. In trial i c acts
    through the trial's dissipated energy, whose effect on the residuals has a trial-specific shape."""
    n = len(v_eff)
    offs = np.arange(n + 1) * n_rows
    J = np.zeros((offs[-1], 1 + n))
    for i in range(n):
        shape = rng.normal(size=n_rows)
        J[offs[i] : offs[i + 1], 0] = shape * (1.0 + 0.3 * i)
        J[offs[i] : offs[i + 1], 1 + i] = rng.normal(size=n_rows)
    return J, offs


def _friction_col(J, offs, v_eff):
    col = np.zeros(J.shape[0])
    for i in range(offs.size - 1):
        col[offs[i] : offs[i + 1]] = J[offs[i] : offs[i + 1], 0] / v_eff[i]
    return col


def test_one_leg_speed_cannot_separate():
    rng = np.random.default_rng(0)
    v = np.full(8, 0.18)
    J, offs = _design(v, rng)
    r = rng.normal(size=J.shape[0])
    out = loss_separation(J * 50.0, r, offs, 1, 0, 10.0, 1.0, v, np.ones(J.shape[1]))
    assert not out["separable"] and not out["damping_identified"]
    assert "cannot be told from a constant loss" in out["note"]


def test_speeds_far_apart_separate_and_noise_shows_no_constant_loss():
    rng = np.random.default_rng(1)
    v = np.array([0.05, 0.1, 0.2, 0.4, 0.8, 0.06, 0.3, 0.6])
    J, offs = _design(v, rng, n_rows=400)
    r = rng.normal(size=J.shape[0])
    r -= J @ np.linalg.lstsq(J, r, rcond=None)[0]  # residuals at the optimum: orthogonal to the fitted columns
    out = loss_separation(J * 50.0, r, offs, 1, 0, 10.0, 1.0, v, np.ones(J.shape[1]))
    assert out["separable"] and out["damping_identified"], out
    assert out["score_p"] > 0.1


def test_residuals_along_a_constant_loss_are_found():
    rng = np.random.default_rng(2)
    v = np.array([0.05, 0.1, 0.2, 0.4, 0.8, 0.06, 0.3, 0.6])
    J, offs = _design(v, rng, n_rows=400)
    f = _friction_col(J, offs, v)
    r = 3.0 * f + 0.2 * rng.normal(size=J.shape[0])  # the data hold a constant loss the model lacks
    r -= J @ np.linalg.lstsq(J, r, rcond=None)[0]  # what the fit of c and the releases leaves
    out = loss_separation(J * 50.0, r, offs, 1, 0, 10.0, 1.0, v, np.ones(J.shape[1]))
    assert out["absorbs_constant_loss"] and not out["damping_identified"]
    assert out["score_p"] < 0.01 and "absorbs it" in out["note"]


def test_one_trial_prints_no_nan_correlation():
    """One trial: c and the friction-like column are the same column, so their correlation is not determined;
    the note said "(correlation +nan)" (seen by a session-21 helper on every single-trial calibration)."""
    rng = np.random.default_rng(3)
    v = np.array([0.2])
    J, offs = _design(v, rng)
    r = rng.normal(size=J.shape[0])
    out = loss_separation(J * 50.0, r, offs, 1, 0, 10.0, 1.0, v, np.ones(J.shape[1]))
    assert not out["separable"] and out["correlation"] is None
    assert "nan" not in out["note"] and "not both determined" in out["note"]


def test_rel_se_band_against_table_values():
    """The band of a relative se of 4.8 % estimated with 5 degrees of freedom: in logarithms, the se's half-widths
    log sqrt(11.0705 / 5) down and log sqrt(5 / 1.1455) up (chi^2_5's 95 % and 5 % quantiles) and c's scatter
    1.6449 x 0.048 (the normal's 95 % quantile), added in quadrature (printed tables)."""
    from rimless.analysis.inference.loss_separation import rel_se_band

    lo, hi = rel_se_band(0.048, 5)
    c_part = 1.6449 * 0.048
    assert lo == pytest.approx(0.048 * math.exp(-math.hypot(0.5 * math.log(11.0705 / 5), c_part)), rel=1e-4)
    assert hi == pytest.approx(0.048 * math.exp(math.hypot(0.5 * math.log(5 / 1.1455), c_part)), rel=1e-4)
    # many degrees of freedom: the se's part vanishes, c's stays (4.76 % reaches past 5 %: the audit's knife edge)
    lo_big, hi_big = rel_se_band(0.0476, 10**7)
    assert hi_big == pytest.approx(0.0476 * math.exp(1.6449 * 0.0476), rel=1e-3) and hi_big > 0.05
    assert lo_big == pytest.approx(0.0476 * math.exp(-1.6449 * 0.0476), rel=1e-3)


def _at_rel(target_rel, dof):
    """loss_separation on separable trials with c's value chosen so that its relative se with a friction-like loss
    free is ``target_rel`` (the se does not depend on c's value; residuals orthogonal, pure noise)."""
    rng = np.random.default_rng(1)
    v = np.array([0.05, 0.1, 0.2, 0.4, 0.8, 0.06, 0.3, 0.6])
    J, offs = _design(v, rng, n_rows=400)
    r = rng.normal(size=J.shape[0])
    r -= J @ np.linalg.lstsq(J, r, rcond=None)[0]
    args = (J * 50.0, r, offs, 1, 0)
    rest = (1.0, v, np.ones(J.shape[1]))
    rel10 = loss_separation(*args, 10.0, *rest)["c_rel_se_with_friction"]
    return loss_separation(*args, 10.0 * rel10 / target_rel, *rest, se_dof=dof)


@pytest.mark.parametrize(
    ("rel", "dof", "separable", "borderline"),
    [
        (0.0476, 5, True, True),  # the audit's two draws (session 21): either side of 5 %, both borderline
        (0.0512, 5, False, True),
        (0.0476, 2000, True, True),  # a residual-set se: c's own scatter (+-8 %) still reaches 5 %
        (0.040, 2000, True, False),  # ... and stays clear of it from 4 %
        (0.020, 5, True, False),  # clear on both sides with the trials' scatter's 5 dof
        (0.120, 5, False, False),
    ],
)
def test_a_verdict_near_the_limit_says_borderline_and_how_near(rel, dof, separable, borderline):
    out = _at_rel(rel, dof)
    assert out["c_rel_se_with_friction"] == pytest.approx(rel, rel=1e-9)
    assert out["separable"] is separable and out["damping_identified"] is separable
    assert out["borderline"] is borderline and out["c_rel_se_limit"] == 0.05 and out["c_rel_se_dof"] == dof
    lo, hi = out["c_rel_se_with_friction_ci90"]
    assert lo < rel < hi and (lo <= 0.05 <= hi) is borderline
    shown = f"{rel:.1%}" if rel < 0.1 else f"{rel:.0%}"
    assert shown in out["note"] and "limit 5.0%" in out["note"]  # how near, in the note
    assert ("borderline" in out["note"]) is borderline
    if borderline:
        assert ("may not be told apart" if separable else "may be told apart") in out["note"]


def test_no_dof_given_takes_the_residual_rows_less_the_columns():
    rng = np.random.default_rng(1)
    v = np.array([0.05, 0.1, 0.2, 0.4, 0.8, 0.06, 0.3, 0.6])
    J, offs = _design(v, rng, n_rows=400)
    r = rng.normal(size=J.shape[0])
    out = loss_separation(J * 50.0, r, offs, 1, 0, 10.0, 1.0, v, np.ones(J.shape[1]))
    assert out["c_rel_se_dof"] == J.shape[0] - (J.shape[1] + 1)  # the friction-like column added
