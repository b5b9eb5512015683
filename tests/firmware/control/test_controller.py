"""Every fail-safe path ends with all clutch pins off (asserted on the mock pins) and a reported fault."""

from __future__ import annotations

import pytest

from rimless.firmware.control.controller import Controller
from rimless.firmware.control.faults import Fault, HealthLimits
from rimless.firmware.control.sampler import Sampler
from rimless.firmware.drivers.fake_adns3080 import FakeFault, GaitTrajectory

TRAJ = GaitTrajectory(start_s=0.1, step_period_s=0.4, compression_m=0.008, compression_s=0.06)


def run_until_locked(rig) -> int:
    """Run until a clutch is on; return its leg."""
    for _ in range(600):
        rig.run(1 / rig.rate_hz)
        engaged = rig.controller.clutches.engaged()
        if engaged:
            assert rig.pin(engaged[0]).state is True
            return engaged[0]
    raise AssertionError("no clutch engaged")


def assert_all_off(rig, fault: Fault) -> None:
    assert all(rig.pin(leg).state is False for leg in range(8))
    assert not rig.controller.armed
    faults = [e.fields["fault"] for e in rig.events("fault")]
    assert faults.count(fault.value) == 1, faults


@pytest.mark.parametrize(
    ("inject", "fault"),
    [
        (FakeFault.SPI_ERROR, Fault.SPI_ERROR),
        (FakeFault.SQUAL_DROP, Fault.SQUAL_LOW),
        (FakeFault.SATURATE, Fault.MOTION_SATURATED),
        (FakeFault.STUCK_BUS, Fault.SENSOR_STUCK),
    ],
)
def test_sensor_faults_release_the_clutch(make_rig, inject, fault) -> None:
    rig = make_rig(TRAJ)
    leg = run_until_locked(rig)
    rig.fake.fault = inject
    rig.run(0.1)  # > squal_low_s and > saturated_samples_max samples
    assert_all_off(rig, fault)
    assert rig.levels(leg) == [False, True, False]


def test_wrong_id_found_by_the_periodic_check(make_rig) -> None:
    rig = make_rig(TRAJ, id_check_interval_s=0.05)
    leg = run_until_locked(rig)
    rig.fake.fault = FakeFault.WRONG_ID
    rig.run(0.06)
    assert_all_off(rig, Fault.ID_MISMATCH)
    assert rig.levels(leg) == [False, True, False]


def test_squal_dip_shorter_than_squal_low_s_is_tolerated(make_rig) -> None:
    rig = make_rig(TRAJ, limits=HealthLimits(squal_min=10, squal_low_s=0.05))
    leg = run_until_locked(rig)
    rig.fake.fault = FakeFault.SQUAL_DROP
    rig.run(0.03)
    rig.fake.fault = None
    rig.run(0.01)
    assert rig.events("fault") == []
    assert rig.pin(leg).state is True


def test_clutch_held_too_long(make_rig) -> None:
    # One stance and no next touchdown: the clutch would stay on forever.
    traj = GaitTrajectory(start_s=0.1, step_period_s=0.4, steps=1)
    rig = make_rig(traj, max_hold_s=0.3)
    leg = run_until_locked(rig)
    t_on = rig.clock.t
    rig.run(0.5)
    assert_all_off(rig, Fault.CLUTCH_TIMEOUT)
    assert rig.levels(leg) == [False, True, False]
    t_fault = rig.events("fault")[0].t_ns * 1e-9
    assert 0.3 <= t_fault - t_on <= 0.3 + 2 / rig.rate_hz


def test_disarm_releases(make_rig) -> None:
    rig = make_rig(TRAJ)
    leg = run_until_locked(rig)
    rig.controller.disarm()
    assert rig.levels(leg) == [False, True, False]
    rig.run(1.0)  # detections continue, but nothing switches
    assert len(rig.events("lock")) >= 2
    assert rig.levels(leg) == [False, True, False]
    assert all(rig.pin(k).state is False for k in range(8))


def test_rearm_clears_a_fault_and_works_again(make_rig) -> None:
    rig = make_rig(TRAJ)
    run_until_locked(rig)
    rig.fake.fault = FakeFault.SQUAL_DROP
    rig.run(0.1)
    rig.fake.fault = None
    rig.controller.arm()
    assert rig.controller.active_faults == {}
    run_until_locked(rig)


def test_exception_in_the_control_thread_releases_the_clutch(make_rig) -> None:
    rig = make_rig(TRAJ)
    leg = run_until_locked(rig)
    ctl: Controller = rig.controller

    def boom() -> None:
        raise RuntimeError("bug in the control path")

    ctl.step = boom  # type: ignore[method-assign]
    sampler = Sampler(ctl, rate_hz=200.0, max_samples=10)
    sampler.start()
    sampler.join(5.0)
    with pytest.raises(RuntimeError, match="bug in the control path"):
        sampler.done.result(timeout=1)
    assert rig.levels(leg) == [False, True, False]
    assert [e.fields["fault"] for e in rig.events("fault")] == ["exception"]
