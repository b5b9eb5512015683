"""The hardware assembly on fakes: one sensor per leg with GPIO chip selects clutches the leg it measures,
sensors sharing a RESET line each get NPD and one pulse."""

from __future__ import annotations

import asyncio
import dataclasses

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


STEP_S = 0.3
RATE_HZ = 300.0  # the default [sampling] rate_hz
# legs k touch down at 0.15 + 0.3 k s after the first sample: stop 0.2 s after leg 3's touchdown (its lock
# 0.06 s after it), 0.1 s before leg 4's
RUN_SAMPLES = round((0.15 + 3 * STEP_S + 0.2) * RATE_HZ)


def _walk_to_leg_3(cfg: RobotConfig):
    """Run the app on fakes with one sensor per leg while the fake walks, for `RUN_SAMPLES` samples on a
    virtual clock (every sample at its deadline, however loaded the machine); returns the run's summary and the
    hardware."""
    from rimless.firmware.clock import VirtualClock, seconds
    from rimless.firmware.service.app import RobotApp
    from rimless.firmware.service.hardware import build_fake

    clock = VirtualClock()
    walk: dict = {}
    hw = build_fake(cfg, trajectories=[leg_view(walk, k) for k in range(8)], clock=clock)
    # the virtual time moves no more until the sampler's first deadline: the walk counts from there
    walk["traj"] = GaitTrajectory(
        start_s=seconds(clock)() + 0.15, step_period_s=STEP_S, compression_m=0.008, compression_s=0.06
    )

    async def main():
        app = RobotApp(cfg, hw)
        # duration_s only guards against a hang: the run ends after its samples
        return await app.run(duration_s=120, max_samples=RUN_SAMPLES, arm=True, handle_signals=False)

    return asyncio.run(main()), hw


def test_one_sensor_per_leg_with_gpio_chip_selects_clutches_the_measured_leg(tmp_path) -> None:
    """Each stance lasts 60 ms of compression; the loop and the fakes run on a virtual clock, so every sample is
    taken and one run is the whole test."""
    cfg = per_leg_config(tmp_path)
    summary, hw = _walk_to_leg_3(cfg)
    assert summary.faults == [] and summary.error is None
    assert summary.samples == RUN_SAMPLES and summary.missed_deadlines == 0
    assert summary.stop_reason == "sampler finished"
    hist = {
        k: "".join("1" if s.state else "0" for s in hw.pin_factory.pin(p).states) for k, p in enumerate(cfg.clutch.pins)
    }
    # legs 0..3 stanced once each, released at the next leg's touchdown (leg 3 at the stop); legs 4..7 not yet
    assert hist == {0: "010", 1: "010", 2: "010", 3: "010", 4: "0", 5: "0", 6: "0", 7: "0"}, hist
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
