"""Byte ranges of a file read as binary streams without a copy: the Vicon CSV reader hands its data blocks
to pandas' C parser straight from the file (or from the bytes in memory) with these."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

__all__ = ["ByteSource"]


class ByteSource:
    """The bytes of a file whose lines are the lines of its decoded text (every CR is part of a CRLF):
    newline offsets, and byte ranges read from memory or from the file."""

    def __init__(self, newlines: np.ndarray, size: int, raw: bytes | None, path: Path | None) -> None:
        self.newlines, self.size, self.raw, self.path = newlines, size, raw, path

    @classmethod
    def of(cls, raw: bytes, path: Path | None = None) -> ByteSource | None:
        """Newline offsets of ``raw`` (found in slices: no file-sized temporary); keeps ``raw`` when no path
        is given. None when line numbers in ``raw`` differ from the text's (a lone CR)."""
        if b"\r" in raw and raw.count(b"\r") != raw.count(b"\r\n"):
            return None
        parts = []
        step = 1 << 24
        for off in range(0, len(raw), step):
            chunk = np.frombuffer(raw, np.uint8, count=min(step, len(raw) - off), offset=off)
            parts.append(np.flatnonzero(chunk == 10) + off)
        nl = np.concatenate(parts) if parts else np.zeros(0, np.int64)
        return cls(nl, len(raw), raw if path is None else None, path)

    def _open(self) -> io.BufferedReader:
        """The file, opened for reading bytes (``raw`` is kept whenever there is no ``path``: see `of`)."""
        if self.path is None:
            raise ValueError("a ByteSource holds either the bytes or the path of its file")
        return open(self.path, "rb")

    def line_start(self, line0: int) -> int:
        """Byte offset of the start of 0-based line ``line0`` (the size past the last line)."""
        if line0 <= 0:
            return 0
        return int(self.newlines[line0 - 1]) + 1 if line0 - 1 < self.newlines.size else self.size

    def stream(self, a: int, b: int) -> io.RawIOBase:
        """Bytes ``a:b`` as a binary stream (no copy of the range)."""
        if self.raw is not None:
            return _ViewReader(memoryview(self.raw)[a:b])
        return _FileRange(self._open(), a, b)

    def counts(self, sub: bytes, spans: list[tuple[int, int]]) -> list[int]:
        """``sub`` occurrences in each byte span."""
        if self.raw is not None:
            return [self.raw.count(sub, a, b) for a, b in spans]
        out = []
        with self._open() as f:
            for a, b in spans:
                f.seek(a)
                out.append(f.read(b - a).count(sub))
        return out


class _ViewReader(io.RawIOBase):
    """A read-only binary stream over a memoryview (pandas reads it without a copy of the whole)."""

    def __init__(self, view: memoryview) -> None:
        super().__init__()
        self._view, self._pos = view, 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = min(len(buffer), len(self._view) - self._pos)
        buffer[:n] = self._view[self._pos : self._pos + n]
        self._pos += n
        return n


class _FileRange(io.RawIOBase):
    """Bytes ``a:b`` of an open binary file, as a stream (closes the file when closed)."""

    def __init__(self, f: io.BufferedReader, a: int, b: int) -> None:
        super().__init__()
        self._f, self._left = f, b - a
        f.seek(a)

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = self._f.readinto(memoryview(buffer)[: min(len(buffer), self._left)])
        self._left -= n
        return n

    def close(self) -> None:
        self._f.close()
        super().close()
