"""No lock on a leg in the air, whatever the walk: a hypothesis property over the fake walk on the virtual clock
(`rimless.firmware.clock.VirtualClock`), one register-level fake ADNS-3080 counting eight legs, the robot's
detector defaults. The truth of which leg stands comes from the walk's own geometry (`FakeWalk.stance_leg`),
never from the detector. Plus one test per scenario of issue 32 item 1, each of which locked an airborne leg on
main before this change (measured there: a gentle first step 9 of 9 locks airborne, a first-step bounce at
0.20-0.25 s 1 airborne lock, a mid-walk bounce at 60-90 % 1 airborne lock, a wrong start leg 9 of 9)."""

from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rimless.firmware.control.controller import EventRecord
from rimless.firmware.control.detector import DetectorParams
from rimless.firmware.drivers.fake_walk import FakeWalk, airborne_locks
from rimless.firmware.service.config import ROBOT_DETECTOR
from tests.support.fake_walk_rig import LEGS, FakeWalkRig


@dataclasses.dataclass
class Run:
    engages: list[tuple[float, int]]
    events: list[tuple[float, str, dict]]
    airborne: list[tuple[float, int, int]]
    pins_high_after_stop: list[int]

    def names(self) -> list[str]:
        return [n for _t, n, _f in self.events]


def run_walk(
    walk: FakeWalk,
    params: DetectorParams = ROBOT_DETECTOR,
    *,
    rate_hz: float = 300.0,
    duration_s: float = 3.0,
    true_start_index: int = 0,
    configured_start_index: int | None = None,
    named: bool = True,
    noise_counts: float = 0.3,
    seed: int = 0,
) -> Run:
    """Arm at t = 0 (naming the true stance leg when `named`, else trusting `configured_start_index`), sample at
    `rate_hz` on a virtual clock for `duration_s`, stop; every engage judged against the walk's truth."""
    start = true_start_index if configured_start_index is None else configured_start_index
    engages: list[tuple[float, int]] = []
    events: list[tuple[float, str, dict]] = []
    with FakeWalkRig(walk, params, start_index=start, noise_counts=noise_counts, seed=seed) as rig:
        ctl = rig.controller
        ctl.arm(stance_leg=LEGS[true_start_index] if named else None)
        for t, engaged, records in rig.drive(rate_hz, duration_s):
            engages += [(t, leg) for leg in engaged]
            events += [(t, rec.name, rec.fields) for rec in records if isinstance(rec, EventRecord)]
        ctl.safe_stop("end of run")
        high = rig.pins_high()
    return Run(engages, events, airborne_locks(walk, engages, LEGS, true_start_index), high)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    first_compression_m=st.one_of(st.floats(0.00005, 0.002), st.none()),  # None: a first step like the others
    bounce_step=st.integers(0, 6),
    bounce_fraction=st.floats(0.0, 0.999),
    bounce_compression_m=st.floats(0.0005, 0.006),
    bounce_peak_s=st.floats(0.01, 0.06),
    start_index=st.integers(0, 7),
    rate_hz=st.floats(100.0, 1000.0),
    noise_counts=st.floats(0.0, 0.5),
    start_s=st.floats(0.3, 0.6),
    seed=st.integers(0, 2**16),
)
def test_no_walk_locks_a_leg_in_the_air_and_every_run_ends_released(
    first_compression_m,
    bounce_step,
    bounce_fraction,
    bounce_compression_m,
    bounce_peak_s,
    start_index,
    rate_hz,
    noise_counts,
    start_s,
    seed,
) -> None:
    walk = FakeWalk(
        start_s=start_s,
        first_compression_m=first_compression_m,
        bounce_step=bounce_step,
        bounce_after_s=bounce_fraction * 0.4,
        bounce_compression_m=bounce_compression_m,
        bounce_compression_s=bounce_peak_s,
    )
    run = run_walk(
        walk, rate_hz=rate_hz, duration_s=3.2, true_start_index=start_index, noise_counts=noise_counts, seed=seed
    )
    assert run.airborne == [], run.engages
    assert run.pins_high_after_stop == []


# --- the scenarios of issue 32 item 1, each one locked an airborne leg on main before this change ----------


@pytest.mark.parametrize("rate_hz", [300.0, 1000.0])
@pytest.mark.parametrize("first_compression_m", [0.0001, 0.00015, 0.0002, 0.00027])
def test_a_first_step_under_the_old_fixed_doubt_loses_the_count_before_any_lock(first_compression_m, rate_hz) -> None:
    walk = FakeWalk(start_s=0.3, first_compression_m=first_compression_m)
    run = run_walk(walk, rate_hz=rate_hz, duration_s=4.0)
    assert run.engages == [] and run.airborne == []
    assert "sync_lost" in run.names()
    t_lost = next(t for t, n, _f in run.events if n == "sync_lost")
    assert t_lost < walk.touchdown_s(1)  # before the next touchdown could be counted one off


@pytest.mark.parametrize("rate_hz", [300.0, 1000.0])
@pytest.mark.parametrize("bounce_after_s", [0.20, 0.22, 0.25])
def test_a_first_step_bounce_near_half_the_step_never_locks(bounce_after_s, rate_hz) -> None:
    walk = FakeWalk(start_s=0.3, bounce_after_s=bounce_after_s)
    run = run_walk(walk, rate_hz=rate_hz, duration_s=4.0)
    assert run.engages == [] and run.airborne == []
    assert "sync_lost" in run.names()


@pytest.mark.parametrize("rate_hz", [300.0, 1000.0])
@pytest.mark.parametrize("fraction", [0.6, 0.7, 0.8, 0.9, 0.95])
def test_a_mid_walk_bounce_late_in_the_step_does_not_move_the_count(fraction, rate_hz) -> None:
    walk = FakeWalk(start_s=0.3, bounce_step=5, bounce_after_s=fraction * 0.4)
    run = run_walk(walk, rate_hz=rate_hz, duration_s=4.0)
    assert run.airborne == []
    assert "sync_lost" not in run.names()
    assert [leg for t, leg in run.engages if t > walk.touchdown_s(6)]  # still walking, on the right legs


@pytest.mark.parametrize("configured", [1, 3, 7])
def test_a_wrong_start_leg_locks_nothing_until_the_operator_names_the_stance_leg(configured) -> None:
    """One sensor cannot tell the legs apart: with the robot's defaults (named_stance_required on, no setting
    changed) a configured start leg is never trusted, and naming the leg at arm walks on the right legs (fails on
    main before named_stance_required became a robot default: 9 of 9 locks on a leg in the air)."""
    walk = FakeWalk(start_s=0.3)
    params = ROBOT_DETECTOR
    run = run_walk(walk, params, duration_s=4.0, configured_start_index=configured, named=False)
    assert run.engages == [] and run.airborne == []
    assert "lock_withheld" in run.names()
    named = run_walk(walk, params, duration_s=4.0, configured_start_index=configured, named=True)
    assert named.airborne == [] and len(named.engages) >= 5


# --- one sensor per leg: the stance leg is the one measured compressing, whatever the operator names ----------


@pytest.mark.parametrize("named", [7, 3, 0, None])
def test_per_leg_sensors_lock_only_the_leg_measured_compressing(named) -> None:
    """Eight sensors, one per leg (legs touch down in order 0, 1, ... from 0.1 s; leg 7 stands before), the
    trailing foot coming down again 0.15 s after each step. Whichever leg the operator names at arm (the right
    one, 7, or a wrong one), every engage holds the leg the walk's truth has on the ground; a wrong one is found
    from the first measured step (fails before this change: the trailing foot of leg 7 was taken for a step
    and locked, and every step after it on the wrong leg)."""
    from tests.firmware.control.test_detector_leg_sync import TRAJ, _leg_view, _per_leg_rig

    rig, bank = _per_leg_rig([_leg_view(TRAJ, k, 0.15) for k in range(8)])
    try:
        if named is None:
            rig.controller.disarm()
            rig.controller.arm()
        else:
            rig.controller.arm(stance_leg=named)
        engages: list[tuple[float, int]] = []
        held: set[int] = set()

        def record(r) -> None:
            now = set(bank.engaged())
            engages.extend((r.clock.t, leg) for leg in sorted(now - held))
            held.clear()
            held.update(now)

        rig.run(TRAJ.touchdown_s(9) + 0.1, on_sample=record)

        def truth(t: float) -> int:
            return 7 if t < TRAJ.start_s else int((t - TRAJ.start_s) // TRAJ.step_period_s) % 8

        assert [(t, leg) for t, leg in engages if leg != truth(t)] == []
        faults = [e.fields for e in rig.events("fault")]
        if named in (7, None):
            assert faults == [] and len(engages) >= 9  # it walks, every step locked
        else:  # measured: the first step is leg 0's, not the one after the named leg
            assert [f["fault"] for f in faults] == ["leg_sync_lost"] and "named at arm is wrong" in faults[0]["detail"]
            assert engages == [] and not rig.controller.armed
            with pytest.raises(ValueError, match="stance_leg"):
                rig.controller.arm()
    finally:
        bank.close()
        rig.factory.close()
