"""SPI transport: the `SpiBus` protocol, the Linux spidev ioctl backend and the packing helpers.

The ADNS-3080 needs a 50-75 us gap between the address byte and the first data byte *inside one
chip-select window* (datasheet p.11, p.15). py-spidev's `xfer2(..., delay_usec)` only waits after the
last byte, and two `xfer2` calls pulse CS high in between, which aborts the transaction. So a bus
message is a list of segments sent as one `SPI_IOC_MESSAGE(n)` ioctl: each segment is one
`struct spi_ioc_transfer`, whose `delay_usecs` is the wait after that segment with CS still low.
"""

from __future__ import annotations

import ctypes
import errno
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from rimless.firmware.errors import SensorError

# Linux include/uapi/linux/spi/spidev.h: _IOW(SPI_IOC_MAGIC, nr, size), SPI_IOC_MAGIC = 'k'.
_IOC_WRITE = 1
_IOC_NRBITS, _IOC_TYPEBITS, _IOC_SIZEBITS = 8, 8, 14
_IOC_TYPESHIFT = _IOC_NRBITS
_IOC_SIZESHIFT = _IOC_TYPESHIFT + _IOC_TYPEBITS
_IOC_DIRSHIFT = _IOC_SIZESHIFT + _IOC_SIZEBITS
SPI_IOC_MAGIC = ord("k")

# struct spi_ioc_transfer, 32 bytes little-endian: u64 tx_buf, u64 rx_buf, u32 len, u32 speed_hz,
# u16 delay_usecs, u8 bits_per_word, u8 cs_change, u8 tx_nbits, u8 rx_nbits, u8 word_delay_usecs, u8 pad.
SPI_IOC_TRANSFER = struct.Struct("<QQIIHBBBBBB")
assert SPI_IOC_TRANSFER.size == 32

SPI_MODE_3 = 3  # CPOL=1, CPHA=1: SCLK idles high, sampled on the rising edge (ADNS-3080 p.15)
SPI_NO_CS = 0x40  # mode flag: the driver leaves chip select alone (a GPIO selects the device)
MAX_DELAY_US = 0xFFFF  # delay_usecs is a u16


def _iow(nr: int, size: int) -> int:
    return (_IOC_WRITE << _IOC_DIRSHIFT) | (size << _IOC_SIZESHIFT) | (SPI_IOC_MAGIC << _IOC_TYPESHIFT) | nr


def spi_ioc_message(n: int) -> int:
    """The ioctl request number `SPI_IOC_MESSAGE(n)` for `n` transfers (n=2 gives 0x40406B00)."""
    return _iow(0, n * SPI_IOC_TRANSFER.size)


SPI_IOC_WR_MODE = _iow(1, 1)
SPI_IOC_WR_BITS_PER_WORD = _iow(3, 1)
SPI_IOC_WR_MAX_SPEED_HZ = _iow(4, 4)


@dataclass(frozen=True, slots=True)
class SpiSegment:
    """One part of a CS-low window: bytes to send, then a wait of `delay_after_us` with CS still low."""

    tx: bytes
    delay_after_us: int = 0

    def __post_init__(self) -> None:
        if not self.tx:
            raise ValueError("an SPI segment needs at least one byte")
        if not 0 <= self.delay_after_us <= MAX_DELAY_US:
            raise ValueError(f"delay_after_us must be in 0..{MAX_DELAY_US}, got {self.delay_after_us}")


@runtime_checkable
class SpiBus(Protocol):
    """A full-duplex SPI bus; `message` is one chip-select window, CS released at its end."""

    def message(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        """Send the segments in one CS-low window; return the bytes received during each."""
        ...

    def close(self) -> None:
        """Release the bus."""
        ...


def pack_transfers(
    segments: Sequence[SpiSegment], tx_addrs: Sequence[int], rx_addrs: Sequence[int], speed_hz: int
) -> bytes:
    """Pack `struct spi_ioc_transfer[n]` for the segments, given the addresses of their tx/rx buffers."""
    out = bytearray()
    for seg, tx, rx in zip(segments, tx_addrs, rx_addrs, strict=True):
        out += SPI_IOC_TRANSFER.pack(tx, rx, len(seg.tx), speed_hz, seg.delay_after_us, 8, 0, 0, 0, 0, 0)
    return bytes(out)


class SpidevBus:
    """The real bus on the Pi: `/dev/spidev<bus>.<device>`, mode 3, one ioctl per message.

    spidev (the Python package) is only used to open and configure the node when it is installed;
    without it the node is opened and configured with the same ioctls directly.
    """

    def __init__(self, bus: int = 0, device: int = 0, *, speed_hz: int = 2_000_000, no_cs: bool = False) -> None:
        self.path = f"/dev/spidev{bus}.{device}"
        self.speed_hz = int(speed_hz)
        self._spidev = None
        try:
            import spidev  # only on the Pi
        except ImportError:
            spidev = None
        try:
            if spidev is not None:
                dev = spidev.SpiDev()
                dev.open(bus, device)
                dev.mode = SPI_MODE_3
                dev.no_cs = no_cs
                dev.max_speed_hz = self.speed_hz
                dev.bits_per_word = 8
                self._spidev = dev
                self._fd = dev.fileno()
            else:
                self._fd = os.open(self.path, os.O_RDWR)
                import fcntl

                fcntl.ioctl(self._fd, SPI_IOC_WR_MODE, struct.pack("<B", SPI_MODE_3 | (SPI_NO_CS if no_cs else 0)))
                fcntl.ioctl(self._fd, SPI_IOC_WR_BITS_PER_WORD, struct.pack("<B", 8))
                fcntl.ioctl(self._fd, SPI_IOC_WR_MAX_SPEED_HZ, struct.pack("<I", self.speed_hz))
        except FileNotFoundError as err:
            msg = f"{self.path} does not exist: enable SPI (dtparam=spi=on or raspi-config)"
            raise SensorError(errno.ENOENT, msg) from err
        except OSError as err:
            raise SensorError(err.errno or errno.EIO, f"cannot open {self.path}: {err}") from err

    def message(self, segments: Sequence[SpiSegment]) -> list[bytes]:
        """One `SPI_IOC_MESSAGE(len(segments))` ioctl: all segments in one CS-low window."""
        import fcntl

        txs = [ctypes.create_string_buffer(bytes(s.tx), len(s.tx)) for s in segments]
        rxs = [ctypes.create_string_buffer(len(s.tx)) for s in segments]
        buf = bytearray(
            pack_transfers(
                segments, [ctypes.addressof(b) for b in txs], [ctypes.addressof(b) for b in rxs], self.speed_hz
            )
        )
        try:
            fcntl.ioctl(self._fd, spi_ioc_message(len(segments)), buf)
        except OSError as err:
            raise SensorError(err.errno or errno.EIO, f"SPI transfer on {self.path} failed: {err}") from err
        return [rx.raw for rx in rxs]

    def close(self) -> None:
        """Close the device node."""
        if self._spidev is not None:
            self._spidev.close()
            self._spidev = None
        elif self._fd >= 0:
            os.close(self._fd)
        self._fd = -1
