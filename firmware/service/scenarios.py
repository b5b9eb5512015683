"""The fault scenarios of `rimless robot run --fake --fake-fault NAME`: a scripted walk (with its truth, so
that every lock can be judged) and a fault injected into the fake sensor at a set time after start.

- `missed-first-touchdown`: the first step compresses 0.4 mm (peak 10 mm/s, under `touch_velocity_m_s`);
- `first-step-bounce`: the first foot comes down again 140 ms after its touchdown (a bounce, not a step);
- `brown-out`: the sensor resets itself 2.5 s after start (registers back to 400 cpi);
- `wrong-product-id`: Product_ID reads 0x00 from 2.5 s after start (nothing on the bus);
- `loop-stall`: the event loop is blocked for 4 s from 2.5 s after start (the watchdog thread releases);
- `log-disk-full`: a trial log runs from the start, and its disk fills 2.5 s after start: one write is cut
  short, every later one fails with ENOSPC (logging degrades, the walk goes on);
- `wrong-start-leg`: the wheel stands on the leg `WRONG_START_OFFSET` (3) after the configured
  `[clutch] start_leg_index` (a plain walk): the configured start leg is wrong, only a leg named at arm is right.

"Start" is the moment the app runs (`on_ready`: the sampler samples, the controller is armed when asked), not
the moment the scenario is made: a loaded machine may take seconds to get there, and a walk that began
before the robot looked would be a step no robot could have seen, not a fault of the firmware. The walk and the
sensor faults count on the scenario's clock: the fakes' `VirtualClock` in `robot run --fake`, whose time does
not move before the sampler's first deadline, so there the start is that deadline (`Timeline.start` before the
app runs) and every sample sees the walk at its own deadline whatever the load. The loop stall and the full disk
strike on the wall clock (they are about the event loop and the disk).
"""

from __future__ import annotations

import errno
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from rimless.firmware.clock import Clock, MonotonicClock, seconds
from rimless.firmware.drivers.fake_adns3080 import FakeAdns3080, FakeFault
from rimless.firmware.drivers.fake_walk import FakeWalk

LOOP_STALL_S = 4.0
WRONG_START_OFFSET = 3  # `wrong-start-leg`: the true start leg, counted in `legs` from the configured one
FAULT_AT_S = 2.5  # when the timed faults strike, after start (s): a clutch is engaged then


class Timeline:
    """A scenario's time origin (s on `clock` as `seconds` reads it, the monotonic clock by default): None until
    `start()`, called
    once the app runs (or, on a virtual clock, before: its time does not move until the sampler's first
    deadline)."""

    def __init__(self, clock: Clock | None = None) -> None:
        self.clock: Clock = clock if clock is not None else MonotonicClock()
        self.now_s = seconds(self.clock)
        self.origin_s: float | None = None

    def start(self) -> None:
        if self.origin_s is None:
            self.origin_s = self.now_s()


class ScenarioWalk:
    """The fake's trajectory: the leg rests until the timeline starts, then walks `template` (whose `start_s`
    counts from the timeline's origin). `walk` is that walk on the fake's clock (None before the start)."""

    def __init__(self, template: FakeWalk, timeline: Timeline) -> None:
        self.template = template
        self.timeline = timeline
        self._walk: FakeWalk | None = None

    @property
    def walk(self) -> FakeWalk | None:
        if self._walk is None and self.timeline.origin_s is not None:
            self._walk = replace(self.template, start_s=self.timeline.origin_s + self.template.start_s)
        return self._walk

    def __call__(self, t: float) -> float:
        walk = self.walk
        return 0.0 if walk is None else walk(t)


@dataclass(frozen=True)
class Scenario:
    """A walk for every fake sensor and, optionally, an action on each fake at `fault_at_s` after start; both
    count from `timeline`'s origin (set by `on_ready`)."""

    name: str
    template: FakeWalk  # start_s counts from the start
    fault: Callable[[FakeAdns3080], None] | None = None
    fault_at_s: float = FAULT_AT_S
    stall_loop_s: float = 0.0  # block the event loop this long at `fault_at_s` after start
    disk_full: bool = False  # run a trial log whose disk fills at `fault_at_s` after start
    start_leg_offset: int = 0  # the leg on the ground at start: this many legs after the configured start leg
    timeline: Timeline = field(default_factory=Timeline)
    motion: ScenarioWalk = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "motion", ScenarioWalk(self.template, self.timeline))

    @property
    def walk(self) -> FakeWalk | None:
        """The walk on the fake's clock, once started (the truth of every lock)."""
        return self.motion.walk


def _wrong_id(fake: FakeAdns3080) -> None:
    fake.fault = FakeFault.WRONG_ID


def _brownout(fake: FakeAdns3080) -> None:
    fake.brownout()


def _walks(start_s: float) -> dict[str, tuple[FakeWalk, Callable[[FakeAdns3080], None] | None]]:
    plain = FakeWalk(start_s=start_s)
    return {
        "none": (plain, None),
        "missed-first-touchdown": (FakeWalk(start_s=start_s, first_compression_m=0.0004), None),
        "first-step-bounce": (FakeWalk(start_s=start_s, bounce_after_s=0.14), None),
        "brown-out": (plain, _brownout),
        "wrong-product-id": (plain, _wrong_id),
        "loop-stall": (plain, None),
        "log-disk-full": (plain, None),
        "wrong-start-leg": (plain, None),
    }


FAKE_FAULTS: tuple[str, ...] = tuple(n for n in _walks(0.0) if n != "none")


def scenario(name: str | None, *, lead_s: float = 1.0, clock: Clock | None = None) -> Scenario:
    """The scenario `name` (None: a plain walk), its first touchdown `lead_s` after the start, on `clock` (None:
    the monotonic clock); ValueError names the known ones."""
    walks = _walks(lead_s)
    key = name or "none"
    if key not in walks:
        raise ValueError(f"unknown fake fault {name!r}; known: {', '.join(FAKE_FAULTS)}")
    walk, fault = walks[key]
    return Scenario(
        key,
        walk,
        fault,
        stall_loop_s=LOOP_STALL_S if key == "loop-stall" else 0.0,
        disk_full=key == "log-disk-full",
        start_leg_offset=WRONG_START_OFFSET if key == "wrong-start-leg" else 0,
        timeline=Timeline(clock),
    )


class DiskFullWrite:
    """`os.write` on a disk that fills at `at_monotonic_s`: the first write after it is cut short, every
    later one raises ENOSPC."""

    def __init__(self, at_monotonic_s: float) -> None:
        self.at_s = at_monotonic_s
        self.short_done = False

    def __call__(self, fd: int, data: Any) -> int:
        if time.monotonic() < self.at_s:
            return os.write(fd, data)
        if not self.short_done and len(data) > 1:
            self.short_done = True
            return os.write(fd, bytes(data[: len(data) // 2]))
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


_TASKS: set[Any] = set()


def on_ready(sc: Scenario, app: Any) -> None:
    """In the running event loop, once the app runs: block the loop (`stall_loop_s`) or start a trial log on
    a disk that fills (`disk_full`) at `sc.fault_at_s`."""
    import asyncio

    sc.timeline.start()
    loop = asyncio.get_running_loop()
    if sc.stall_loop_s > 0:
        loop.call_later(sc.fault_at_s, time.sleep, sc.stall_loop_s)
    if sc.disk_full:
        app.trial_log_write = DiskFullWrite(time.monotonic() + sc.fault_at_s)
        task = loop.create_task(app.start_trial(f"fake-{sc.name}"))
        _TASKS.add(task)
        task.add_done_callback(_TASKS.discard)


class ScheduledFaultBus:
    """The fake's bus, applying `action(fake)` once at the first message from `after_s` after the timeline's
    start on (on the timeline's clock)."""

    def __init__(
        self, fake: FakeAdns3080, timeline: Timeline, after_s: float, action: Callable[[FakeAdns3080], None]
    ) -> None:
        self.fake = fake
        self.timeline = timeline
        self.after_s = after_s
        self.action: Callable[[FakeAdns3080], None] | None = action

    def message(self, segments: Any) -> list[bytes]:
        origin = self.timeline.origin_s
        if self.action is not None and origin is not None and self.timeline.now_s() >= origin + self.after_s:
            action, self.action = self.action, None
            action(self.fake)
        return self.fake.message(segments)

    def close(self) -> None:
        self.fake.close()


def inject(sc: Scenario, sensors: Sequence[Any], fakes: Sequence[FakeAdns3080]) -> None:
    """Put the scenario's timed fault between each sensor driver and its fake (sensors on a GPIO chip select
    keep their wrapper and get the fault inside it)."""
    if sc.fault is None:
        return
    for sensor, fake in zip(sensors, fakes, strict=True):
        bus = ScheduledFaultBus(fake, sc.timeline, sc.fault_at_s, sc.fault)
        if hasattr(sensor.bus, "cs"):  # GpioChipSelectBus
            sensor.bus.bus = bus
        else:
            sensor.bus = bus
