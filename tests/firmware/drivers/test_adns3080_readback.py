"""Read-back of the sensor's identity and configuration: a brown-out (the chip back in its power-on state,
[DS p.23]'s reset values, as the register-level fake models it) is found at every resolution and frame-rate
setting, 400 cpi with the automatic rate included, where every configuration register the firmware writes
holds its power-on value; a wrong Product_ID is found within one round of `READBACK_REGISTERS` reads.

Fails before the read-back: `mark_configured`/`check_next`/`check_all` did not exist, and only Motion's RES
bit (1600 cpi) could show a reset."""

from __future__ import annotations

import pytest

from rimless.firmware.drivers import adns3080 as reg
from rimless.firmware.drivers.adns3080 import Adns3080
from rimless.firmware.drivers.fake_adns3080 import DEFAULT_COUNTS_PER_M, FakeAdns3080, FakeFault
from rimless.firmware.errors import SensorNotFound, SensorReset

# The datasheet's register table [DS p.23], written here apart from the driver's constants.
DS_POWER_ON = {0x0A: 0x09, 0x0B: 0x00, 0x19: 0xE0, 0x1A: 0x2E}


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def configured(cpi: int, rate_hz: float | None) -> tuple[FakeAdns3080, Adns3080]:
    clock = Clock()
    fake = FakeAdns3080(lambda t: 0.0, clock=clock)
    drv = Adns3080(
        fake,
        counts_per_m=DEFAULT_COUNTS_PER_M,
        reset=fake.set_reset,
        sleep=clock.sleep,
        clock_ns=lambda: round(clock.t * 1e9),
    )
    drv.power_up()
    drv.set_resolution(cpi)
    drv.set_frame_rate(rate_hz)
    drv.mark_configured()
    return fake, drv


def test_at_400_cpi_and_the_automatic_rate_the_configuration_alone_cannot_show_a_reset() -> None:
    """Why a marker is needed: without it the registers the firmware sets read their power-on values."""
    clock = Clock()
    fake = FakeAdns3080(lambda t: 0.0, clock=clock)
    drv = Adns3080(fake, counts_per_m=1.0, reset=fake.set_reset, sleep=clock.sleep)
    drv.power_up()
    drv.set_resolution(400)
    drv.set_frame_rate(None)
    assert {a: drv.read_register(a) for a in DS_POWER_ON} == DS_POWER_ON
    drv.mark_configured()
    assert {a: drv.read_register(a) for a in DS_POWER_ON} != DS_POWER_ON
    assert drv.frame_rate_hz() >= reg.FRAME_RATE_MIN_HZ  # the marker keeps the least frame rate at 2000 fps


@pytest.mark.parametrize(("cpi", "rate_hz"), [(400, None), (1600, None), (400, 2000.0), (400, 3000.0), (1600, 6000.0)])
def test_a_brownout_is_found_at_every_setting_within_one_round(cpi, rate_hz) -> None:
    fake, drv = configured(cpi, rate_hz)
    for _ in range(3 * reg.READBACK_REGISTERS):  # a configured chip: no false alarm
        drv.check_next()
    drv.check_all()
    fake.brownout()
    with pytest.raises(SensorReset, match="reset itself"):
        drv.check_all()
    found_after = None
    for k in range(1, reg.READBACK_REGISTERS + 1):
        try:
            drv.check_next()
        except SensorReset:
            found_after = k
            break
    assert found_after is not None and found_after <= reg.READBACK_REGISTERS


@pytest.mark.parametrize("start", range(reg.READBACK_REGISTERS))
def test_a_wrong_product_id_is_found_within_one_round_from_any_point_of_it(start) -> None:
    fake, drv = configured(1600, None)
    for _ in range(start):
        drv.check_next()
    fake.fault = FakeFault.WRONG_ID
    with pytest.raises(SensorNotFound):
        for _ in range(reg.READBACK_REGISTERS):
            drv.check_next()


def test_reconfiguring_drops_the_configuration_from_the_readback_until_marked_again() -> None:
    fake, drv = configured(400, None)
    drv.set_resolution(1600)  # the expected Configuration_bits changed: not checked until marked
    for _ in range(2 * reg.READBACK_REGISTERS):
        drv.check_next()
    drv.mark_configured()
    fake.brownout()
    with pytest.raises(SensorReset):
        drv.check_all()
