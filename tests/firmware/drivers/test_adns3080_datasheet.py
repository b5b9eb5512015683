"""The sensor handled by the datasheet: the mandatory RESET pulse, NPD, the frame-rate bound rule,
MOT/RES/OVF and reserved Motion bits, and no lock on a sample the chip does not vouch for."""

from __future__ import annotations

import pytest

from rimless.firmware.control.faults import Fault
from rimless.firmware.drivers import adns3080 as reg
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080, FakeFault, GaitTrajectory
from rimless.firmware.drivers.spi import SpiSegment
from rimless.firmware.errors import SensorError, SensorNotFound, SpiProtocolError

TRAJ = GaitTrajectory(start_s=0.1, step_period_s=0.4, compression_m=0.008, compression_s=0.06)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def chip(**kw):
    clock = Clock()
    fake = FakeAdns3080(lambda t: 0.0, clock=clock, **kw)
    pins: list[tuple[str, bool]] = []

    def reset(on: bool) -> None:
        pins.append(("reset", on))
        fake.set_reset(on)

    def npd(on: bool) -> None:
        pins.append(("npd", on))
        fake.set_npd(on)

    drv = Adns3080(
        fake,
        counts_per_m=DEFAULT_COUNTS_PER_M,
        reset=reset,
        npd=npd,
        sleep=clock.sleep,
        clock_ns=lambda: round(clock.t * 1e9),
    )
    return clock, fake, drv, pins


def test_the_chip_answers_nothing_until_the_reset_pulse() -> None:
    clock, fake, drv, pins = chip()
    assert drv.read_register(0x00) == 0x00  # no power-on reset: nothing drives MISO
    no_reset = Adns3080(fake, counts_per_m=1.0, sleep=clock.sleep)
    with pytest.raises(SensorError, match="RESET"):
        no_reset.power_up()
    t0 = clock.t
    drv.power_up()
    assert [p for p in pins if p[0] == "reset"] == [("reset", True), ("reset", False)]
    assert clock.t - t0 >= reg.T_PU_RESET_S + reg.T_PW_RESET_S  # pulse, then 35 ms before motion is valid
    assert fake.resets == 1 and drv.verify_id() == 0x01


def test_npd_is_raised_before_the_reset_and_power_down_silences_the_chip() -> None:
    clock, fake, drv, pins = chip()
    fake.set_npd(False)
    drv.power_up()
    assert pins[0] == ("npd", True) and pins[1] == ("reset", True)
    fake.set_npd(False)
    with pytest.raises(SensorNotFound):
        drv.verify_id()


def test_fixed_frame_rate_keeps_max_bound_at_least_min_bound_plus_shutter_bound() -> None:
    clock, fake, drv, _ = chip()
    drv.power_up()
    drv.set_frame_rate(3000)  # 8000 counts: the reset shutter bound 8192 alone would break the rule
    regs = fake.regs
    max_b = (regs[0x1A] << 8) | regs[0x19]
    min_b = (regs[0x1C] << 8) | regs[0x1B]
    sh_b = (regs[0x1E] << 8) | regs[0x1D]
    assert max_b == 8000 and max_b >= min_b + sh_b and sh_b == 8000 - 3710
    assert drv.frame_rate_hz() == pytest.approx(3000.0)
    assert fake.violations == 0


def test_the_fake_models_the_bound_rule_and_busy() -> None:
    clock, fake, drv, _ = chip()
    drv.power_up()
    fake.regs[0x0B] |= 0x01
    drv.write_register(0x19, 8000 & 0xFF)
    with pytest.raises(SpiProtocolError, match="Min_Bound"):
        drv.write_register(0x1A, 8000 >> 8)  # 8000 < 3710 + 8192
    drv.write_register(0x1D, 0x00)
    drv.write_register(0x1E, 0x10)  # 4096
    drv.write_register(0x19, 8000 & 0xFF)
    drv.write_register(0x1A, 8000 >> 8)
    assert drv.read_register(0x0B) & 0x80  # Busy for two frames
    with pytest.raises(SpiProtocolError, match="Busy"):
        drv.write_register(0x19, 0x40)
    clock.t += 2 * 8000 / 24e6
    assert not drv.read_register(0x0B) & 0x80


def test_frame_rate_without_room_for_the_shutter_is_refused() -> None:
    clock, fake, drv, _ = chip()
    drv.power_up()
    with pytest.raises(SensorError, match="no room for the shutter"):
        drv.set_frame_rate(6469)
    assert fake.violations == 0


def test_brownout_reset_to_400_cpi_is_a_fault(make_rig) -> None:
    rig = make_rig(TRAJ)
    for _ in range(300):
        rig.run(1 / rig.rate_hz)
        if rig.controller.clutches.engaged():
            break
    leg = rig.controller.clutches.engaged()[0]
    rig.fake.brownout()  # registers back to reset values: 400 cpi, velocities 4x too small
    rig.run(2 / rig.rate_hz)
    faults = [e.fields for e in rig.events("fault")]
    assert [f["fault"] for f in faults] == [Fault.SENSOR_RESET.value]
    assert "400 cpi" in faults[0]["detail"]
    assert rig.levels(leg) == [False, True, False] and not rig.controller.armed


def test_rearming_after_saturation_clears_the_overflow(make_rig) -> None:
    rig = make_rig(TRAJ)
    rig.run(0.3)
    rig.fake.fault = FakeFault.SATURATE
    rig.run(0.05)
    assert [e.fields["fault"] for e in rig.events("fault")] == [Fault.MOTION_SATURATED.value]
    rig.fake.fault = None
    rig.controller.arm()  # Motion_Clear clears OVF
    rig.run(0.8)
    assert [e.fields["fault"] for e in rig.events("fault")] == [Fault.MOTION_SATURATED.value]
    assert rig.controller.armed and len(rig.events("lock")) >= 2


def test_reserved_motion_bits_do_not_trip_a_fault(make_rig) -> None:
    rig = make_rig(TRAJ)
    rig.fake.reserved_motion_bits = 0x6E  # every undocumented bit set
    rig.run(1.0)
    assert rig.events("fault") == []
    assert len(rig.events("lock")) == 3 and rig.controller.armed


def test_no_lock_on_frozen_motion_with_low_squal(make_rig) -> None:
    """Tracking lost 30 ms before the true peak: the frozen deltas look like zero velocity, but the
    samples are not trusted, so nothing locks before the SQUAL fault releases everything."""
    rig = make_rig(TRAJ)
    k = 1
    rig.run(TRAJ.max_compression_s(k) - 0.03)
    locks_before = len(rig.events("lock"))
    rig.fake.fault = FakeFault.TRACKING_LOST
    rig.run(0.1)
    assert len(rig.events("lock")) == locks_before
    assert rig.levels(k) == [False]  # leg 1 never clutched on untrusted samples
    assert [e.fields["fault"] for e in rig.events("fault")] == [Fault.SQUAL_LOW.value]
    assert all(rig.pin(leg).state is False for leg in range(8))


def test_stuck_bus_is_still_a_fault(make_rig) -> None:
    rig = make_rig(TRAJ)
    rig.run(0.2)
    rig.fake.fault = FakeFault.STUCK_BUS
    rig.run(0.02)
    assert [e.fields["fault"] for e in rig.events("fault")] == [Fault.SENSOR_STUCK.value]


def test_wire_time_counts_bytes_and_gaps_at_the_clock() -> None:
    clock, fake, drv, _ = chip(speed_hz=1_000_000)
    drv.power_up()
    w0 = fake.wire_time_s
    drv.read_raw_motion()
    assert fake.wire_time_s - w0 == pytest.approx(8 * 8 / 1e6 + 75e-6)
    w0 = fake.wire_time_s
    fake.message([SpiSegment(b"\x00", 50), SpiSegment(b"\x00")])
    assert fake.wire_time_s - w0 == pytest.approx(2 * 8 / 1e6 + 50e-6)
