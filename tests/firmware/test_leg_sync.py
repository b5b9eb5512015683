"""The stance leg is trustworthy: a missed or extra touchdown is a fault that releases everything and
disarms until the operator names the leg on the ground; re-arming mid-walk keeps the count; the
configured start leg is the one standing at arm time."""

from __future__ import annotations

import pytest

from rimless.firmware.detector import DetectorParams, LegDetector
from rimless.firmware.fake_adns3080 import GaitTrajectory
from rimless.firmware.faults import Fault

TRAJ = GaitTrajectory(start_s=0.1, step_period_s=0.4, compression_m=0.008, compression_s=0.06)


def without_step(traj: GaitTrajectory, skipped: int):
    """The gait with step `skipped` unseen by the sensor (a missed touchdown)."""

    def f(t: float) -> float:
        k = int((t - traj.start_s) // traj.step_period_s) if t >= traj.start_s else -1
        return 0.0 if k == skipped else traj(t)

    return f


def with_bounce(traj: GaitTrajectory, step: int, after_s: float):
    """The gait plus a second, smaller compression `after_s` after touchdown `step` (an extra touchdown)."""
    bounce = GaitTrajectory(start_s=traj.touchdown_s(step) + after_s, step_period_s=10.0, compression_m=0.004,
                            compression_s=0.03, steps=1)
    return lambda t: traj(t) + bounce(t)


def engaged_legs(rig) -> list[int]:
    return [leg for leg in range(8) if True in rig.levels(leg)]


def test_missed_touchdown_is_a_fault_that_releases_everything(make_rig) -> None:
    rig = make_rig(without_step(TRAJ, 3))
    rig.run(TRAJ.touchdown_s(5) + 0.2)
    faults = [e for e in rig.events("fault") if e.fields["fault"] == Fault.LEG_SYNC_LOST.value]
    assert len(faults) == 1 and "missed touchdown" in faults[0].fields["detail"]
    t_fault = faults[0].t_ns * 1e-9
    # Found before the next seen touchdown (which a dead-reckoned count would have given to leg 3).
    assert TRAJ.touchdown_s(2) + 0.4 < t_fault < TRAJ.touchdown_s(4)
    assert engaged_legs(rig) == [0, 1, 2]  # leg 3 (the wrong one for touchdown 4) never clutched
    assert all(rig.pin(leg).state is False for leg in range(8))
    assert not rig.controller.armed
    assert rig.levels(2) == [False, True, False]  # released by the fault
    st = rig.controller.status()
    assert st["channels"][0]["synchronised"] is False


def test_extra_touchdown_is_a_fault(make_rig) -> None:
    rig = make_rig(with_bounce(TRAJ, 2, 0.15))
    rig.run(TRAJ.touchdown_s(4))
    details = [e.fields["detail"] for e in rig.events("fault") if e.fields["fault"] == Fault.LEG_SYNC_LOST.value]
    assert len(details) == 1 and "extra touchdown" in details[0]
    assert all(rig.pin(leg).state is False for leg in range(8))
    assert engaged_legs(rig) == [0, 1, 2]


def test_after_a_sync_fault_arm_needs_the_stance_leg_and_then_clutches_the_right_one(make_rig) -> None:
    rig = make_rig(without_step(TRAJ, 3))
    rig.run(TRAJ.touchdown_s(4) + 0.01)
    with pytest.raises(ValueError, match="stance_leg"):
        rig.controller.arm()
    assert not rig.controller.armed
    # Touchdown 4 happened: the leg on the ground is leg 4 of the real gait.
    rig.controller.arm(stance_leg=4)
    rig.run(TRAJ.touchdown_s(6) - TRAJ.touchdown_s(4) - 0.01 + 0.2)
    assert engaged_legs(rig) == [0, 1, 2, 5, 6]
    with pytest.raises(ValueError, match="not a leg"):
        rig.controller.arm(stance_leg=9)


def test_rearming_mid_walk_keeps_the_count(make_rig) -> None:
    rig = make_rig(TRAJ)
    rig.run(TRAJ.touchdown_s(2) + 0.2)  # legs 0, 1, 2 clutched in turn
    rig.controller.disarm()
    rig.controller.arm()  # no stance_leg: carry on counting
    rig.run(0.4)
    assert engaged_legs(rig) == [0, 1, 2, 3]
    assert rig.events("fault") == []


def test_start_leg_index_is_the_leg_standing_at_arm_time(make_rig) -> None:
    rig = make_rig(TRAJ, start_index=2)  # leg 2 stands: the first touchdown is leg 3's
    rig.run(TRAJ.touchdown_s(0) + 0.2)
    assert engaged_legs(rig) == [3]


def test_step_bounds_follow_the_running_period() -> None:
    det = LegDetector(DetectorParams(), list(range(8)))
    assert det.counted and not LegDetector(DetectorParams(), [5]).counted
    with pytest.raises(ValueError, match="step_period_tolerance"):
        DetectorParams(step_period_tolerance=1.5).validated()
    with pytest.raises(ValueError, match="max_step_s"):
        DetectorParams(max_step_s=0.05).validated()


def test_a_slowing_gait_within_tolerance_keeps_sync(make_rig) -> None:
    # Step periods 0.40, 0.44, 0.48, ...: each within 40 % of the running period.
    starts = [0.1]
    for k in range(6):
        starts.append(starts[-1] + 0.4 + 0.04 * k)

    def traj(t: float) -> float:
        return sum(GaitTrajectory(start_s=s, step_period_s=10, steps=1)(t) for s in starts)

    rig = make_rig(traj)
    rig.run(starts[-1] + 0.2)
    assert rig.events("fault") == []
    assert engaged_legs(rig) == list(range(7))
