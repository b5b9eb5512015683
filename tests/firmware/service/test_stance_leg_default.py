"""The robot's defaults never trust a configured start leg (issue 32 item 1, "a wrong start_leg_index: 11 of 11").

The whole app (`RobotApp`) on the fake sensor and mock pins on a virtual clock, with `RobotConfig()`'s detector
(the robot's defaults, no setting changed) and one sensor counting eight legs. The fake walk stands on leg 0 at
start, while `[clutch] start_leg_index` says 3. The truth of every engage comes from the walk's own geometry
(`FakeWalk.stance_leg`), never from the detector. Armed without naming the stance leg (`RobotApp.run(arm=True)`,
what `robot run --arm` did before `--stance-leg` and what a remote `arm` without `--stance-leg` does), nothing
locks; on main before `named_stance_required` became a robot default, every lock held a leg in the air (measured
there: 9 of 9). Named at arm, the same walk locks its stance legs, so the first result is not a walk that could
not lock anyway."""

from __future__ import annotations

import asyncio
import dataclasses
from pathlib import Path

from rimless.firmware.clock import VirtualClock, seconds
from rimless.firmware.control.controller import EventRecord
from rimless.firmware.drivers.fake_walk import FakeWalk, airborne_locks
from rimless.firmware.drivers.gpio import PinLog
from rimless.firmware.service.app import RobotApp
from rimless.firmware.service.config import ROBOT_DETECTOR, ClutchConfig, RobotConfig
from rimless.firmware.service.hardware import build_fake
from tests.support.firmware_app import config

TRUE_START_INDEX = 0  # the fake walk's leg on the ground at start (legs 0..7, the default sensor's)
CONFIGURED_START_INDEX = 3  # what robot.toml says: wrong


def walk_and_judge(cfg: RobotConfig, tmp_path: Path, stance_leg: int | None, duration_s: float = 5.0):
    """Run the app armed at start (naming `stance_leg`, or not) for `duration_s` of virtual time over a fake walk
    from 0.3 s; return (engages (t_s, leg), the engages on a leg in the air, the event names)."""
    clock = VirtualClock()
    now_s = seconds(clock)
    pins = PinLog(tmp_path / f"pins-{stance_leg}.jsonl", clock=now_s)
    walk = FakeWalk(start_s=now_s() + 0.3)
    hw = build_fake(cfg, trajectory=walk, pin_log=pins, clock=clock)
    events: list[EventRecord] = []
    app = RobotApp(cfg, hw, event_sink=events)
    named = {} if stance_leg is None else {"stance_leg": stance_leg}  # without a name: main's call, to compare
    asyncio.run(app.run(duration_s=duration_s, arm=True, handle_signals=False, **named))
    pins.close()
    on = 1 if cfg.clutch.active_high else 0
    engages = sorted(
        (t, leg)
        for leg, pin in enumerate(cfg.clutch.pins)
        for t, p, level in pins.transitions
        if p == pin and level == on
    )
    legs = cfg.sensors[0].legs
    return engages, airborne_locks(walk, engages, legs, TRUE_START_INDEX), [e.name for e in events]


def test_the_robot_defaults_lock_no_leg_in_the_air_from_a_wrong_configured_start_leg(tmp_path) -> None:
    cfg = config(tmp_path, commands=dataclasses.replace(config(tmp_path).commands, enabled=False))
    cfg = dataclasses.replace(cfg, clutch=ClutchConfig(start_leg_index=CONFIGURED_START_INDEX))
    assert cfg.detector == RobotConfig().detector == ROBOT_DETECTOR  # the robot's defaults, nothing changed
    assert len(cfg.sensors) == 1 and len(cfg.sensors[0].legs) == 8  # one sensor counting the legs

    engages, airborne, names = walk_and_judge(cfg, tmp_path, stance_leg=None)
    assert airborne == [] and engages == []
    assert "lock_withheld" in names and "touchdown" in names  # it walked, and each lock was withheld

    # the same walk, the leg on the ground named at arm: it locks, on the stance legs only
    true_leg = cfg.sensors[0].legs[TRUE_START_INDEX]
    engages, airborne, _ = walk_and_judge(cfg, tmp_path, stance_leg=true_leg)
    assert airborne == [] and len(engages) >= 5  # touchdowns at 0.3 + 0.4 k s; the first lock at the 4th
