"""The hardware assembly on fakes: one sensor per leg with GPIO chip selects clutches the leg it measures,
sensors sharing a RESET line each get NPD and one pulse."""

from __future__ import annotations

import asyncio
import dataclasses
import time

from rimless.firmware.drivers.fake_adns3080 import GaitTrajectory
from rimless.firmware.service.config import RobotConfig, SensorConfig
from tests.support.firmware_app import config


def leg_view(walk: dict, leg: int, legs: int = 8, steps: int | None = None):
    """What the sensor of `leg` sees: only the stances of that leg (every `legs`-th step) of `walk["traj"]`
    (nothing until it is set), and only among the first `steps` steps when given."""

    def f(t: float) -> float:
        traj = walk.get("traj")
        if traj is None or t < traj.start_s:
            return 0.0
        k = int((t - traj.start_s) // traj.step_period_s)
        return traj(t) if k % legs == leg and (steps is None or k < steps) else 0.0

    return f


CS_PINS = (2, 3, 4, 5, 6, 12, 13, 19)


def per_leg_config(tmp_path) -> RobotConfig:
    base = config(tmp_path)
    sensors = tuple(SensorConfig(spi_device=0, cs_pin=cs, legs=(k,)) for k, cs in enumerate(CS_PINS))
    return dataclasses.replace(base, sensors=sensors)


def _walk_until_leg_3_holds(cfg: RobotConfig):
    """Run the app on fakes with one sensor per leg while the fake walks; returns the run's summary and the
    hardware."""
    from rimless.firmware.service.app import RobotApp
    from rimless.firmware.service.hardware import build_fake

    walk: dict = {}
    hw = build_fake(cfg, trajectories=[leg_view(walk, k) for k in range(8)])

    async def stop_once_leg_3_holds(app) -> None:
        # A condition, not a delay: a loaded machine (CI at load 6) pauses the loop for tenths of a second.
        leg3 = hw.pin_factory.pin(cfg.clutch.pins[3])
        deadline = time.monotonic() + 30.0
        while not leg3.state and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        app.request_stop("test done")

    async def walk_then_stop(app) -> None:
        # The walk starts once the control loop samples (a loaded machine may take long to start it); the app
        # stops once leg 3 holds. The walk goes on meanwhile, so a late stop still sees every lock released by
        # the next touchdown (a walk that ended after leg 3 left its lock to max_hold_s: clutch_timeout in a CI
        # run).
        deadline = time.monotonic() + 30.0
        while app.controller.samples < 30 and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        walk["traj"] = GaitTrajectory(
            start_s=time.monotonic() + 0.15, step_period_s=0.3, compression_m=0.008, compression_s=0.06
        )
        await stop_once_leg_3_holds(app)

    def ready(app) -> None:
        walk["stopper"] = asyncio.get_running_loop().create_task(walk_then_stop(app))

    async def main():
        app = RobotApp(cfg, hw, on_ready=ready)
        return await app.run(duration_s=30, arm=True, handle_signals=False)

    return asyncio.run(main()), hw


def test_one_sensor_per_leg_with_gpio_chip_selects_clutches_the_measured_leg(tmp_path) -> None:
    """Each stance lasts 60 ms of compression, sampled on the wall clock in this process: a loop that missed
    its deadlines through one (a loaded test machine; at load 6 one run in two) sees no stance there, and that
    leg does not lock (then the walk goes round again until leg 3 holds). A run whose loop missed deadlines and
    whose legs 0..3 did not lock once each is started again (at most three runs)."""
    cfg = per_leg_config(tmp_path)
    for _attempt in range(3):
        summary, hw = _walk_until_leg_3_holds(cfg)
        assert summary.faults == [] and summary.error is None
        hist = {
            k: "".join("1" if s.state else "0" for s in hw.pin_factory.pin(p).states)
            for k, p in enumerate(cfg.clutch.pins)
        }
        if summary.missed_deadlines == 0 or all(hist[k] == "010" for k in range(4)):
            break
    for k in range(4):  # legs 0..3 stanced once each, released at the next leg's touchdown (or at the stop)
        assert hist[k] == "010", (hist, summary.missed_deadlines)
    # legs 4..7: not yet in stance at the stop, or (a stop delayed by a loaded machine) locked once and released
    assert all(hist[k] in ("0", "010") for k in range(4, 8)), hist
    assert hist[7] == "0", hist  # the stop came within a walk round
    for cs in CS_PINS:  # every chip select idles high and was pulled low for transfers
        states = [s.state for s in hw.pin_factory.pin(cs).states]
        assert states[-1] is True and False in states[1:]


def test_sensors_sharing_a_reset_line_each_get_npd_and_one_pulse(tmp_path) -> None:
    from rimless.firmware.service.hardware import build_fake

    base = config(tmp_path)
    sensors = (
        SensorConfig(spi_device=0, legs=(0, 1, 2, 3), npd_pin=5),
        SensorConfig(spi_device=1, legs=(4, 5, 6, 7), npd_pin=6),
    )
    hw = build_fake(dataclasses.replace(base, sensors=sensors))
    try:
        assert [f.resets for f in hw.fakes] == [1, 1] and all(f.powered for f in hw.fakes)
        reset = [s.state for s in hw.pin_factory.pin(25).states]
        assert reset == [False, True, False]  # one pulse on the shared line
        assert all(hw.pin_factory.pin(p).state is True for p in (5, 6))
        assert [s.verify_id() for s in hw.sensors] == [1, 1]
    finally:
        hw.close()


def test_release_clutches_reports_the_off_level_of_the_configuration() -> None:
    from rimless.firmware.service.config import ClutchConfig
    from rimless.firmware.service.hardware import release_clutches

    report = release_clutches(RobotConfig(), fake=True)
    js = report.to_json()
    assert js["released_pins"] == list(RobotConfig().clutch.pins) and js["level"] == "low"
    assert all(set(h) == {"0"} for h in js["fake_levels"].values())
    low = release_clutches(RobotConfig(clutch=ClutchConfig(active_high=False)), fake=True)
    assert low.off_level == "high" and "fake_levels" in low.to_json()
    assert "fake_levels" not in dataclasses.replace(report, fake_levels=None).to_json()
