"""A register-level fake ADNS-3080 behind `SpiBus`, replaying a leg-compression trajectory.

It enforces the protocol the real chip needs: a read is an address segment whose in-window delay is
at least t_SRAD (75 us for Motion/Motion_Burst) followed by its data in the *same* CS window; a write
is address|0x80 plus one byte with t_SWW after it. A violation raises `SpiProtocolError`, which the
real chip would show as garbage. Counts are quantised (floor) with Gaussian noise, motion latches on a
read of Motion, and the accumulator saturates and overflows as the datasheet describes.

It also models what the datasheet asks of the host: the chip answers nothing (every byte 0x00) until a
RESET pulse (`set_reset(True)` then `set_reset(False)`; there is no power-on reset) and while NPD is
low; OVF stays set until Motion_Clear; a Frame_Period_Max_Bound write that breaks Max_Bound >=
Min_Bound + Shutter_Max_Bound, or any bound write while Busy (two frames after the last one), is a
protocol violation; `brownout()` resets the registers (400 cpi) as a supply dip would. `wire_time_s`
adds up the SPI time of every message at `speed_hz` (bytes plus the in-window delays).
"""

from __future__ import annotations

import errno
import math
import random
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum

from rimless.firmware.drivers import adns3080 as reg
from rimless.firmware.drivers.spi import SpiSegment
from rimless.firmware.errors import SensorError, SpiProtocolError

ACCUMULATOR_LIMIT = 2047  # fake's model of the chip's >8-bit accumulator; beyond it OVF is set
DEFAULT_COUNTS_PER_M = 1600 / 0.0254  # 1600 cpi on the datasheet's 2.4 mm lens geometry


class FakeFault(str, Enum):
    """Faults the fake can inject."""

    SPI_ERROR = "spi_error"  # every transfer raises OSError(EIO)
    WRONG_ID = "wrong_id"  # Product_ID reads 0x00 (nothing on the bus)
    STUCK_BUS = "stuck_bus"  # MISO stuck high: every byte reads 0xFF
    SQUAL_DROP = "squal_drop"  # surface lost: SQUAL reads 2
    SATURATE = "saturate"  # motion far beyond the 8-bit range: full-scale deltas, then OVF
    TRACKING_LOST = "tracking_lost"  # surface lost mid-motion: SQUAL reads 2 and the deltas freeze at 0


@dataclass(frozen=True)
class GaitTrajectory:
    """Scripted stance phases: every `step_period_s` a leg touches down at `start_s + k*step_period_s`,
    compresses to `compression_m` at `compression_s` and rebounds freely to 0 at 2*compression_s.

    Returns the compression displacement in metres at time `t` (s, on the fake's clock).
    """

    start_s: float = 0.2
    step_period_s: float = 0.4
    compression_m: float = 0.008
    compression_s: float = 0.06
    steps: int | None = None

    def touchdown_s(self, k: int) -> float:
        """Time of the k-th touchdown (s)."""
        return self.start_s + k * self.step_period_s

    def max_compression_s(self, k: int) -> float:
        """Time of the k-th maximum compression (s): where the compression velocity is zero."""
        return self.touchdown_s(k) + self.compression_s

    def __call__(self, t: float) -> float:
        u = t - self.start_s
        if u < 0:
            return 0.0
        k = int(u // self.step_period_s)
        if self.steps is not None and k >= self.steps:
            return 0.0
        tau = u - k * self.step_period_s
        if tau >= 2 * self.compression_s:
            return 0.0
        return self.compression_m * math.sin(math.pi * tau / (2 * self.compression_s))


def still(_t: float) -> float:
    """A leg that never moves (noise only)."""
    return 0.0


class FakeAdns3080:
    """Answers `SpiBus.message` like an ADNS-3080 watching a leg that follows `trajectory`.

    :param trajectory: compression displacement (m) as a function of the fake's clock (s).
    :param counts_per_m: counts per metre at 1600 cpi (a quarter of that at 400 cpi).
    :param noise_counts: standard deviation of the position noise, in counts.
    :param clock: time source in seconds (monotonic by default; tests pass a virtual clock).
    """

    def __init__(
        self,
        trajectory: Callable[[float], float] = still,
        *,
        counts_per_m: float = DEFAULT_COUNTS_PER_M,
        axis: str = "y",
        sign: int = 1,
        noise_counts: float = 0.3,
        squal: int = 60,
        seed: int = 0,
        clock: Callable[[], float] = time.monotonic,
        history: int = 1000,
        speed_hz: int = 2_000_000,
        needs_reset: bool = True,
    ) -> None:
        self.trajectory = trajectory
        self.counts_per_m = counts_per_m
        self.axis = axis
        self.sign = sign
        self.noise_counts = noise_counts
        self.squal_value = squal
        self.clock = clock
        self.fault: FakeFault | None = None
        self.closed = False
        self._history = history
        self._rng = random.Random(seed)
        self.speed_hz = speed_hz
        self.wire_time_s = 0.0
        self.messages = 0
        self.reserved_motion_bits = 0  # OR'ed into Motion: undocumented bits a real chip may set
        self.reset_high = False
        self.powered = True  # NPD high
        self.serial_up = not needs_reset  # no power-on reset: nothing answers until a RESET pulse
        self.resets = 0
        self._busy_until_s = -math.inf
        self._power_on_registers()

    def _power_on_registers(self) -> None:
        self.regs = {
            reg._REG_PRODUCT_ID: reg.PRODUCT_ID,
            reg._REG_REVISION_ID: 0x01,
            reg._REG_CONFIGURATION_BITS: 0x09,
            reg._REG_EXTENDED_CONFIG: 0x00,
            reg._REG_SHUTTER_LOWER: 0x85,
            reg._REG_SHUTTER_UPPER: 0x00,
            reg._REG_FRAME_PERIOD_MAX_BOUND_LOWER: 0xE0,
            reg._REG_FRAME_PERIOD_MAX_BOUND_UPPER: 0x2E,
            # Table values [DS p.23]: Min_Bound 0x0E7E (6469 fps), Shutter_Max_Bound 0x2000, so that the
            # reset state keeps Max_Bound 12000 >= 3710 + 8192.
            reg._REG_FRAME_PERIOD_MIN_BOUND_LOWER: 0x7E,
            reg._REG_FRAME_PERIOD_MIN_BOUND_UPPER: 0x0E,
            reg._REG_SHUTTER_MAX_BOUND_LOWER: 0x00,
            reg._REG_SHUTTER_MAX_BOUND_UPPER: 0x20,
            reg._REG_SROM_ID: 0x00,
            reg._REG_INVERSE_PRODUCT_ID: reg.INVERSE_PRODUCT_ID,
        }
        self._pending: dict[int, int] = {}
        self._pending_max_lower: int | None = None
        self._frame_period = 0x2EE0  # automatic rate starts at 2000 fps
        self._reported_counts = self._true_counts()  # the chip starts with a clear accumulator
        self._extra_counts = 0
        self._overflow = False
        self._latched = (0, 0, 0)  # motion, dx, dy frozen by a Motion read
        if not hasattr(self, "transactions"):
            self.transactions: deque[tuple[str, int]] = deque(maxlen=self._history)
            self.violations = 0
            self.motion_reads = 0

    # --- pins -----------------------------------------------------------------------------------
    def set_reset(self, high: bool) -> None:
        """Drive the RESET pin (active high); the falling edge after a high level resets the chip."""
        if self.reset_high and not high:
            self._power_on_registers()
            self.serial_up = True
            self.resets += 1
        self.reset_high = high

    def set_npd(self, high: bool) -> None:
        """Drive NPD (low = power-down: the chip answers nothing)."""
        self.powered = high

    def brownout(self) -> None:
        """A supply dip: the chip resets itself to its power-on registers (400 cpi, automatic frame rate)."""
        self._power_on_registers()

    # --- the bus --------------------------------------------------------------------------------
    def message(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        """One CS-low window (see `SpiBus`)."""
        if self.closed:
            raise SensorError(errno.EBADF, "fake SPI bus is closed")
        if self.fault is FakeFault.SPI_ERROR:
            raise SensorError(errno.EIO, "SPI transfer failed (injected)")
        if not segments:
            raise SpiProtocolError("empty SPI message")
        self.messages += 1
        self.wire_time_s += sum(len(sg.tx) * 8 / self.speed_hz + sg.delay_after_us * 1e-6 for sg in segments)
        if not self.serial_up or not self.powered or self.reset_high:
            return [bytes(len(sg.tx)) for sg in segments]  # nothing drives MISO
        first = segments[0]
        addr = first.tx[0]
        if addr & reg._WRITE_BIT:
            return self._write(segments)
        return self._read(segments)

    def close(self) -> None:
        """Close the fake bus; later transfers fail like a closed fd."""
        self.closed = True

    def _violation(self, msg: str) -> SpiProtocolError:
        self.violations += 1
        return SpiProtocolError(msg)

    def _write(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        seg = segments[0]
        if len(segments) != 1 or len(seg.tx) != 2:
            raise self._violation("a write is exactly address|0x80 and one data byte in one CS window")
        if seg.delay_after_us < reg.T_SWW_US:
            raise self._violation(f"write needs t_SWW >= {reg.T_SWW_US} us after it, got {seg.delay_after_us}")
        addr, value = seg.tx[0] & reg._ADDRESS_MASK, seg.tx[1]
        self.transactions.append(("write", addr))
        if addr == reg._REG_MOTION_CLEAR:
            self._reported_counts = self._true_counts()
            self._extra_counts = 0
            self._overflow = False
        elif (
            reg._REG_FRAME_PERIOD_MAX_BOUND_LOWER <= addr <= reg._REG_SHUTTER_MAX_BOUND_UPPER
            and self.clock() < self._busy_until_s
        ):
            raise self._violation("bound register written while Busy (wait two frames): the chip's state is undefined")
        elif addr == reg._REG_FRAME_PERIOD_MAX_BOUND_LOWER:
            self._pending_max_lower = value
        elif addr == reg._REG_FRAME_PERIOD_MAX_BOUND_UPPER:
            if self._pending_max_lower is None:
                raise self._violation("Frame_Period_Max_Bound: write Lower before Upper")
            new = dict(self.regs)
            new.update(self._pending)
            new[reg._REG_FRAME_PERIOD_MAX_BOUND_LOWER] = self._pending_max_lower
            new[addr] = value
            max_b = (value << 8) | self._pending_max_lower
            min_b = (new[reg._REG_FRAME_PERIOD_MIN_BOUND_UPPER] << 8) | new[reg._REG_FRAME_PERIOD_MIN_BOUND_LOWER]
            sh_b = (new[reg._REG_SHUTTER_MAX_BOUND_UPPER] << 8) | new[reg._REG_SHUTTER_MAX_BOUND_LOWER]
            self._pending_max_lower = None
            self._pending = {}
            if max_b < min_b + sh_b:
                raise self._violation(
                    f"Frame_Period_Max_Bound {max_b} < Frame_Period_Min_Bound {min_b} + Shutter_Max_Bound {sh_b}"
                )
            self.regs = new
            if self.regs[reg._REG_EXTENDED_CONFIG] & reg._EXT_FIXED_FR:
                self._frame_period = max_b
            self._busy_until_s = self.clock() + 2 * self._frame_period / reg.CLOCK_HZ
        elif reg._REG_FRAME_PERIOD_MIN_BOUND_LOWER <= addr <= reg._REG_SHUTTER_MAX_BOUND_UPPER:
            self._pending[addr] = value  # applied by the next Frame_Period_Max_Bound write
        elif addr in (reg._REG_CONFIGURATION_BITS, reg._REG_EXTENDED_CONFIG):
            self.regs[addr] = value & ~reg._EXT_BUSY if addr == reg._REG_EXTENDED_CONFIG else value
            if addr == reg._REG_EXTENDED_CONFIG and not value & reg._EXT_FIXED_FR:
                self._frame_period = 0x2EE0
        else:
            self.regs[addr] = value
        return [bytes(2)]

    def _read(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        addr_seg = segments[0]
        addr = addr_seg.tx[0]
        if len(segments) == 1:
            if len(addr_seg.tx) == 1:
                raise self._violation(
                    f"read of 0x{addr:02X}: address and data in different CS windows (CS high aborts it)"
                )
            raise self._violation(f"read of 0x{addr:02X}: no address-to-data gap inside the CS window")
        if len(segments) != 2 or len(addr_seg.tx) != 1:
            raise self._violation(f"read of 0x{addr:02X}: expected [address+gap, data] segments")
        need = reg.srad_us(addr)
        if addr_seg.delay_after_us < need:
            raise self._violation(
                f"read of 0x{addr:02X}: address-to-data gap {addr_seg.delay_after_us} us < t_SRAD {need} us"
            )
        n = len(segments[1].tx)
        if addr == reg._REG_MOTION_BURST:
            if n > reg.BURST_LEN:
                raise self._violation(f"Motion_Burst is {reg.BURST_LEN} bytes, {n} clocked")
            data = self._burst()[:n]
        else:
            if n != 1:
                raise self._violation(f"register 0x{addr:02X} read clocks 1 byte, got {n}")
            data = bytes([self._register(addr)])
        self.transactions.append(("read", addr))
        if self.fault is FakeFault.STUCK_BUS:
            data = b"\xff" * n
        return [b"\x00", data]

    # --- registers ------------------------------------------------------------------------------
    def _register(self, addr: int) -> int:
        if addr == reg._REG_PRODUCT_ID and self.fault is FakeFault.WRONG_ID:
            return 0x00
        if addr == reg._REG_INVERSE_PRODUCT_ID and self.fault is FakeFault.WRONG_ID:
            return 0x00
        if addr == reg._REG_MOTION:
            self._latch()
            return self._latched[0]
        if addr == reg._REG_DELTA_X:
            return self._latched[1] & 0xFF
        if addr == reg._REG_DELTA_Y:
            return self._latched[2] & 0xFF
        if addr == reg._REG_SQUAL:
            return self._squal()
        if addr == reg._REG_MAXIMUM_PIXEL:
            return 42
        if addr == reg._REG_FRAME_PERIOD_LOWER:
            return self._frame_period & 0xFF
        if addr == reg._REG_FRAME_PERIOD_UPPER:
            return self._frame_period >> 8
        if addr == reg._REG_EXTENDED_CONFIG:
            busy = reg._EXT_BUSY if self.clock() < self._busy_until_s else 0
            return self.regs[addr] | busy
        return self.regs.get(addr, 0x00)  # reads of invalid addresses return 0 [DS p.21]

    def _squal(self) -> int:
        return 2 if self.fault in (FakeFault.SQUAL_DROP, FakeFault.TRACKING_LOST) else self.squal_value

    def _cpm(self) -> float:
        res_1600 = self.regs[reg._REG_CONFIGURATION_BITS] & reg._CONFIG_RES_1600
        return self.counts_per_m if res_1600 else self.counts_per_m / 4

    def _true_counts(self) -> int:
        x = self.trajectory(self.clock()) * self.sign * self._cpm()
        return math.floor(x + self._rng.gauss(0.0, self.noise_counts)) if self.noise_counts else math.floor(x)

    def _latch(self) -> None:
        """A Motion read freezes the deltas: take what accumulated since the last report."""
        self.motion_reads += 1
        now = self._true_counts()
        if self.fault is FakeFault.TRACKING_LOST:
            self._reported_counts = now  # the motion is not seen, and lost
            self._latched = (self.reserved_motion_bits | self._res_bit(), 0, 0)
            return
        if self.fault is FakeFault.SATURATE:
            self._extra_counts += 400
        acc = now - self._reported_counts + self._extra_counts
        if abs(acc) > ACCUMULATOR_LIMIT:
            self._overflow = True
        along = max(reg.DELTA_MIN, min(reg.DELTA_MAX, acc))
        self._reported_counts = now
        self._extra_counts = acc - along  # what did not fit stays in the accumulator
        motion = reg._MOTION_MOT if (along or self._extra_counts) else 0
        if self._overflow:
            motion |= reg._MOTION_OVF
        motion |= self._res_bit() | self.reserved_motion_bits
        if self.axis == "y":
            self._latched = (motion, 0, along)
        else:
            self._latched = (motion, along, 0)

    def _res_bit(self) -> int:
        return reg._MOTION_RES if self.regs[reg._REG_CONFIGURATION_BITS] & reg._CONFIG_RES_1600 else 0

    def _burst(self) -> bytes:
        self._latch()
        motion, dx, dy = self._latched
        shutter = (self.regs[reg._REG_SHUTTER_UPPER] << 8) | self.regs[reg._REG_SHUTTER_LOWER]
        return bytes([motion, dx & 0xFF, dy & 0xFF, self._squal(), shutter >> 8, shutter & 0xFF, 42])
