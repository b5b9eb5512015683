"""The driver against the register-level fake, and the fake's protocol enforcement."""

from __future__ import annotations

import math

import pytest

from rimless.firmware.drivers import adns3080 as reg
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080, FakeFault
from rimless.firmware.drivers.spi import SpiSegment
from rimless.firmware.errors import SensorError, SensorNotFound, SpiProtocolError


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def make(trajectory=lambda t: 0.0, **kw):
    clock = Clock()
    fake = FakeAdns3080(trajectory, clock=clock, **kw)
    drv = Adns3080(
        fake,
        counts_per_m=DEFAULT_COUNTS_PER_M,
        reset=fake.set_reset,
        sleep=clock.sleep,
        clock_ns=lambda: round(clock.t * 1e9),
    )
    drv.reset_pulse()  # the chip has no power-on reset: nothing answers before this
    clock.t = 0.0
    return clock, fake, drv


def test_power_up_checks_both_ids_and_clears_motion() -> None:
    _, fake, drv = make()
    drv.power_up()
    reads = [a for kind, a in fake.transactions if kind == "read"]
    assert reads[:2] == [0x00, 0x3F]
    assert ("write", 0x12) in fake.transactions
    assert fake.violations == 0


def test_wrong_id_says_check_wiring() -> None:
    _, fake, drv = make()
    fake.fault = FakeFault.WRONG_ID
    with pytest.raises(SensorNotFound, match="check wiring") as info:
        drv.power_up()
    assert "Product_ID=0x00" in str(info.value)
    assert isinstance(info.value, OSError)


def test_stuck_bus_is_not_the_sensor() -> None:
    _, fake, drv = make()
    fake.fault = FakeFault.STUCK_BUS
    with pytest.raises(SensorNotFound, match="0xFF"):
        drv.verify_id()


def test_resolution_is_read_modify_write() -> None:
    _, fake, drv = make()
    drv.set_resolution(1600)
    assert fake.regs[0x0A] == 0x19  # reset value 0x09 keeps bits 0 and 3
    assert drv.resolution() == reg.Resolution.CPI_1600
    drv.set_resolution(400)
    assert fake.regs[0x0A] == 0x09
    with pytest.raises(ValueError):
        drv.set_resolution(800)


def test_fixed_frame_rate_writes_lower_then_upper() -> None:
    _, fake, drv = make()
    drv.set_frame_rate(3000)
    writes = [a for kind, a in fake.transactions if kind == "write"]
    assert writes[-2:] == [0x19, 0x1A]
    assert fake.regs[0x0B] & 0x01
    assert drv.frame_rate_hz() == pytest.approx(3000.0)
    drv.set_frame_rate(None)
    assert drv.frame_rate_hz() == pytest.approx(2000.0)
    with pytest.raises(ValueError, match="frame rate"):
        drv.set_frame_rate(7000)


def test_displacement_matches_trajectory_within_a_count() -> None:
    traj = lambda t: 0.004 * math.sin(2 * math.pi * 3 * t)  # noqa: E731
    clock, fake, drv = make(traj, noise_counts=0.0)
    drv.power_up()
    drv.set_resolution(1600)
    clock.t = 0.0  # power-up advanced the clock: restart the trajectory from a clear accumulator
    drv.clear_motion()
    total = 0.0
    for k in range(1, 301):
        clock.t = k / 300
        s = drv.read_motion()
        total += s.displacement_m
        assert not s.saturated and not s.overflow
        assert abs(total - traj(clock.t)) <= 1.0 / DEFAULT_COUNTS_PER_M + 1e-12
    assert s.t_ns == round(clock.t * 1e9)
    assert fake.violations == 0


def test_400_cpi_gives_a_quarter_of_the_counts() -> None:
    clock, fake, drv = make(lambda t: 0.01 * t, noise_counts=0.0)
    drv.set_resolution(400)
    drv.counts_per_m = DEFAULT_COUNTS_PER_M / 4
    drv.read_motion()
    clock.t = 1.0
    s = drv.read_motion()
    assert s.counts == pytest.approx(0.01 * DEFAULT_COUNTS_PER_M / 4, abs=1)
    assert s.displacement_m == pytest.approx(0.01, abs=4 / DEFAULT_COUNTS_PER_M)


def test_fast_motion_is_drained_by_rereads() -> None:
    # 300 counts in one period: beyond the 8-bit delta, but the accumulator keeps it.
    clock, fake, drv = make(lambda t: 300 / DEFAULT_COUNTS_PER_M if t >= 0.5 else 0.0, noise_counts=0.0)
    drv.set_resolution(1600)
    drv.read_motion()
    clock.t = 1.0
    s = drv.read_motion()
    assert s.counts == 300
    assert not s.saturated and not s.overflow


def test_saturation_and_overflow_are_flagged() -> None:
    clock, fake, drv = make()
    fake.fault = FakeFault.SATURATE
    s = drv.read_motion()
    assert s.saturated
    for _ in range(3):
        s = drv.read_motion()
    assert s.overflow


def test_stuck_bus_sets_reserved_bits() -> None:
    _, fake, drv = make()
    fake.fault = FakeFault.STUCK_BUS
    assert drv.read_motion().reserved_bits


def test_spi_error_is_a_sensor_error() -> None:
    _, fake, drv = make()
    fake.fault = FakeFault.SPI_ERROR
    with pytest.raises(SensorError):
        drv.read_motion()


@pytest.mark.parametrize(
    ("segments", "match"),
    [
        ([SpiSegment(b"\x00\x00")], "no address-to-data gap"),
        ([SpiSegment(b"\x00", 50)], "different CS windows"),
        ([SpiSegment(b"\x00", 49), SpiSegment(b"\x00")], "t_SRAD 50"),
        ([SpiSegment(b"\x02", 50), SpiSegment(b"\x00")], "t_SRAD 75"),
        ([SpiSegment(b"\x50", 74), SpiSegment(bytes(7))], "t_SRAD 75"),
        ([SpiSegment(b"\x50", 75), SpiSegment(bytes(8))], "7 bytes"),
        ([SpiSegment(b"\x05", 50), SpiSegment(b"\x00\x00")], "clocks 1 byte"),
        ([SpiSegment(b"\x92\x00")], "t_SWW"),
        ([SpiSegment(b"\x92", 50), SpiSegment(b"\x00")], "exactly address"),
    ],
)
def test_fake_rejects_protocol_violations(segments, match) -> None:
    _, fake, _ = make()
    with pytest.raises(SpiProtocolError, match=match):
        fake.message(segments)
    assert fake.violations == 1


def test_fake_accepts_the_correct_framing() -> None:
    _, fake, _ = make()
    assert fake.message([SpiSegment(b"\x00", 50), SpiSegment(b"\x00")])[1] == b"\x17"
    assert fake.message([SpiSegment(b"\x3f", 50), SpiSegment(b"\x00")])[1] == b"\xf8"
    burst = fake.message([SpiSegment(b"\x50", 75), SpiSegment(bytes(7))])[1]
    assert len(burst) == 7 and burst[3] == 60
    assert fake.violations == 0


def test_frame_period_upper_before_lower_is_enforced() -> None:
    _, fake, _ = make()
    with pytest.raises(SpiProtocolError, match="Lower before Upper"):
        fake.message([SpiSegment(b"\x9a\x2e", 50)])
