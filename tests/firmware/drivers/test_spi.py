"""The ioctl packing of the real SPI backend (the part testable without a Pi)."""

from __future__ import annotations

import struct

import pytest

from rimless.firmware.drivers.spi import SPI_IOC_TRANSFER, SpidevBus, SpiSegment, pack_transfers, spi_ioc_message
from rimless.firmware.errors import SensorError


def test_spi_ioc_message_numbers() -> None:
    # _IOW('k', 0, char[n*32]) from linux/spi/spidev.h; 0x40406B00 for n = 2 (hardware.md).
    assert spi_ioc_message(2) == 0x40406B00
    assert spi_ioc_message(1) == 0x40206B00


def test_transfer_struct_layout() -> None:
    segs = [SpiSegment(b"\x50", 75), SpiSegment(bytes(7))]
    buf = pack_transfers(segs, [0x1000, 0x2000], [0x3000, 0x4000], 2_000_000)
    assert len(buf) == 64 and SPI_IOC_TRANSFER.size == 32
    tx, rx, n, speed, delay, bits, cs_change = struct.unpack_from("<QQIIHBB", buf, 0)
    assert (tx, rx, n, speed, delay, bits, cs_change) == (0x1000, 0x3000, 1, 2_000_000, 75, 8, 0)
    tx, rx, n, speed, delay, bits, cs_change = struct.unpack_from("<QQIIHBB", buf, 32)
    assert (tx, rx, n, delay, cs_change) == (0x2000, 0x4000, 7, 0, 0)


def test_segment_validation() -> None:
    with pytest.raises(ValueError):
        SpiSegment(b"")
    with pytest.raises(ValueError):
        SpiSegment(b"\x00", 70000)


def test_missing_device_node_is_a_clear_sensor_error() -> None:
    with pytest.raises(SensorError, match="spidev"):
        SpidevBus(6, 3)
