"""Studies of the firmware in the loop (rimless.sim.in_the_loop.studies): its fixed point, and what limits
the slope it walks down to."""

import math

import numpy as np
import pytest

from rimless.firmware.control.detector import DetectorParams
from rimless.sim.in_the_loop.loop import FirmwareLoop, FirmwareLoopConfig
from rimless.sim.in_the_loop.studies import (
    FIRMWARE_FAULT_PREFIX,
    FirmwareBoundaries,
    FirmwareCriticalSlope,
    firmware_fixed_point,
    ideal_gait,
    without_step_timing_checks,
)


def _walk(params, z, steps, **cfg):
    loop = FirmwareLoop(params, FirmwareLoopConfig(**cfg))
    try:
        return loop, loop.walk(z, steps)
    finally:
        loop.close()


HIGH_RATE = dict(
    jitter_s=0.0, noise_counts=0.0, engage_delay_s=0.0, release_delay_s=0.0, counts_per_m_1600=6.3e6
)  # a 100x finer sensor: quantisation out of the way


def _high_rate(rate_hz, window_s):
    det = DetectorParams(velocity_window_s=window_s, touch_compression_m=1e-5, touch_debounce_samples=1)
    return dict(HIGH_RATE, rate_hz=rate_hz, detector=det)


@pytest.mark.slow
def test_high_rate_no_noise_no_delay_converges_to_the_ideal_fixed_point(table1, er_fixed_point):
    """The firmware can only release the trailing clutch after it has seen the touchdown; the trailing leg
    slips against the holding force meanwhile, which is the remaining difference. Its one-step deficit
    shrinks as the rate rises (and the velocity window with it), and at 20 kHz the fixed point is within
    2 % (theta'+) and 3 % (period) of the ideal one: the one-step deficit there is ~0.009 rad/s, and the
    fixed point moves by about 1 / (1 - 0.79) of it (the map's dominant eigenvalue is 0.79)."""
    ideal = er_fixed_point[1]
    deficits = []
    for rate, window in ((5000.0, 0.008), (20000.0, 0.002)):
        _, walk = _walk(table1, ideal.z, 2, **_high_rate(rate, window))
        assert walk.failure is None
        deficits.append(ideal.z[1] - walk.steps[1].z_end[1])
    assert 0 < deficits[1] < deficits[0] / 1.6, deficits
    fp = firmware_fixed_point(table1, FirmwareLoopConfig(**_high_rate(20000.0, 0.002)), ideal.z, steps=9)
    assert fp.walk.failure is None
    assert fp.z[1] == pytest.approx(ideal.z[1], rel=0.02)
    assert fp.z[0] == pytest.approx(ideal.z[0], abs=0.002)
    assert fp.period_s == pytest.approx(ideal.step.period_s, rel=0.03)
    assert np.max(np.abs(fp.eigenvalues)) == pytest.approx(np.max(np.abs(ideal.eigenvalues)), abs=0.05)
    assert fp.stored_energy_J == pytest.approx(
        0.5 * table1.k * (table1.leg_length_m - ideal.step.y_minus[3]) ** 2, rel=0.02
    )
    assert all(s.lock_class == "peak" for s in fp.walk.steps)
    assert max(abs(s.energy_residual_J) for s in fp.walk.steps) < 1e-7


def test_a_leg_sync_fault_before_a_stall_is_reported_with_the_mechanical_cause(table1):
    """At 1.9 deg with a 5 ms clutch at 300 Hz the gait slows step by step. The firmware's leg count
    faults (leg_sync_lost: no touchdown within 1.4 x the running step period) and stops clutching; with
    the step-timing checks relaxed the same walk stalls mechanically instead, classified."""
    params = table1.replace(slope_rad=math.radians(1.9))
    z = ideal_gait(params).z
    cfg = FirmwareLoopConfig()
    _, walk = _walk(params, z, 5, **cfg.__dict__)
    faults = [f["fault"] for _, name, f in walk.events if name == "fault"]
    assert faults == ["leg_sync_lost"]
    relaxed = without_step_timing_checks(cfg)
    assert relaxed.detector.max_step_s == 10.0 and relaxed.max_hold_s == 60.0
    assert relaxed.detector.velocity_window_s == cfg.detector.velocity_window_s
    loop = FirmwareLoop(params, relaxed)
    try:
        relaxed_walk = loop.walk(z, 6)
    finally:
        loop.close()
    assert not [1 for _, name, _ in relaxed_walk.events if name == "fault"]
    assert relaxed_walk.failure is not None and relaxed_walk.failure.reason.value == "stall"
    # up to the fault both walks are the same walk (the relaxed checks change nothing else)
    n = len(relaxed_walk.steps)
    assert n >= 3
    assert [s.period_s for s in walk.steps[: n - 1]] == [s.period_s for s in relaxed_walk.steps[: n - 1]]


def test_boundaries_say_what_limits_the_critical_slope():
    fault = f"{FIRMWARE_FAULT_PREFIX} (leg_sync_lost): it no longer clutches"
    fw = FirmwareCriticalSlope(0.036, 0.035, fault, [])
    stall = "step 6: stall"
    # relaxed, the wheel walks well below where the firmware faulted: the firmware limits it
    b = FirmwareBoundaries(fw, FirmwareCriticalSlope(0.030, 0.029, stall, []))
    assert b.limited_by == "firmware" and b.mechanical_slope_rad == 0.030 and "would walk" in b.detail
    # relaxed, it fails at the same boundary: the fault only came first
    b = FirmwareBoundaries(fw, FirmwareCriticalSlope(0.036, 0.0352, stall, []))
    assert b.limited_by == "mechanics" and "fires first" in b.detail
    b = FirmwareBoundaries(FirmwareCriticalSlope(0.036, 0.035, stall, []), None)
    assert b.limited_by == "mechanics" and b.mechanical_slope_rad == 0.036
