"""The doubt test's parts against hand-computed cases: the noise meter's sigma and quantum, the threshold's
scaling with the measured noise, and a rise that came and went."""

from __future__ import annotations

import math
import random

import pytest

from rimless.firmware.control.rise_watch import NoiseMeter, RiseWatch


def test_noise_meter_measures_sigma_of_a_non_accumulating_noise() -> None:
    """Positions x_k = sigma * n_k (independent): dx has variance 2 sigma^2, so the meter reads sigma."""
    rng = random.Random(1)
    sigma = 7e-6
    meter = NoiseMeter(tau_s=1.0)
    prev = 0.0
    for _ in range(3000):
        x = rng.gauss(0.0, sigma)
        meter.see(x - prev)
        meter.add_quiet(x - prev, 0.001)
        prev = x
    assert meter.measured
    assert meter.sigma_m == pytest.approx(sigma, rel=0.1)  # 1 s average of ~1000 samples: a few % spread


def test_threshold_is_relative_to_the_noise_with_two_quanta_at_least() -> None:
    meter = NoiseMeter()
    assert meter.rise_threshold_m(6.0, 4) == math.inf  # not measured yet
    for dx in [2e-6, -2e-6] * 50:  # mean square 4e-12 m^2: sigma = sqrt(2) um
        meter.see(dx)
        meter.add_quiet(dx, 0.01)
    sigma = math.sqrt(0.5 * 4e-12)
    assert meter.rise_threshold_m(6.0, 4) == pytest.approx(6.0 * math.sqrt(2 / 4) * sigma)
    assert meter.rise_threshold_m(6.0, 4) < meter.rise_threshold_m(12.0, 4)  # scales with sigmas
    meter.see(1.59e-5)
    meter.see(4e-6)  # the smallest non-zero displacement is the quantum
    assert meter.quantum_m == 2e-6
    meter.quantum_m = 1.59e-5
    assert meter.rise_threshold_m(6.0, 4) == pytest.approx(2 * 1.59e-5)


def test_rise_watch_reports_a_rise_that_fell_back_by_half() -> None:
    watch = RiseWatch(smooth_s=0.0, span_s=0.5)  # no smoothing: the mean is the last position
    path = [0.0, 0.0, 1.0, 2.0, 3.0, 2.6, 2.0, 1.4]  # rises 3, then falls
    out = []
    for k, x in enumerate(path):
        watch.add_position(k * 0.01, x)
        out.append(watch.watch(k * 0.01, 2.0))
    # rise 2 reached at k = 3 (cross time 0.03); top 3; fall of 1 (half of 2) reached at k = 6 (3 - 2 = 1)
    assert out[:6] == [None] * 6 and out[6] == 3.0
    assert watch.cross_s == 0.03
    watch.forget()
    assert watch.rise_m() == 0.0 and watch.cross_s is None
