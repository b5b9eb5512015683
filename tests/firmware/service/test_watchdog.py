"""The dead-man's chain outside the event loop: a blocked event loop releases every clutch while it stays
blocked (the design bound is `loop_stalled` 0.25 s + the watchdog period; the time is printed, not asserted: a
loaded machine runs the watchdog thread late), no clutch engages after the release, and the heartbeat pin stops
toggling; the control thread stalling trips it too. Fails on today's main: the stall and link checks lived in
the event loop, so the control thread went on clutching through the whole block. The watchdogs run on the wall
clock (as on the robot); the fakes on a virtual clock paced to it, and the block ends on events (the watchdog's
trip, then a count of control steps), never after a fixed time."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import pytest

from rimless.firmware.clock import VirtualClock, seconds
from rimless.firmware.control.faults import Fault
from rimless.firmware.control.watchdog import Watchdog
from rimless.firmware.drivers.fake_walk import FakeWalk
from rimless.firmware.drivers.gpio import PinLog
from rimless.firmware.service.app import EVENT_LOOP, WATCHDOG_PERIOD_S, RobotApp
from rimless.firmware.service.config import SamplingConfig
from rimless.firmware.service.hardware import build_fake
from tests.support.firmware_app import WATCHDOG_TEST_SAMPLING, config

CLUTCH_PINS = (17, 27, 22, 23, 24, 16, 20, 21)
HEARTBEAT = 18
#: control steps the block lasts past the watchdog's trip: at every step a healthy chain toggles the heartbeat,
#: and a touchdown (every 0.9 s, 300 steps per second) would engage a clutch
STEPS_AFTER_THE_TRIP = 400
HANG_GUARD_S = 120.0  # only a broken chain waits this long


def block(how: str, until: Callable[[], bool]) -> None:
    """Block the calling thread (the event loop) until `until()` holds: in a blocking call that releases the GIL
    ("sleep") or in pure Python busy work that keeps taking the GIL back ("busy")."""
    end = time.monotonic() + HANG_GUARD_S
    while not until():
        assert time.monotonic() < end, "the blocked event loop never saw the awaited event"
        if how == "sleep":
            time.sleep(0.01)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["sleep", "busy"])
def test_a_blocked_event_loop_releases_while_it_stays_blocked(tmp_path, how) -> None:
    # the watchdogs at 5 s until the block: a machine at load 10-20 paused the whole process for 0.3-1.3 s and
    # tripped the robot's bounds before the first engage; at the block the event loop's goes to the robot's
    cfg = config(tmp_path, sampling=SamplingConfig(stall_timeout_s=5.0, loop_stall_s=5.0))
    loop_stall_s = SamplingConfig().loop_stall_s  # the robot's bound (0.25 s)
    log = PinLog()  # on the monotonic clock, as t0 and t1 below
    clock = VirtualClock()
    # A slow walk (a touchdown every 0.9 s): the lock before the block is held ~0.84 s unless the watchdog acts.
    walk = FakeWalk(start_s=seconds(clock)() + 0.4, step_period_s=0.9)
    hw = build_fake(cfg, trajectory=walk, pin_log=log, clock=clock)

    async def main():
        ready = asyncio.Event()
        app = RobotApp(cfg, hw, on_ready=lambda a: ready.set())
        run = asyncio.create_task(
            app.run(duration_s=2 * HANG_GUARD_S, arm=True, handle_signals=False, stance_leg=cfg.configured_stance_leg())
        )
        await ready.wait()
        end = time.monotonic() + HANG_GUARD_S
        while not hw.clutches.engaged() and time.monotonic() < end:
            await asyncio.sleep(0.002)
        engaged = hw.clutches.engaged()
        tripped_at: list[int] = []

        def tripped_and_stepped_on() -> bool:  # the watchdog tripped, then the control thread went on stepping
            if not tripped_at and Fault.LOOP_STALLED in app.controller.active_faults:
                tripped_at.append(app.controller.samples)
            return bool(tripped_at) and app.controller.samples - tripped_at[0] >= STEPS_AFTER_THE_TRIP

        app.watchdog.add(EVENT_LOOP, loop_stall_s)  # fed now, with the robot's bound
        t0 = time.monotonic()
        block(how, tripped_and_stepped_on)  # the event loop blocked (as a hung callback would)
        t1 = time.monotonic()
        app.request_stop("test done")
        summary = await run
        return engaged, t0, t1, summary

    engaged, t0, t1, summary = asyncio.run(main())
    assert engaged, "no clutch engaged before the block"
    pin = CLUTCH_PINS[engaged[0]]
    offs = [t for t, p, level in log.transitions if p == pin and level == 0 and t >= t0]
    assert offs and offs[0] < t1, "not released while the event loop was blocked"
    release = offs[0]
    bound_ms = (loop_stall_s + WATCHDOG_PERIOD_S) * 1e3
    print(f"release {(release - t0) * 1e3:.1f} ms after the event loop blocked (design bound {bound_ms:.0f} ms)")
    assert "loop_stalled" in summary.faults
    # no clutch engaged while the loop was blocked, nor after the release (the controller is disarmed)
    assert not [t for t, p, level in log.transitions if p in CLUTCH_PINS and level == 1 and t0 < t < t1]
    assert [t for t, p, level in log.transitions if p in CLUTCH_PINS and level == 1 and t > release] == []
    # the heartbeat stopped over the control steps after the trip: the hardware monostable drops too (one toggle
    # may be past its health check already)
    beats = [t for t, p, _level in log.transitions if p == HEARTBEAT and release < t < t1]
    assert len(beats) <= 1, beats


def test_the_watchdog_trips_once_per_stall_and_recovers() -> None:
    """On a clock of its own: no dependence on how fast a loaded machine runs the test."""
    now = [0]
    trips: list[str] = []
    wd = Watchdog(lambda name, detail: trips.append(name), period_s=0.005, clock_ns=lambda: now[0])
    wd.add("a", 0.05)
    now[0] += 50_000_000  # at the deadline: still fed in time
    wd.check_now()
    assert wd.healthy and trips == []
    now[0] += 30_000_000
    wd.check_now()
    wd.check_now()
    assert trips == ["a"] and not wd.healthy
    wd.feed("a")
    wd.check_now()
    assert wd.healthy


def test_a_blocked_watchdog_thread_stops_the_heartbeat_releases_and_faults(tmp_path) -> None:
    """Fails before the watchdog's own liveness check: with the watchdog thread blocked, `healthy` stayed True
    and the control thread went on toggling the heartbeat (the hardware backstop never acted) with the clutch
    held. On a clock of the test's own: the control thread's steps and the watchdog's rounds are called here,
    one by one (no threads, no sleeps)."""
    from rimless.firmware.service.app import CONTROL_LOOP

    cfg = config(tmp_path, sampling=WATCHDOG_TEST_SAMPLING)
    log = PinLog()
    hw = build_fake(cfg, trajectory=lambda t: 0.0, pin_log=log)
    app = RobotApp(cfg, hw)
    now = [0]
    wd = app.watchdog = Watchdog(app._watchdog_trip, period_s=0.01, clock_ns=lambda: now[0], self_timeout_s=0.25)
    wd.add(CONTROL_LOOP, cfg.sampling.stall_timeout_s)

    def beats() -> int:
        return sum(1 for _t, p, _level in log.transitions if p == HEARTBEAT)

    def run_ms(ms: int, *, watchdog_runs: bool) -> None:  # the control thread at 1 kHz, the watchdog every 10 ms
        for i in range(ms):
            now[0] += 1_000_000
            app._on_sample()
            if watchdog_runs and i % 10 == 9:
                wd.check_now()

    try:
        run_ms(100, watchdog_runs=True)
        assert beats() >= 99 and not app.controller.active_faults
        hw.clutches.engage(0)
        app.controller.armed = True
        run_ms(250, watchdog_runs=False)  # the watchdog thread blocks: the bound (0.25 s) is not over yet
        assert hw.clutches.engaged() == [0] and not app.controller.active_faults
        held = beats()
        run_ms(20, watchdog_runs=False)  # past the bound: released, disarmed, reported, heartbeat stopped
        assert hw.clutches.engaged() == [] and not app.controller.armed
        assert list(app.controller.active_faults) == [Fault.WATCHDOG_STALLED]
        assert "watchdog thread" in app.controller.active_faults[Fault.WATCHDOG_STALLED]
        stopped = beats()
        assert stopped - held <= 11  # toggled until the bound, then never
        run_ms(500, watchdog_runs=False)
        assert beats() == stopped and hw.clutches.engaged() == []
        faults = [r for r in app.controller.outbox if getattr(r, "name", "") == "fault"]
        assert len(faults) == 1  # reported once
        run_ms(30, watchdog_runs=True)  # the watchdog runs again: the heartbeat resumes, the fault stays latched
        assert beats() > stopped and hw.clutches.engaged() == [] and not app.controller.armed
    finally:
        hw.close()
