"""ADNS-3080 optical-flow sensor driver (Avago AV02-0366EN datasheet, pages cited as [DS p.N]).

Register map first, then the driver. Public reads speak SI (metres); raw counts only in `read_raw_*`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

from rimless.firmware.drivers.spi import SpiBus, SpiSegment
from rimless.firmware.errors import SensorError, SensorNotFound, SensorReset

# --- Register map [DS p.23-38] -------------------------------------------------------------------
_REG_PRODUCT_ID = 0x00
_REG_REVISION_ID = 0x01
_REG_MOTION = 0x02
_REG_DELTA_X = 0x03
_REG_DELTA_Y = 0x04
_REG_SQUAL = 0x05
_REG_PIXEL_SUM = 0x06
_REG_MAXIMUM_PIXEL = 0x07
_REG_CONFIGURATION_BITS = 0x0A
_REG_EXTENDED_CONFIG = 0x0B
_REG_SHUTTER_LOWER = 0x0E
_REG_SHUTTER_UPPER = 0x0F
_REG_FRAME_PERIOD_LOWER = 0x10
_REG_FRAME_PERIOD_UPPER = 0x11
_REG_MOTION_CLEAR = 0x12
_REG_FRAME_PERIOD_MAX_BOUND_LOWER = 0x19
_REG_FRAME_PERIOD_MAX_BOUND_UPPER = 0x1A
_REG_FRAME_PERIOD_MIN_BOUND_LOWER = 0x1B
_REG_FRAME_PERIOD_MIN_BOUND_UPPER = 0x1C
_REG_SHUTTER_MAX_BOUND_LOWER = 0x1D
_REG_SHUTTER_MAX_BOUND_UPPER = 0x1E
_REG_SROM_ID = 0x1F
_REG_INVERSE_PRODUCT_ID = 0x3F
_REG_MOTION_BURST = 0x50

PRODUCT_ID = 0x17
INVERSE_PRODUCT_ID = 0xF8  # == ~0x17 & 0xFF

# Bits.
_WRITE_BIT = 0x80  # address MSB = 1 for a write [DS p.16]
_ADDRESS_MASK = 0x7F
_MOTION_MOT = 0x80  # motion since last report
_MOTION_OVF = 0x10  # accumulator overflowed: the absolute path is lost
_MOTION_RES = 0x01  # 1 = 1600 cpi
_MOTION_RESERVED = 0x6E  # reserved bits: reported, never a fault (the datasheet does not define them)
_CONFIG_RES_1600 = 0x10  # Configuration_bits bit 4 [DS p.29]
_EXT_FIXED_FR = 0x01  # Extended_Config bit 0: fixed frame rate
_EXT_BUSY = 0x80  # Extended_Config bit 7: a bound write is still being applied
_MOTION_CLEAR_ANY = 0x00  # writing any value clears the deltas [DS p.32]

# Timing, minimums [DS p.11, p.17-22]; each wait in the code names the one it honours.
T_SRAD_US = 50  # address to data, ordinary register
T_SRAD_MOT_US = 75  # address to data, Motion and Motion_Burst
T_SWW_US = 50  # write to next write
T_SWR_US = 50  # write to next read
T_PW_RESET_S = 10e-6  # minimum RESET pulse
T_PU_RESET_S = 35e-3  # RESET falling edge until motion data is valid
T_SERIAL_RESET_S = 1e-3  # NCS high this long resets the serial port
T_PUPD_S = 75e-3  # NPD raised until the chip is up (t_PUPD)

CLOCK_HZ = 24e6  # frame period registers count this clock
FRAME_RATE_MIN_HZ = 2000.0
FRAME_RATE_MAX_HZ = 6469.0
FRAME_PERIOD_MIN_COUNTS = 0x0E7E  # 6469 fps
FRAME_PERIOD_MAX_COUNTS = 0x2EE0  # 2000 fps
BURST_LEN = 7  # Motion, Delta_X, Delta_Y, SQUAL, Shutter_Upper, Shutter_Lower, Maximum_Pixel [DS p.38]
DELTA_MIN, DELTA_MAX = -128, 127
MAX_PIXEL_MASK = 0x3F
SQUAL_MAX = 169
MIN_SHUTTER_MAX_BOUND = 0x0100  # the least shutter bound the driver accepts when it lowers it for a frame rate
# Power-on values of the registers the read-back check watches [DS p.23]: a chip that reset itself reads them.
POWER_ON_CONFIGURATION_BITS = 0x09  # 400 cpi
POWER_ON_EXTENDED_CONFIG = 0x00  # automatic frame rate
POWER_ON_MAX_BOUND = 0x2EE0  # Frame_Period_Max_Bound: 2000 fps
RESET_MARKER_MAX_BOUND = POWER_ON_MAX_BOUND - 1  # written with the automatic rate: 2000.2 fps minimum, a no-op
READBACK_REGISTERS = 5  # Product_ID, Inverse_Product_ID, Configuration_bits, Extended_Config, Max_Bound Lower
MAX_REREADS = 4  # extra bursts to drain a saturated accumulator before calling the sample saturated
_BUSY_POLLS = 20


class Resolution(IntEnum):
    """Counts per inch; the value of Configuration_bits bit 4 follows from it."""

    CPI_400 = 400
    CPI_1600 = 1600


def _s8(byte: int) -> int:
    """8-bit two's complement to int."""
    return byte - 256 if byte & 0x80 else byte


def srad_us(register: int) -> int:
    """Address-to-data gap required before reading `register` (75 us for Motion/Motion_Burst)."""
    return T_SRAD_MOT_US if register in (_REG_MOTION, _REG_MOTION_BURST) else T_SRAD_US


class RawMotion(NamedTuple):
    """One Motion_Burst, as the chip reports it (counts)."""

    motion: int
    dx_counts: int
    dy_counts: int
    squal: int
    shutter: int
    max_pixel: int


@dataclass(frozen=True, slots=True)
class MotionSample:
    """One timestamped motion read, in SI.

    `t_ns` is `time.monotonic_ns()` at the middle of the read; `displacement_m` is the leg's motion
    along the sensor axis since the previous read (compression positive), `lateral_m` the other axis.
    `overflow`: the chip lost the path (OVF); `saturated`: deltas stayed at full scale after re-reads.
    """

    t_ns: int
    displacement_m: float
    lateral_m: float
    squal: int
    shutter: int
    max_pixel: int
    overflow: bool
    saturated: bool
    counts: int
    reserved_bits: bool = False  # informative only
    stuck: bool = False  # every burst byte 0xFF, or SQUAL beyond 169: the link, not the chip
    resolution_reset: bool = False  # RES reads 400 cpi while 1600 was configured: the chip reset itself


class Adns3080:
    """ADNS-3080 on an `SpiBus`.

    :param counts_per_m: calibrated counts per metre of leg travel at the configured resolution.
    :param axis: "x" or "y", the sensor axis along the leg guide.
    :param sign: +1 or -1 so that compression is positive.
    :param reset: callable driving the RESET pin (True = high = reset asserted); required by
        `power_up`, since the chip has no power-on reset.
    :param npd: optional callable driving NPD (True = high = running, False = powered down).
    """

    def __init__(
        self,
        bus: SpiBus,
        *,
        counts_per_m: float,
        axis: str = "y",
        sign: int = 1,
        reset: Callable[[bool], None] | None = None,
        npd: Callable[[bool], None] | None = None,
        sleep: Callable[[float], None] = time.sleep,
        clock_ns: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        if counts_per_m <= 0:
            raise ValueError(f"counts_per_m must be > 0, got {counts_per_m}")
        if axis not in ("x", "y"):
            raise ValueError(f"axis must be 'x' or 'y', got {axis!r}")
        if sign not in (1, -1):
            raise ValueError(f"sign must be +1 or -1, got {sign}")
        self.bus = bus
        self.counts_per_m = float(counts_per_m)
        self.axis = axis
        self.sign = sign
        self._reset = reset
        self._npd = npd
        self.expected_cpi: int | None = None  # set by set_resolution; checked on every motion read
        # (register, expected value, mask) read back by `check_next`/`check_all`; the identity registers only
        # until `mark_configured` adds the configuration a reset would undo
        self._readback: list[tuple[int, int, int]] = [
            (_REG_PRODUCT_ID, PRODUCT_ID, 0xFF),
            (_REG_INVERSE_PRODUCT_ID, INVERSE_PRODUCT_ID, 0xFF),
        ]
        self._next_readback = 0
        self._sleep = sleep
        self._clock_ns = clock_ns

    # --- register access ------------------------------------------------------------------------
    def read_register(self, register: int) -> int:
        """Read one register: address, t_SRAD in the same CS window, one data byte."""
        addr = register & _ADDRESS_MASK
        rx = self.bus.message([SpiSegment(bytes([addr]), srad_us(addr)), SpiSegment(b"\x00")])
        return rx[1][0]

    def write_register(self, register: int, value: int) -> None:
        """Write one register; the t_SWW/t_SWR wait runs with CS still low after the data byte."""
        self.bus.message([SpiSegment(bytes([(register & _ADDRESS_MASK) | _WRITE_BIT, value & 0xFF]), T_SWW_US)])

    # --- power-up and identity ------------------------------------------------------------------
    def wake(self) -> None:
        """NPD high (if wired), then t_PUPD = 75 ms."""
        if self._npd is not None:
            self._npd(True)
            self._sleep(T_PUPD_S)

    def reset_pulse(self, *, wake: bool = True) -> None:
        """NPD high (`wake`), then the RESET pulse the chip needs after every power-up (DS p.22)."""
        if self._reset is None:
            raise SensorError("the ADNS-3080 has no power-on reset: wire RESET to a GPIO and set reset_pin")
        if wake:
            self.wake()
        self._reset(True)
        self._sleep(max(T_PW_RESET_S, 1e-3))  # t_PW-RESET >= 10 us; 1 ms as [RP]
        self._reset(False)
        self._sleep(T_PU_RESET_S)  # t_PU-RESET: motion data valid 35 ms after RESET falls

    def power_up(self, *, pulse_reset: bool = True) -> None:
        """The mandatory reset pulse (there is no power-on reset, DS p.22; `pulse_reset=False` only when
        the caller just pulsed a RESET line shared by several sensors), serial-port reset, ID check,
        Motion_Clear. Raises SensorError if RESET is not wired, SensorNotFound on a wrong ID."""
        if pulse_reset:
            self.reset_pulse()
        self._sleep(T_SERIAL_RESET_S)  # NCS high >= 1 ms resets the serial port (DS p.21)
        self.verify_id()
        self.write_register(_REG_MOTION_CLEAR, _MOTION_CLEAR_ANY)

    def verify_id(self) -> int:
        """Check Product_ID and Inverse_Product_ID; return Revision_ID. Raises `SensorNotFound`."""
        pid = self.read_register(_REG_PRODUCT_ID)
        inv = self.read_register(_REG_INVERSE_PRODUCT_ID)
        if pid != PRODUCT_ID or inv != INVERSE_PRODUCT_ID:
            msg = (
                f"ADNS-3080 not found: Product_ID=0x{pid:02X} (expected 0x{PRODUCT_ID:02X}), "
                f"Inverse_Product_ID=0x{inv:02X} (expected 0x{INVERSE_PRODUCT_ID:02X}); check wiring "
                "(NCS, MISO, MOSI, SCLK, 3.3 V, RESET) and that SPI is enabled"
            )
            raise SensorNotFound(msg)
        return self.read_register(_REG_REVISION_ID)

    # --- configuration --------------------------------------------------------------------------
    def set_resolution(self, cpi: int) -> None:
        """400 or 1600 cpi, by read-modify-write of Configuration_bits (bits 0 and 3 stay as read)."""
        res = Resolution(cpi)
        cfg = self.read_register(_REG_CONFIGURATION_BITS)
        cfg = (cfg | _CONFIG_RES_1600) if res is Resolution.CPI_1600 else (cfg & ~_CONFIG_RES_1600)
        self.write_register(_REG_CONFIGURATION_BITS, cfg)
        self.expected_cpi = int(res)
        self._readback = self._readback[:2]  # the identity only, until `mark_configured`

    def resolution(self) -> Resolution:
        """The resolution the chip reports in Configuration_bits."""
        cfg = self.read_register(_REG_CONFIGURATION_BITS)
        return Resolution.CPI_1600 if cfg & _CONFIG_RES_1600 else Resolution.CPI_400

    def set_frame_rate(self, rate_hz: float | None) -> None:
        """Fixed frame rate in 2000..6469 fps, or None for the automatic rate (SmartSpeed)."""
        ext = self.read_register(_REG_EXTENDED_CONFIG)
        self._readback = self._readback[:2]  # the identity only, until `mark_configured`
        if rate_hz is None:
            self.write_register(_REG_EXTENDED_CONFIG, ext & ~_EXT_FIXED_FR & ~_EXT_BUSY)
            return
        if not FRAME_RATE_MIN_HZ <= rate_hz <= FRAME_RATE_MAX_HZ:
            raise ValueError(f"frame rate must be {FRAME_RATE_MIN_HZ:.0f}..{FRAME_RATE_MAX_HZ:.0f} Hz, got {rate_hz}")
        period = round(CLOCK_HZ / rate_hz)
        period = min(max(period, FRAME_PERIOD_MIN_COUNTS), FRAME_PERIOD_MAX_COUNTS)
        shutter_max = self.shutter_bound_for(period)
        self.write_register(_REG_EXTENDED_CONFIG, (ext | _EXT_FIXED_FR) & ~_EXT_BUSY)
        # Rule [DS p.34]: Max_Bound >= Min_Bound + Shutter_Max_Bound. Shutter_Max_Bound is written first
        # (it is pending until the Max_Bound write applies it), then Max_Bound, Lower then Upper.
        self.write_register(_REG_SHUTTER_MAX_BOUND_LOWER, shutter_max & 0xFF)
        self.write_register(_REG_SHUTTER_MAX_BOUND_UPPER, shutter_max >> 8)
        self.write_register(_REG_FRAME_PERIOD_MAX_BOUND_LOWER, period & 0xFF)
        self.write_register(_REG_FRAME_PERIOD_MAX_BOUND_UPPER, period >> 8)
        self._wait_not_busy()

    def shutter_bound_for(self, period: int) -> int:
        """The Shutter_Max_Bound to pair with Frame_Period_Max_Bound `period` (counts): the current one,
        lowered so that Max_Bound >= Min_Bound + Shutter_Max_Bound holds. Raises SensorError if even
        `MIN_SHUTTER_MAX_BOUND` does not fit."""
        min_bound = self._read16(_REG_FRAME_PERIOD_MIN_BOUND_UPPER, _REG_FRAME_PERIOD_MIN_BOUND_LOWER)
        shutter = self._read16(_REG_SHUTTER_MAX_BOUND_UPPER, _REG_SHUTTER_MAX_BOUND_LOWER)
        room = period - min_bound
        if room < MIN_SHUTTER_MAX_BOUND:
            raise SensorError(
                f"frame rate {CLOCK_HZ / period:.0f} fps leaves no room for the shutter: Frame_Period_Max_Bound "
                f"{period} < Frame_Period_Min_Bound {min_bound} + {MIN_SHUTTER_MAX_BOUND}"
            )
        return min(shutter, room)

    def _read16(self, upper: int, lower: int) -> int:
        hi = self.read_register(upper)
        return (hi << 8) | self.read_register(lower)

    def _wait_not_busy(self) -> None:
        """Wait two frames at the slowest rate, then poll Busy, before the next bound write [DS p.34]."""
        self._sleep(2 / FRAME_RATE_MIN_HZ)
        for _ in range(_BUSY_POLLS):
            if not self.read_register(_REG_EXTENDED_CONFIG) & _EXT_BUSY:
                return
            self._sleep(1 / FRAME_RATE_MIN_HZ)
        raise SensorError("ADNS-3080 stayed busy after a frame-period write")

    # --- read-back: identity and configuration, against a swap and a brown-out ----------------------
    def mark_configured(self) -> None:
        """Remember the configuration as written, after making sure a reset would change it.

        At 400 cpi with the automatic frame rate every configuration register holds its power-on value, so a
        brown-out (the chip back in its reset state) would read the same. With the automatic rate,
        Frame_Period_Max_Bound (the least frame rate, 2000 fps at reset) is therefore written one count lower
        (2000.2 fps: no effect on tracking) as a reset marker; with a fixed rate, Extended_Config's Fixed_FR
        bit already differs from its reset value. Call it after `set_resolution` and `set_frame_rate`.
        """
        ext = self.read_register(_REG_EXTENDED_CONFIG) & ~_EXT_BUSY
        if not ext & _EXT_FIXED_FR:
            marker = RESET_MARKER_MAX_BOUND
            shutter_max = self.shutter_bound_for(marker)
            self.write_register(_REG_SHUTTER_MAX_BOUND_LOWER, shutter_max & 0xFF)
            self.write_register(_REG_SHUTTER_MAX_BOUND_UPPER, shutter_max >> 8)
            self.write_register(_REG_FRAME_PERIOD_MAX_BOUND_LOWER, marker & 0xFF)
            self.write_register(_REG_FRAME_PERIOD_MAX_BOUND_UPPER, marker >> 8)
            self._wait_not_busy()
        cfg = self.read_register(_REG_CONFIGURATION_BITS)
        max_lower = self.read_register(_REG_FRAME_PERIOD_MAX_BOUND_LOWER)
        watched = [
            (_REG_CONFIGURATION_BITS, cfg, 0xFF),
            (_REG_EXTENDED_CONFIG, ext, 0xFF & ~_EXT_BUSY),
            (_REG_FRAME_PERIOD_MAX_BOUND_LOWER, max_lower, 0xFF),
        ]
        power_on = (POWER_ON_CONFIGURATION_BITS, POWER_ON_EXTENDED_CONFIG, POWER_ON_MAX_BOUND & 0xFF)
        if all(value == p for (_, value, _), p in zip(watched, power_on, strict=True)):
            raise SensorError(
                "ADNS-3080 configuration reads back as its power-on state after the reset marker "
                "was written: the chip does not keep its registers"
            )
        self._readback = self._readback[:2] + watched
        self._next_readback = 0

    def _check(self, register: int, expected: int, mask: int) -> None:
        value = self.read_register(register) & mask
        if value == expected:
            return
        if register in (_REG_PRODUCT_ID, _REG_INVERSE_PRODUCT_ID):
            self.verify_id()  # raises SensorNotFound with both IDs named
            return  # read right the second time: a glitch the next round checks again
        raise SensorReset(
            f"ADNS-3080 register 0x{register:02X} reads 0x{value:02X}, configured 0x{expected:02X}: "
            "the chip reset itself (brown-out?); restart the firmware to configure it again"
        )

    def check_next(self) -> None:
        """Read back one register of the identity and configuration, the next in turn: `READBACK_REGISTERS`
        calls cover them all. Raises SensorNotFound (Product_ID) or SensorReset (configuration lost)."""
        register, expected, mask = self._readback[self._next_readback % len(self._readback)]
        self._next_readback = (self._next_readback + 1) % len(self._readback)
        self._check(register, expected, mask)

    def check_all(self) -> None:
        """Read back every identity and configuration register (see `check_next`)."""
        for register, expected, mask in self._readback:
            self._check(register, expected, mask)

    def frame_rate_hz(self) -> float:
        """Current frame rate from Frame_Period (Upper read first) [DS p.31]."""
        upper = self.read_register(_REG_FRAME_PERIOD_UPPER)
        lower = self.read_register(_REG_FRAME_PERIOD_LOWER)
        period = (upper << 8) | lower
        if period == 0:
            raise SensorError("ADNS-3080 Frame_Period reads 0: sensor not running")
        return CLOCK_HZ / period

    def squal(self) -> int:
        """Surface quality (features / 4, 0..169)."""
        return self.read_register(_REG_SQUAL)

    def clear_motion(self) -> None:
        """Clear Delta_X/Y and the accumulators."""
        self.write_register(_REG_MOTION_CLEAR, _MOTION_CLEAR_ANY)

    # --- motion ---------------------------------------------------------------------------------
    def read_raw_motion(self) -> RawMotion:
        """One Motion_Burst: 0x50, t_SRAD-MOT = 75 us with CS low, then 7 bytes with no gaps."""
        rx = self.bus.message([SpiSegment(bytes([_REG_MOTION_BURST]), T_SRAD_MOT_US), SpiSegment(bytes(BURST_LEN))])[1]
        return RawMotion(rx[0], _s8(rx[1]), _s8(rx[2]), rx[3], (rx[4] << 8) | rx[5], rx[6] & MAX_PIXEL_MASK)

    def read_motion(self) -> MotionSample:
        """Read motion in metres, draining a saturated accumulator with up to `MAX_REREADS` bursts.

        Each message ends with CS high, which satisfies t_BEXIT between bursts.
        """
        t0 = self._clock_ns()
        raw = self.read_raw_motion()
        t1 = self._clock_ns()
        stuck = (
            raw.motion == 0xFF and raw.dx_counts == -1 and raw.dy_counts == -1 and raw.squal == 0xFF
        ) or raw.squal > SQUAL_MAX
        # Delta_X/Y mean something only with MOT set [DS p.24].
        dx, dy = (raw.dx_counts, raw.dy_counts) if raw.motion & _MOTION_MOT else (0, 0)
        overflow = bool(raw.motion & _MOTION_OVF)
        reserved = bool(raw.motion & _MOTION_RESERVED)
        res_reset = not stuck and self.expected_cpi == Resolution.CPI_1600 and not raw.motion & _MOTION_RES
        saturated = not stuck and (_full_scale(dx) or _full_scale(dy))
        rereads = 0
        while saturated and rereads < MAX_REREADS:
            more = self.read_raw_motion()
            rereads += 1
            mdx, mdy = (more.dx_counts, more.dy_counts) if more.motion & _MOTION_MOT else (0, 0)
            dx += mdx
            dy += mdy
            overflow = overflow or bool(more.motion & _MOTION_OVF)
            saturated = _full_scale(mdx) or _full_scale(mdy)
        along, lateral = (dy, dx) if self.axis == "y" else (dx, dy)
        counts = self.sign * along
        return MotionSample(
            t_ns=(t0 + t1) // 2,
            displacement_m=counts / self.counts_per_m,
            lateral_m=lateral / self.counts_per_m,
            squal=raw.squal,
            shutter=raw.shutter,
            max_pixel=raw.max_pixel,
            overflow=overflow,
            saturated=saturated,
            counts=counts,
            reserved_bits=reserved,
            stuck=stuck,
            resolution_reset=res_reset,
        )


def _full_scale(delta: int) -> bool:
    return delta in (DELTA_MIN, DELTA_MAX)
