"""The adequacy check's timing noise and a wheel that limps (issue 31, session 21).

`adequacy.timing_noise_sd` takes the impact times' noise from what each trial's periods leave about their own
trend p* + a lambda^i. Its negative multipliers were written sign(lambda) |lambda|^i, which never alternates: a
period sequence approaching its fixed point with alternating sign (a negative multiplier), or alternating for
good (a limp), went into the noise, and the check then called a limping wheel "fits" (session 21's study: limps
of 5-20 % passed with periods chi^2/dof 0.76-0.84).

Truths: closed-form period sequences with white impact-time noise of a known sd (the expected value is that sd).
Not enough for a limp after a release (session 21: 5.7 ms on c = 11 ER walks limping by 5 %, the check said "fits"):
the trend now holds a persistent alternation too (session 22, `test_adequacy_timing_noise.py`; docs/trials.md).
"""

from __future__ import annotations

import numpy as np

from rimless.analysis.inference.adequacy import timing_noise_sd

NOISE_S = 0.5e-3


def _impacts(periods: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(periods)]) + rng.normal(0.0, NOISE_S, periods.size + 1)


def test_an_alternating_approach_to_the_fixed_point_is_trend_not_noise() -> None:
    """Periods 0.3 s + 12 ms (-0.6)^i (a negative multiplier, a plain approach to the fixed point): the pooled
    estimate over 40 trials of 10 periods is the impact noise's sd (0.5 ms), within 20 %. Main gave about 2 ms."""
    rng = np.random.default_rng(11)
    i = np.arange(10)
    trials = [_impacts(0.3 + 0.012 * (-0.6) ** i, rng) for _ in range(40)]
    sigma, dof = timing_noise_sd(trials)
    assert dof == 40 * 6
    assert 0.8 * NOISE_S < sigma < 1.2 * NOISE_S, sigma


def test_a_monotone_approach_is_unchanged() -> None:
    """The same with a positive multiplier (+0.6): the estimate was right before and stays right."""
    rng = np.random.default_rng(12)
    i = np.arange(10)
    sigma, _ = timing_noise_sd([_impacts(0.3 + 0.012 * 0.6**i, rng) for _ in range(40)])
    assert 0.8 * NOISE_S < sigma < 1.2 * NOISE_S, sigma
