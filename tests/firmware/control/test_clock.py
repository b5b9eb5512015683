"""The clock seam: the sampler thread on a virtual clock takes every sample at its deadline (exact count and
times, no missed deadline) and acts as a loop stepped by hand; the virtual clock moves only to the deadlines
it is asked for, paced to the wall clock or not."""

from __future__ import annotations

import time

from rimless.firmware.clock import MonotonicClock, VirtualClock, seconds, sleeper
from rimless.firmware.control.sampler import Sampler
from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory
from rimless.firmware.service.bench import detector_delays

TRAJ = GaitTrajectory(start_s=0.1, step_period_s=0.4, compression_m=0.008, compression_s=0.06)
RATE_HZ = 300.0
N = 300  # one second: touchdowns at 0.1, 0.5 and 0.9 s


def test_the_sampler_on_a_virtual_clock_samples_every_deadline(make_rig) -> None:
    rig = make_rig(TRAJ, rate_hz=RATE_HZ)
    sampler = Sampler(rig.controller, rate_hz=RATE_HZ, max_samples=N, clock=rig.clock)
    sampler.start()
    stats = sampler.done.result(timeout=120)  # a hang guard only
    sampler.join()
    assert stats.samples == N and stats.missed_deadlines == 0
    period_ns = round(1e9 / RATE_HZ)
    assert [r.t_ns for r in rig.samples()] == [k * period_ns for k in range(N)]
    assert (stats.started_ns, stats.stopped_ns) == (0, (N - 1) * period_ns)
    # the same walk stepped by hand, one period later (the sampler samples at its start, the rig a period on)
    by_hand = make_rig(TRAJ, rate_hz=RATE_HZ)
    by_hand.run(N / RATE_HZ)
    assert [rig.levels(leg) for leg in range(8)] == [by_hand.levels(leg) for leg in range(8)]
    assert rig.levels(0) == [False, True, False] and rig.levels(1) == [False, True, False]
    assert [e.fields["leg"] for e in rig.events("lock")] == [0, 1, 2]
    # every part of the delay on the detector's side, exact here (the bench measures it on the wall clock)
    lock_ms, touch_ms = detector_delays(rig.events("lock") + rig.events("touchdown"), TRAJ)
    print(f"lock after the peak {lock_ms} ms, touchdown seen after {touch_ms} ms")
    assert len(lock_ms) == 3 and all(abs(d) <= 1e3 / RATE_HZ for d in lock_ms), lock_ms  # within one sample
    assert len(touch_ms) == 3 and all(0.0 <= d <= 20.0 for d in touch_ms), touch_ms


def test_the_virtual_clock_moves_only_to_the_deadlines_asked_for() -> None:
    clock = VirtualClock(start_ns=5_000, paced=False)
    assert clock.now_ns() == 5_000
    clock.sleep_until(9_000)
    clock.sleep_until(7_000)  # a deadline passed: at once, and time never runs back
    assert clock.now_ns() == 9_000
    sleeper(clock)(0.5)
    assert clock.now_ns() == 9_000 + 500_000_000
    assert seconds(clock)() == (clock.now_ns() - 5_000) * 1e-9  # the fakes' seconds count from the start


def test_a_paced_virtual_clock_does_not_run_ahead_of_the_wall_clock() -> None:
    wall0 = time.monotonic_ns()
    clock = VirtualClock(slack_s=0.002)
    t0 = clock.now_ns()
    clock.sleep_until(t0 + 50_000_000)  # 50 ms ahead: it waits (a lower bound only: a loaded machine is later)
    assert clock.now_ns() == t0 + 50_000_000
    assert time.monotonic_ns() - wall0 >= 50_000_000 - 2_000_000


def test_the_monotonic_clock_returns_at_the_deadline_not_before() -> None:
    clock = MonotonicClock(spin_s=0.0003)
    deadline = clock.now_ns() + 5_000_000
    clock.sleep_until(deadline)
    assert time.monotonic_ns() >= deadline
