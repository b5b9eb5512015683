"""The stance leg is trustworthy: a missed or extra touchdown is a fault that releases everything and
disarms until the operator names the leg on the ground; re-arming mid-walk keeps the count; the
configured start leg is the one standing at arm time."""

from __future__ import annotations

import math

import pytest

from rimless.firmware.control.detector import DetectorParams, LegDetector
from rimless.firmware.control.faults import Fault
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory

TRAJ = GaitTrajectory(start_s=0.1, step_period_s=0.4, compression_m=0.008, compression_s=0.06)


def without_step(traj: GaitTrajectory, skipped: int):
    """The gait with step `skipped` unseen by the sensor (a missed touchdown)."""

    def f(t: float) -> float:
        k = int((t - traj.start_s) // traj.step_period_s) if t >= traj.start_s else -1
        return 0.0 if k == skipped else traj(t)

    return f


def with_bounce(traj: GaitTrajectory, step: int, after_s: float):
    """The gait plus a second, smaller compression `after_s` after touchdown `step` (an extra touchdown)."""
    bounce = GaitTrajectory(
        start_s=traj.touchdown_s(step) + after_s, step_period_s=10.0, compression_m=0.004, compression_s=0.03, steps=1
    )
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


def test_confirm_within_steps_leaves_a_clean_resync_its_touchdowns() -> None:
    """The bound on unconfirmed touchdowns is off (0) or leaves a clean (re)sync the confirm_steps + 2 touchdowns it
    needs (the first, the one measuring the period, then confirm_steps agreeing ones); `set` names it."""
    DetectorParams(confirm_steps=2, confirm_within_steps=4).validated()
    DetectorParams(confirm_steps=2, confirm_within_steps=0).validated()
    with pytest.raises(
        ValueError, match=r"confirm_within_steps must be 0 \(off\) or an integer in confirm_steps \+ 2 \(4\)"
    ):
        DetectorParams(confirm_steps=2, confirm_within_steps=3).validated()
    with pytest.raises(ValueError, match="confirm_within_steps must be an integer"):
        DetectorParams().with_value("confirm_within_steps", 4.5)


def test_set_confirm_steps_names_the_parameter_set_and_the_one_to_set_first() -> None:
    """`set confirm_steps N` with N + 2 above the bound in force names confirm_steps (the one set) and says to set
    confirm_within_steps first, instead of a message about confirm_within_steps alone."""
    p = DetectorParams(confirm_steps=2, confirm_within_steps=5)
    assert p.with_value("confirm_steps", 3).confirm_steps == 3  # 3 + 2 <= 5
    with pytest.raises(ValueError) as err:
        p.with_value("confirm_steps", 10)
    msg = str(err.value)
    assert msg.startswith("confirm_steps = 10 is refused with confirm_within_steps = 5:")
    assert "confirm_steps + 2 (12)" in msg and msg.endswith("(set confirm_within_steps first)")
    assert p.with_value("confirm_within_steps", 0).with_value("confirm_steps", 10).confirm_steps == 10


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


# --- one sensor per leg: the trailing foot coming down again is not a step -----------------------------


def _per_leg_rig(trajectories, rate_hz: float = 300.0):
    """Eight channels (one fake sensor per leg, legs = [k]) on one virtual clock, armed with leg 7 standing."""
    from gpiozero.pins.mock import MockFactory

    from rimless.firmware.control.controller import Channel, Controller
    from rimless.firmware.control.faults import HealthLimits, HealthMonitor
    from rimless.firmware.drivers.adns3080 import Adns3080
    from rimless.firmware.drivers.clutch import ClutchBank
    from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080
    from tests.support.firmware_rig import PINS, Rig, VirtualClock

    clock = VirtualClock()
    channels, fakes = [], []
    for k, traj in enumerate(trajectories):
        fake = FakeAdns3080(traj, clock=clock, noise_counts=0.3, seed=k)
        fakes.append(fake)
        drv = Adns3080(
            fake, counts_per_m=DEFAULT_COUNTS_PER_M, reset=fake.set_reset, sleep=clock.sleep, clock_ns=clock.ns
        )
        drv.power_up()
        drv.set_resolution(1600)
        channels.append(Channel(drv, LegDetector(DetectorParams(), [k]), HealthMonitor(HealthLimits())))
    factory = MockFactory(revision="c03111")
    bank = ClutchBank(PINS, pin_factory=factory)
    clock.t = 0.0
    ctl = Controller(channels, bank, id_check_interval_s=0.0, clock_ns=clock.ns)
    ctl.arm(stance_leg=7)
    return Rig(clock, fakes[0], channels[0].sensor, ctl, factory, rate_hz), bank


def _leg_view(traj: GaitTrajectory, leg: int, recontact_after_s: float | None):
    """Leg `leg`'s sensor: its own stances (legs touch down in order 0, 1, ...), and, as trailing leg, its foot
    coming down again `recontact_after_s` after the next leg's touchdown (a 3 mm, 30 ms compression)."""

    def f(t: float) -> float:
        if t < traj.start_s:
            return 0.0
        k = int((t - traj.start_s) // traj.step_period_s)
        x = traj(t) if k % 8 == leg else 0.0
        if recontact_after_s is not None and k % 8 == (leg + 1) % 8:
            tau = t - traj.touchdown_s(k) - recontact_after_s
            if 0.0 <= tau < 0.06:
                x += 0.003 * math.sin(math.pi * tau / 0.06)
        return x

    return f


@pytest.mark.parametrize("after_s", [0.05, 0.15])
def test_per_leg_sensors_do_not_take_the_trailing_foot_for_a_step(after_s) -> None:
    """Each leg clutched once, at its own stance, and released at the next touchdown; the trailing foot
    coming down again (inside min_step_s of the step, or later) is dismissed, and clutches nothing."""
    rig, bank = _per_leg_rig([_leg_view(TRAJ, k, after_s) for k in range(8)])
    try:
        rig.run(TRAJ.touchdown_s(4) + 0.05)
        hist = {k: "".join("1" if s else "0" for s in rig.levels(k)) for k in range(8)}
        assert [hist[k] for k in range(4)] == ["010"] * 4, hist  # legs 0..3 stanced and released
        assert hist[4] == "0" and all(hist[k] == "0" for k in range(5, 8)), hist
        touch = [e.fields["channel"] for e in rig.events("touchdown")]
        assert touch == [0, 1, 2, 3, 4]
        dismissed = rig.events("touchdown_dismissed")
        # each trailing foot once (leg 7 stood at arm time; leg 3 comes down again after the run ends)
        assert [e.fields["channel"] for e in dismissed] == [7, 0, 1, 2]
        why = "too soon after the last step" if after_s < DetectorParams().min_step_s else "the trailing leg's"
        assert all(e.fields["why"] == why for e in dismissed)
        assert not rig.events("fault") and rig.controller.armed
    finally:
        bank.close()
        rig.factory.close()


def test_dismissing_a_touchdown_restores_the_count() -> None:
    det = LegDetector(DetectorParams(), [0, 1, 2])
    t_ns = 0
    for k in range(40):  # quiet, then a compression that reads as a touchdown
        t_ns = k * 3_333_333
        dec = det.update(t_ns, 0.0 if k < 10 else 0.0004)
        if "touchdown" in dec.events:
            break
    assert det.stance_leg == 1
    det.dismiss_touchdown()
    assert det.stance_leg == 0 and det.phase.value == "wait" and det.synced
