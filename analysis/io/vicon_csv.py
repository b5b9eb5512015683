"""Read Vicon CSV exports (Tracker 3.x and Nexus 2.x) into a `ViconFile` (`rimless.analysis.io.vicon_file`).

The reader is strict about structure and tolerant of the layout quirks real exports have:

- several sections per file (``Objects``, ``Trajectories``, ``Devices``, ``Joints``, ``Model Outputs``,
  ``Segments`` or any other title), each made of a title row, a rate row, a name row, a column-header row
  (``Frame``, ``Sub Frame``, components) and a units row, then data rows until a blank row;
- Tracker's ``Global Angle`` / ``Local Angle`` name prefix and repeated ``Obj:Obj`` names;
- units converted by what the units row says: mm / cm / m to m, deg / rad to rad (other units are kept);
- occlusions as empty cells or short rows (NaN), rows padded with delimiters, leading/trailing blank rows,
  CRLF / LF / CR, a UTF-8 BOM, ``,`` ``;`` or tab delimiters (``;`` with decimal commas too),
  3-digit exponents (``7.2e-006``), a first frame other than 1.

Every malformed input raises `ViconCsvError` naming the file, line and column (1-based) with a distinct
``cause``; nothing is returned half-parsed. Values are SI inside (m, rad, s).
"""

from __future__ import annotations

import io
import math
import re
import warnings
from pathlib import Path

import numpy as np

from rimless.analysis.io.byte_source import ByteSource
from rimless.analysis.io.vicon_file import (
    ANGLE_UNITS_RAD,
    LENGTH_UNITS_M,
    MAX_COORDINATE_M,
    RATE_RANGE_HZ,
    Column,
    Section,
    ViconFile,
)
from rimless.errors import InputFileError

__all__ = [
    "Column",
    "Section",
    "ViconCsvError",
    "ViconFile",
    "read_vicon_csv",
    "parse_vicon_bytes",
    "parse_vicon_text",
]

#: Components that must carry a length unit / an angle unit in pose and marker sections.
_LENGTH_COMPONENTS = frozenset({"X", "Y", "Z", "TX", "TY", "TZ"})
_ANGLE_COMPONENTS = frozenset({"RX", "RY", "RZ"})
#: Sections whose coordinate columns are checked against the unit tables.
_POSE_SECTIONS = frozenset({"Objects", "Trajectories", "Segments"})
_NAME_PREFIXES = ("Global Angle ", "Local Angle ")

# A line that cannot be a data row: anything not starting like a number (titles, header and blank rows).
_STRUCTURAL = re.compile(r"\n(?![0-9+\-.])")
# ASCII digits only: Python's \d also matches other scripts' digits, which no exporter writes.
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
#: At most this many errors are collected per file (the first, in file order, is the one raised).
MAX_ERRORS = 20
#: Largest frame number accepted (a day at 10 kHz is 8.6e8).
MAX_FRAME = 1e10


class ViconCsvError(InputFileError):
    """A Vicon CSV file cannot be parsed; the message names the file, line and column (1-based).

    Attributes
    ----------
    path, line, column : where the problem is (``line``/``column`` may be None for whole-file causes).
    cause : short stable code, one per kind of problem (e.g. ``"non-numeric"``, ``"duplicate-frame"``).
    """

    def __init__(self, path: str, line: int | None, column: int | None, cause: str, message: str):
        self.path, self.line, self.column, self.cause = path, line, column, cause
        self.detail = message
        where = path
        if line is not None:
            where += f", line {line}"
        if column is not None:
            where += f", column {column}"
        super().__init__(f"{where}: {message} [{cause}]")
        #: Every error found in the file (this one first), at most `MAX_ERRORS`.
        self.errors: list[ViconCsvError] = [self]

    def location(self) -> str:
        """``file:line:column: message [cause]`` (compiler style; line/column omitted when unknown)."""
        where = self.path + "".join(f":{v}" for v in (self.line, self.column) if v is not None)
        return f"{where}: {self.detail} [{self.cause}]"

    def all_locations(self) -> list[str]:
        """`location` of every collected error, in file order."""
        return [e.location() for e in self.errors]


# ----------------------------------------------------------------------------------------------- reading


def read_vicon_csv(path: str | Path) -> ViconFile:
    """Read a Vicon CSV export.

    Parameters
    ----------
    path : the file.

    Returns
    -------
    ViconFile with every section, lengths in m and angles in rad.

    Raises
    ------
    ViconCsvError
        On any malformed content, naming file, line, column and cause.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as err:
        raise ViconCsvError(str(p), None, None, "unreadable", f"cannot read the file ({err.strerror})") from None
    text, encoding, line_ending = _decode(raw)
    source = ByteSource.of(raw, p)  # newline offsets; the data blocks are read back from the file
    del raw  # only the text stays in memory while the blocks are parsed
    return _parse(text, str(p), encoding, line_ending, source)


def _decode(raw: bytes) -> tuple[str, str, str]:
    """(text with LF line ends, encoding, line ending of the file)."""
    encoding = "utf-8"
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("cp1252", errors="replace")
        encoding = "cp1252"
    line_ending = _line_ending(text)
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return text, encoding, line_ending


def parse_vicon_bytes(raw: bytes, name: str = "<bytes>") -> ViconFile:
    """Parse the bytes of a Vicon CSV export (see `read_vicon_csv`).

    The header rows are read from the decoded text; the numeric data blocks are read by pandas' C parser
    straight from ``raw`` (in chunks, into preallocated arrays), so no second copy of the file is made.
    """
    text, encoding, line_ending = _decode(raw)
    return _parse(text, name, encoding, line_ending, ByteSource.of(raw))


def parse_vicon_text(text: str, name: str = "<text>", *, encoding: str = "utf-8") -> ViconFile:
    """Parse the text of a Vicon CSV export (see `read_vicon_csv`); ``name`` is used in messages."""
    if text.startswith("\ufeff"):
        text = text[1:]
    line_ending = _line_ending(text)
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    return _parse(text, name, encoding, line_ending, None)


def _line_ending(text: str) -> str:
    if "\r" not in text:  # one scan of the text in the common case
        return "\n"
    return "\r\n" if "\r\n" in text else "\r"


def _parse(text: str, name: str, encoding: str, line_ending: str, raw: ByteSource | None) -> ViconFile:
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise ViconCsvError(name, line, None, "binary", "the file holds NUL bytes: it is not a CSV text file")
    if not re.search(r"[^ \t\n,;]", text):  # no copy of a large file, unlike strip()
        raise ViconCsvError(name, None, None, "empty", "the file holds no content")
    parser = _Parser(text, name, raw)
    sections = parser.parse()
    return ViconFile(
        path=name,
        sections=tuple(sections),
        delimiter=parser.delim,
        decimal=parser.decimal,
        encoding=encoding,
        line_ending=line_ending,
    )


def _detect_delimiter(text: str) -> str:
    head = text[:20000]
    counts = {d: head.count(d) for d in (",", ";", "\t")}
    best = max(counts, key=lambda d: counts[d])
    return best if counts[best] else ","


class _Parser:
    """Walks the structural lines of a file; data blocks are parsed in bulk."""

    def __init__(self, text: str, name: str, raw: ByteSource | None = None) -> None:
        self.text = text
        self.name = name
        #: The file's bytes, whose lines are the lines of ``text`` (or None: blocks are encoded from ``text``).
        self.raw = raw
        self.delim = _detect_delimiter(text)
        self.decimal = "."
        if self.delim == ";":
            # Decimal commas: a data row (starts with a digit) that holds a comma.
            m = re.search(r"(?m)^\d[^\n]*,", text[:200000])
            if m:
                self.decimal = ","
        # Line starts of lines that cannot be data rows.
        starts = [0] if text and text[0] not in "0123456789+-." else []
        starts += [m.start() + 1 for m in _STRUCTURAL.finditer(text)]
        self.struct = [s for s in starts if s < len(text)]
        self.ends_with_newline = text.endswith("\n")
        #: errors of the data rows found so far (every section); raised together, in file order, at the end
        self.pending: list[ViconCsvError] = []

    # -- helpers
    def err(self, line: int | None, column: int | None, cause: str, message: str) -> ViconCsvError:
        return ViconCsvError(self.name, line, column, cause, message)

    def line_at(self, pos: int) -> str:
        end = self.text.find("\n", pos)
        return self.text[pos:] if end < 0 else self.text[pos:end]

    def next_line_pos(self, pos: int) -> int:
        end = self.text.find("\n", pos)
        return len(self.text) if end < 0 else end + 1

    def cells(self, line: str) -> list[str]:
        return [c.strip() for c in line.split(self.delim)]

    @staticmethod
    def is_blank(cells: list[str]) -> bool:
        return not any(cells)

    def starts_section(self, pos: int) -> bool:
        """Whether the line at ``pos`` opens a section: a title cell alone, then (three lines on) a column
        header row starting with 'Frame'. A title-like row without that header is a data row with a bad frame."""
        cells = self.cells(self.line_at(pos))
        if not (cells[0] and not any(cells[1:]) and not _NUMBER.fullmatch(cells[0])):
            return False
        for _ in range(3):
            pos = self.next_line_pos(pos)
            if pos >= len(self.text):
                return True  # a title at the end of the file: parse_section says what is missing
        return self.cells(self.line_at(pos))[0] == "Frame"

    # -- structure
    def parse(self) -> list[Section]:
        text = self.text
        sections: list[Section] = []
        line_no = 1
        last_pos = 0
        k = 0
        struct = self.struct
        lead = re.match(r"(?:[ ,;\t]*\n)*", text)
        first = lead.end() if lead else 0
        if first < len(text) and text[first] in "0123456789+-.":
            raise self.err(
                text.count("\n", 0, first) + 1,
                1,
                "missing-title",
                "the file starts with a number: no section title row (e.g. 'Trajectories') above it",
            )
        while k < len(struct):
            pos = struct[k]
            line_no += text.count("\n", last_pos, pos)
            last_pos = pos
            cells = self.cells(self.line_at(pos))
            if self.is_blank(cells):
                k += 1
                continue
            if cells[0] and not any(cells[1:]) and not _NUMBER.fullmatch(cells[0]):
                try:
                    section, data_end = self.parse_section(cells[0], pos, line_no)
                except ViconCsvError as err:  # a structural error: what was found before it comes first
                    raise self._collect([*self.pending, *err.errors]) from None
                sections.append(section)
                # Skip structural lines inside the section's header and data.
                while k < len(struct) and struct[k] < data_end:
                    k += 1
                continue
            if cells[0] == "Frame":
                raise self.err(
                    line_no,
                    1,
                    "missing-title",
                    "column header row without a section title row (e.g. 'Trajectories') above it",
                )
            raise self.err(
                line_no,
                1,
                "unexpected-row",
                f"expected a section title such as 'Objects' or 'Trajectories', found {_show(cells)}",
            )
        if self.pending:
            raise self._collect(self.pending)
        if not sections:
            # Data rows but no structural line: the file starts with numbers.
            raise self.err(1, 1, "missing-title", "no section title row (e.g. 'Objects' or 'Trajectories') found")
        return sections

    def header_line(self, pos: int, line_no: int, what: str, kind: str) -> tuple[list[str], int]:
        if pos >= len(self.text):
            raise self.err(
                line_no,
                None,
                "truncated-header",
                f"the file ends before the {what} row of section {kind!r} (truncated?)",
            )
        return self.cells(self.line_at(pos)), self.next_line_pos(pos)

    def parse_section(self, kind: str, pos: int, line_no: int) -> tuple[Section, int]:
        title_line = line_no
        pos = self.next_line_pos(pos)
        rate_cells, pos = self.header_line(pos, line_no + 1, "rate", kind)
        rate = _to_float(rate_cells[0]) if rate_cells and rate_cells[0] else None
        lo_hz, hi_hz = RATE_RANGE_HZ
        if rate is None or not math.isfinite(rate) or not lo_hz <= rate <= hi_hz:
            shown = rate_cells[0] if rate_cells and rate_cells[0] else "(empty)"
            raise self.err(
                line_no + 1,
                1,
                "bad-rate",
                f"the rate row of section {kind!r} must hold a frame rate of {lo_hz:g}-{hi_hz:g} Hz, "
                f"found {shown[:40]!r}",
            )
        names, pos = self.header_line(pos, line_no + 2, "name", kind)
        comps, pos = self.header_line(pos, line_no + 3, "column header", kind)
        if not comps or comps[0] != "Frame":
            raise self.err(
                line_no + 3,
                1,
                "bad-header",
                f"section {kind!r}: the column header row must start with 'Frame', found {_show(comps)}",
            )
        first_data = 2 if len(comps) > 1 and comps[1] == "Sub Frame" else 1
        units_line = line_no + 4
        units, pos = self.header_line(pos, units_line, "units", kind)
        if units and _NUMBER.fullmatch(units[0]):
            raise self.err(
                units_line,
                1,
                "missing-units",
                f"section {kind!r}: expected the units row under the column header, found a data row",
            )
        last = max((i for i, c in enumerate(comps) if c), default=0)
        n_cols = last + 1 - first_data
        if n_cols <= 0:
            raise self.err(line_no + 3, None, "bad-header", f"section {kind!r} has no data columns")
        columns, prefix = self.build_columns(kind, names, comps, units, first_data, last, line_no)

        # The data block runs to the next structural line.
        data_start = pos
        data_line = line_no + 5
        nxt = next((s for s in self.struct if s >= data_start), len(self.text))
        bad_row: ViconCsvError | None = None  # a row of this block whose frame cell is not a number
        if nxt < len(self.text):
            cells = self.cells(self.line_at(nxt))
            if not self.is_blank(cells) and not self.starts_section(nxt):
                bad_line = data_line + self.text.count("\n", data_start, nxt)
                cell = cells[0] if cells[0] else "(empty)"
                # raised after the rows above it are read: their errors come first, in file order
                bad_row = self.err(bad_line, 1, "bad-frame", f"section {kind!r}: frame number {cell!r} is not a number")
        width = max(len(comps), len(units), first_data + n_cols)
        bounds = self.group_bounds(columns, first_data)
        lead, data, extra_at = self.parse_block(
            data_start, nxt, data_line, width, kind, first_data, n_cols, bounds=bounds
        )
        frame, sub = self.check_frames(lead, data_line, first_data, kind)
        if extra_at is not None:
            r, c = extra_at
            self.pending.append(
                self.err(
                    data_line + int(r),
                    int(first_data + n_cols + c + 1),
                    "extra-cell",
                    f"section {kind!r}: a value lies beyond the last column of the header",
                )
            )
        bad = np.isinf(data)
        for r, c in np.argwhere(bad)[:MAX_ERRORS]:
            self.pending.append(
                self.err(
                    data_line + int(r), int(first_data + c + 1), "non-finite", f"section {kind!r}: value is infinite"
                )
            )
        del bad
        # Convert to SI by what the units row says (in place: ``data`` is ours).
        _to_si_inplace(data, [c.file_unit for c in columns])
        if kind in _POSE_SECTIONS:
            big = (data > MAX_COORDINATE_M) | (data < -MAX_COORDINATE_M)
            for r, c in np.argwhere(big)[:MAX_ERRORS]:
                self.pending.append(
                    self.err(
                        data_line + int(r),
                        int(first_data + c + 1),
                        "out-of-range",
                        f"section {kind!r}: value beyond {MAX_COORDINATE_M:.0e} m (or rad): "
                        "not a position in a capture volume",
                    )
                )
        if bad_row is not None:
            raise bad_row
        section = Section(
            kind=kind,
            rate_hz=float(rate),
            line=title_line,
            frame=frame,
            sub_frame=sub,
            columns=tuple(columns),
            values=data,
            name_prefix=prefix,
            data_line=data_line,
            units_line=units_line,
        )
        return section, nxt

    def build_columns(
        self, kind: str, names: list[str], comps: list[str], units: list[str], first_data: int, last: int, line_no: int
    ) -> tuple[list[Column], str]:
        columns: list[Column] = []
        group = ""
        prefix = ""
        for i in range(first_data, last + 1):
            if i < len(names) and names[i]:
                group, p = _clean_name(names[i])
                prefix = prefix or p
            comp = comps[i]
            file_unit = units[i] if i < len(units) else ""
            if kind in _POSE_SECTIONS:
                if comp in _LENGTH_COMPONENTS and file_unit not in LENGTH_UNITS_M:
                    raise self.err(
                        line_no + 4,
                        i + 1,
                        "bad-unit",
                        f"section {kind!r}: unit {file_unit or '(empty)'!r} of {comp} ({group}) is not "
                        f"a length unit ({', '.join(LENGTH_UNITS_M)})",
                    )
                if comp in _ANGLE_COMPONENTS and file_unit not in ANGLE_UNITS_RAD:
                    raise self.err(
                        line_no + 4,
                        i + 1,
                        "bad-unit",
                        f"section {kind!r}: unit {file_unit or '(empty)'!r} of {comp} ({group}) is not "
                        f"an angle unit (rad, deg)",
                    )
            unit = "m" if file_unit in LENGTH_UNITS_M else ("rad" if file_unit in ANGLE_UNITS_RAD else file_unit)
            columns.append(Column(group=group, component=comp, unit=unit, file_unit=file_unit, column=i + 1))
        return columns, prefix

    @staticmethod
    def group_bounds(columns: list[Column], first_data: int) -> frozenset[int]:
        """Cell counts a short row may have: the frame cells, or whole groups (an occluded tail)."""
        ends = {first_data, 1}
        for a, b in zip(columns, columns[1:]):
            if a.group != b.group:
                ends.add(a.column)
        return frozenset(ends)

    def check_cell_counts(
        self, start: int, end: int, data_line: int, width: int, kind: str, bounds: frozenset[int], rows: np.ndarray
    ) -> None:
        """A row shorter than the header that does not end at a group boundary lost a cell: error.

        Only rows with a missing value can be short, so only ``rows`` (block row indices whose last cell is
        empty) are counted.
        """
        if rows.size == 0:
            return
        delim = self.delim.encode()
        rows_l = rows.tolist()
        if self.raw is not None:
            base = data_line - 1  # 0-based line of block row 0
            ls = self.raw.line_start
            n_delims = self.raw.counts(delim, [(ls(base + r), ls(base + r + 1) - 1) for r in rows_l])
        else:
            data = self.text[start:end].encode("utf-8", "surrogatepass")
            nl = np.flatnonzero(np.frombuffer(data, np.uint8) == 10)
            starts = np.concatenate([[0], nl + 1])
            n_delims = [
                data.count(delim, int(starts[r]), int(starts[r + 1]) - 1 if r + 1 < starts.size else len(data))
                for r in rows_l
            ]
        errs = []
        for r, n_delim in zip(rows_l, n_delims):
            n_cells = n_delim + 1
            if n_cells < width and n_cells not in bounds:
                errs.append(
                    self.err(
                        data_line + int(r),
                        n_cells + 1,
                        "missing-cell",
                        f"section {kind!r}: the row has {n_cells} cells and ends inside a "
                        f"marker/object (the header has {width}): a cell is missing, values would be "
                        "shifted",
                    )
                )
                if len(errs) >= MAX_ERRORS:
                    break
        self.pending.extend(errs)

    @staticmethod
    def _collect(errs: list[ViconCsvError]) -> ViconCsvError:
        """The first error in file order (line, then column; whole-file causes last), carrying up to
        `MAX_ERRORS` of them in file order; one error per cell."""
        seen: set[tuple] = set()
        uniq = []
        for e in errs:
            key = (e.line, e.column)
            if key in seen and e.line is not None:
                continue
            seen.add(key)
            uniq.append(e)
        uniq.sort(key=lambda e: (e.line if e.line is not None else math.inf, e.column if e.column is not None else 0))
        first = uniq[0]
        first.errors = uniq[:MAX_ERRORS]
        return first

    # -- data
    def parse_block(
        self,
        start: int,
        end: int,
        data_line: int,
        width: int,
        kind: str,
        first_data: int,
        n_cols: int,
        bounds: frozenset[int] = frozenset(),
    ) -> tuple[np.ndarray, np.ndarray, tuple[int, int] | None]:
        """Read the data rows in ``text[start:end]``.

        Returns (frame cells (n, first_data), data (n, n_cols) C-contiguous and owned, (row, column) of the
        first value beyond the data columns or None).
        """
        text = self.text
        if not re.compile(r"\S").search(text, start, end):
            return np.zeros((0, first_data)), np.zeros((0, n_cols)), None
        n_rows = text.count("\n", start, end) + (0 if text.endswith("\n", start, end) else 1)
        if end >= len(text) and not self.ends_with_newline:
            last = text.rfind("\n", start, end) + 1
            n_cells = text.count(self.delim, last, end) + 1
            if n_cells < width:
                line = data_line + n_rows - 1
                trunc = self.err(
                    line,
                    n_cells,
                    "truncated",
                    f"section {kind!r}: the file ends in the middle of a row ({n_cells} of {width} "
                    "cells and no line end): truncated file?",
                )
                # the rows before it are read (their errors come first, in file order); the cut row is dropped
                self.pending.append(trunc)
                return self.parse_block(start, last, data_line, width, kind, first_data, n_cols, bounds)
        out = self.fast_block(start, end, data_line, n_rows, width, first_data, n_cols)
        if out is None:
            values = self.slow_block(text[start:end], data_line, width, kind)
            lead = values[:, :first_data]
            data = np.ascontiguousarray(values[:, first_data : first_data + n_cols])
            extra = values[:, first_data + n_cols :]
            extra_at = None
            if extra.size and not np.isnan(extra).all():
                r, c = np.argwhere(~np.isnan(extra))[0]
                extra_at = (int(r), int(c))
            short = np.flatnonzero(np.isnan(values[:, -1]))
        else:
            lead, data, extra_at, short = out
        if bounds:
            self.check_cell_counts(start, end, data_line, width, kind, bounds, short)
        return lead, data, extra_at

    #: Rows per pandas chunk: bounds the parser's temporary memory.
    CHUNK_ROWS = 200_000

    def fast_block(
        self, start: int, end: int, data_line: int, n_rows: int, width: int, first_data: int, n_cols: int
    ) -> tuple[np.ndarray, np.ndarray, tuple[int, int] | None, np.ndarray] | None:
        """Bulk parse with pandas' C reader, in chunks, into preallocated arrays.

        Reads the bytes of the block from ``raw`` when the file's bytes are at hand (no copy), else an encoded
        copy of the text. Returns (lead, data, first extra (row, column) or None, rows whose last cell is
        empty), or None to send the block to `slow_block` (which locates errors).
        """
        import pandas as pd

        if self.raw is not None:
            a, b = self.raw.line_start(data_line - 1), self.raw.line_start(data_line - 1 + n_rows)
            source: io.RawIOBase | io.BytesIO = self.raw.stream(a, b)
        else:
            source = io.BytesIO(self.text[start:end].encode("utf-8", "surrogatepass"))
        lead = np.empty((n_rows, first_data))
        data = np.empty((n_rows, n_cols))
        extra_at: tuple[int, int] | None = None
        short: list[np.ndarray] = []
        k = 0
        stop = first_data + n_cols
        try:
            with warnings.catch_warnings():
                # A row wider than the header makes pandas drop cells with a warning: take the slow path.
                warnings.simplefilter("error", pd.errors.ParserWarning)
                reader = pd.read_csv(
                    source,
                    sep=self.delim,
                    header=None,
                    names=range(width),
                    dtype=np.float64,
                    na_values=[""],
                    keep_default_na=False,
                    decimal=self.decimal,
                    engine="c",
                    skip_blank_lines=False,
                    index_col=False,
                    chunksize=self.CHUNK_ROWS,
                )
                with reader:
                    for chunk in reader:
                        v = chunk.to_numpy(dtype=np.float64)
                        m = v.shape[0]
                        if k + m > n_rows:
                            return None
                        lead[k : k + m] = v[:, :first_data]
                        data[k : k + m] = v[:, first_data:stop]
                        if extra_at is None and v.shape[1] > stop:
                            seen = ~np.isnan(v[:, stop:])
                            if seen.any():
                                r, c = np.argwhere(seen)[0]
                                extra_at = (k + int(r), int(c))
                        short.append(np.flatnonzero(np.isnan(v[:, -1])) + k)
                        k += m
        except (ValueError, pd.errors.ParserError, pd.errors.ParserWarning):
            return None
        finally:
            source.close()
        if k != n_rows:
            return None
        return lead, data, extra_at, np.concatenate(short) if short else np.zeros(0, np.int64)

    def slow_block(self, block: str, data_line: int, width: int, kind: str) -> np.ndarray:
        lines = block.split("\n")
        if lines and lines[-1] == "":
            lines.pop()
        out = np.full((len(lines), width), np.nan)
        errs: list[ViconCsvError] = []
        for r, line in enumerate(lines):
            cells = line.split(self.delim)
            if len(cells) > width:
                for c in range(width, len(cells)):
                    if cells[c].strip():
                        errs.append(
                            self.err(
                                data_line + r,
                                c + 1,
                                "extra-cell",
                                f"section {kind!r}: a value lies beyond the last column of the header",
                            )
                        )
                        break
                cells = cells[:width]
            for c, cell in enumerate(cells):
                s = cell.strip()
                if not s:
                    continue
                if self.decimal == ",":
                    s = s.replace(",", ".")
                if not _NUMBER.fullmatch(s):
                    what = (
                        "is not a number (digits must be ASCII 0-9)"
                        if any(ch.isdigit() and not ch.isascii() for ch in s)
                        else "is not a number"
                    )
                    errs.append(
                        self.err(
                            data_line + r, c + 1, "non-numeric", f"section {kind!r}: cell {cell.strip()[:40]!r} {what}"
                        )
                    )
                    continue
                out[r, c] = float(s)
            if len(errs) >= MAX_ERRORS:
                break
        self.pending.extend(errs)
        return out

    def check_frames(
        self, values: np.ndarray, data_line: int, first_data: int, kind: str
    ) -> tuple[np.ndarray, np.ndarray]:
        """Frame (and sub frame) numbers of the rows; every bad one, a repeat or a step back is added to
        ``pending`` (rows with a bad number are left out of the order check). Bad numbers are returned as -1."""
        if values.shape[0] == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        f = values[:, 0]
        bad = np.isnan(f) | (f != np.round(f)) | (f < 0) | (f > MAX_FRAME)
        for r in np.flatnonzero(bad)[:MAX_ERRORS]:
            self.pending.append(
                self.err(
                    data_line + int(r),
                    1,
                    "bad-frame",
                    f"section {kind!r}: frame number must be an integer from 0 to {MAX_FRAME:.0e}",
                )
            )
        frame = np.where(bad, -1.0, f).astype(np.int64)
        if first_data == 2:
            s = values[:, 1]
            s = np.where(np.isnan(s), 0.0, s)  # Nexus writes an empty Sub Frame where nothing was computed
            bad_s = (s != np.round(s)) | (s < 0) | (s > MAX_FRAME)
            for r in np.flatnonzero(bad_s)[:MAX_ERRORS]:
                self.pending.append(
                    self.err(
                        data_line + int(r),
                        2,
                        "bad-frame",
                        f"section {kind!r}: sub frame must be a non-negative integer",
                    )
                )
            bad = bad | bad_s
            sub = np.where(bad_s, 0, s).astype(np.int64)
        else:
            sub = np.zeros_like(frame)
        rows = np.flatnonzero(~bad)
        if rows.size < 2:
            return frame, sub
        key = frame[rows] * (int(sub[rows].max()) + 1) + sub[rows]
        d = np.diff(key)
        for i in np.flatnonzero(d <= 0)[:MAX_ERRORS]:
            r, r0 = int(rows[i + 1]), int(rows[i])
            if d[i] == 0:
                self.pending.append(
                    self.err(
                        data_line + r,
                        1,
                        "duplicate-frame",
                        f"section {kind!r}: frame {frame[r]} (sub frame {sub[r]}) appears "
                        f"twice (first at line {data_line + r0})",
                    )
                )
            else:
                self.pending.append(
                    self.err(
                        data_line + r,
                        1,
                        "frame-order",
                        f"section {kind!r}: frame {frame[r]} comes after frame {frame[r0]}: "
                        "frames must increase (a second take pasted after the first? split "
                        "the file at this line)",
                    )
                )
        return frame, sub


def _to_float(s: str) -> float | None:
    if not _NUMBER.fullmatch(s):
        return None
    return float(s)


_DIVISORS = {"mm": 1000.0, "cm": 100.0}


def _to_si_inplace(data: np.ndarray, units: list[str]) -> None:
    """Convert columns to m / rad in place (mm and cm by exact division, so 409.832 mm is 0.409832 m)."""
    for j, unit in enumerate(units):
        if unit in _DIVISORS:
            data[:, j] /= _DIVISORS[unit]
        elif unit in ANGLE_UNITS_RAD and ANGLE_UNITS_RAD[unit] != 1.0:
            data[:, j] *= ANGLE_UNITS_RAD[unit]


def _clean_name(name: str) -> tuple[str, str]:
    prefix = ""
    for p in _NAME_PREFIXES:
        if name.startswith(p):
            prefix, name = p.strip(), name[len(p) :]
            break
    if ":" in name:
        a, b = name.split(":", 1)
        if a == b:
            name = a
    return name, prefix


def _show(cells: list[str]) -> str:
    while cells and not cells[-1]:
        cells = cells[:-1]
    s = ",".join(cells)
    return repr(s[:60] + ("..." if len(s) > 60 else ""))
