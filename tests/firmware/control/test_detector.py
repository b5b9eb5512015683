"""Zero-velocity detection on scripted compression-rebound trajectories, asserted on mock pins."""

from __future__ import annotations

import math
import random

import pytest

from rimless.firmware.control.detector import DetectorParams, LegDetector, Phase, VelocityEstimator
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory, still


def test_quadratic_velocity_is_exact_on_a_parabola_with_jittered_times() -> None:
    est = VelocityEstimator(0.02)
    rng = random.Random(3)
    t = 0.0
    for _ in range(12):
        t += 0.003 + rng.uniform(-0.0005, 0.0005)
        est.add(t, 0.002 + 0.3 * t - 4.0 * t * t)
    assert est.estimate() == pytest.approx(0.3 - 8.0 * t, abs=1e-9)
    assert est.estimate(lead_s=0.001) == pytest.approx(0.3 - 8.0 * (t + 0.001), abs=1e-9)


def test_too_few_samples_give_no_estimate() -> None:
    est = VelocityEstimator(0.02)
    for k in range(3):
        est.add(k * 0.001, 0.0)
    assert est.estimate() is None


@pytest.mark.parametrize(
    ("compression_m", "compression_s", "seed"),
    [(0.008, 0.06, 0), (0.005, 0.045, 1), (0.012, 0.08, 2), (0.004, 0.05, 3)],
)
def test_clutch_locks_within_one_period_of_max_and_releases_at_next_touchdown(
    make_rig, compression_m, compression_s, seed
) -> None:
    traj = GaitTrajectory(
        start_s=0.2, step_period_s=0.4, compression_m=compression_m, compression_s=compression_s, steps=4
    )
    rig = make_rig(traj, rate_hz=300.0, noise_counts=0.5, seed=seed)
    period = 1 / 300
    on_times: dict[int, float] = {}
    off_times: dict[int, float] = {}
    prev = [False] * 8

    def watch(r) -> None:
        for leg in range(8):
            state = r.pin(leg).state
            if state and not prev[leg]:
                on_times[leg] = r.clock.t
            if prev[leg] and not state:
                off_times[leg] = r.clock.t
            prev[leg] = state

    rig.run(1.9, watch)  # ends before the missed-touchdown watchdog (1.4 s + 1.4 x 0.4 s) fires
    # Legs 0..3 each stance once, in order; 4..7 never.
    assert sorted(on_times) == [0, 1, 2, 3]
    for k in range(4):
        assert abs(on_times[k] - traj.max_compression_s(k)) <= period + 1e-9
    for k in range(3):  # released by the next leg's touchdown, within the touchdown debounce
        td = traj.touchdown_s(k + 1)
        assert td <= off_times[k] <= td + 4 * period
    # Pin histories, with their length: off at start, on once, off once.
    for k in range(3):
        assert rig.levels(k) == [False, True, False]
    assert rig.levels(3) == [False, True]  # last stance leg stays locked (no next touchdown yet)
    for k in range(4, 8):
        assert rig.levels(k) == [False]
    assert rig.fake.violations == 0


def test_phases_follow_the_model(make_rig) -> None:
    traj = GaitTrajectory(start_s=0.1, step_period_s=0.4, compression_m=0.008, compression_s=0.06, steps=2)
    rig = make_rig(traj)
    phases: list[int] = []
    rig.run(0.9, lambda r: phases.append(r.controller.channels[0].detector.phase.code))
    collapsed = [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p]
    w, ds, fc, cl = (Phase.WAIT.code, Phase.DOUBLE_SUPPORT.code, Phase.FREE_COMPRESSION.code, Phase.CLUTCHED.code)
    assert collapsed == [w, ds, fc, cl, ds, fc, cl]


@pytest.mark.parametrize("seed", range(4))
def test_no_false_triggers_on_noise(make_rig, seed) -> None:
    rig = make_rig(still, noise_counts=1.0, seed=seed)
    rig.run(3.0)
    assert rig.events("touchdown") == [] and rig.events("lock") == []
    for leg in range(8):
        assert rig.levels(leg) == [False]


def test_small_vibration_below_thresholds_does_not_trigger(make_rig) -> None:
    # 0.3 mm, 5 Hz wobble: peak velocity 9 mm/s, far below touch_velocity_m_s.
    rig = make_rig(lambda t: 0.0003 * math.sin(2 * math.pi * 5 * t), noise_counts=0.5)
    rig.run(2.0)
    assert rig.events("touchdown") == []
    assert all(rig.levels(leg) == [False] for leg in range(8))


def test_disarmed_detects_but_never_switches(make_rig) -> None:
    traj = GaitTrajectory(start_s=0.1, step_period_s=0.4, steps=2)
    rig = make_rig(traj, arm=False)
    rig.run(1.0)
    assert len(rig.events("lock")) == 2
    assert all(rig.levels(leg) == [False] for leg in range(8))


def test_one_sensor_per_leg_configuration(make_rig) -> None:
    traj = GaitTrajectory(start_s=0.1, step_period_s=0.4, steps=3)
    rig = make_rig(traj, legs=(5,))
    rig.run(1.4)
    assert rig.levels(5) == [False, True, False, True, False, True]
    assert all(rig.levels(leg) == [False] for leg in range(8) if leg != 5)


def test_param_validation_names_the_parameter() -> None:
    p = DetectorParams()
    assert p.with_value("touch_velocity_m_s", 0.1).touch_velocity_m_s == 0.1
    assert p.with_value("touch_debounce_samples", 3.0).touch_debounce_samples == 3
    with pytest.raises(ValueError, match="unknown detector parameter 'nope'"):
        p.with_value("nope", 1)
    with pytest.raises(ValueError, match="touch_velocity_m_s"):
        p.with_value("touch_velocity_m_s", -1)
    with pytest.raises(ValueError, match="touch_debounce_samples"):
        p.with_value("touch_debounce_samples", 1.5)
    with pytest.raises(ValueError, match="number"):
        p.with_value("velocity_window_s", "0.1")
    with pytest.raises(ValueError, match="finite"):
        p.with_value("velocity_window_s", float("nan"))


def test_detector_needs_legs() -> None:
    with pytest.raises(ValueError):
        LegDetector(DetectorParams(), [])
