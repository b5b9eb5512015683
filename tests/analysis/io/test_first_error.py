"""The first error in file order comes first (in the exception and in `all_locations`), also when the file
is truncated at its end. The export is written here by hand (an Objects section of 60 rows: data on lines 6-65)."""

from __future__ import annotations

import pytest

from rimless.analysis.io.vicon_csv import ViconCsvError, read_vicon_csv


def _export(n: int = 60) -> list[str]:
    lines = [
        "Objects",
        "100",
        ",,Global Angle Wheel:Wheel,,,,,",
        "Frame,Sub Frame,RX,RY,RZ,TX,TY,TZ",
        ",,rad,rad,rad,mm,mm,mm",
    ]
    for i in range(n):
        lines.append(f"{i + 1},0,0.1,{0.01 * i:.3f},0.2,{100 + 3 * i},{-50 + i},{300 - 0.1 * i:.1f}")
    return lines


@pytest.mark.parametrize("newline_at_end", [False, True])
def test_bad_cell_then_truncated_last_row(tmp_path, newline_at_end):
    lines = _export()
    cells = lines[35].split(",")  # file line 36
    cells[4] = "x1"
    lines[35] = ",".join(cells)
    lines[-1] = lines[-1][:14]  # the last row cut inside an object's cells
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + ("\n" if newline_at_end else ""))
    with pytest.raises(ViconCsvError) as exc:
        read_vicon_csv(path)
    locs = exc.value.all_locations()
    assert ":36:5:" in str(exc.value.location()) and "non-numeric" in locs[0]
    assert ":36:5:" in locs[0]
    if not newline_at_end:  # the truncation is collected after it
        assert len(locs) == 2 and ":65:" in locs[1] and "truncated" in locs[1]


def test_truncated_alone_is_reported(tmp_path):
    lines = _export()
    lines[-1] = lines[-1][:14]
    path = tmp_path / "t.csv"
    path.write_text("\n".join(lines))
    with pytest.raises(ViconCsvError) as exc:
        read_vicon_csv(path)
    locs = exc.value.all_locations()
    assert len(locs) == 1 and ":65:" in locs[0] and "truncated" in locs[0]


def _bad(lines: list[str], line: int, col: int, value: str) -> None:
    cells = lines[line - 1].split(",")
    cells[col - 1] = value
    lines[line - 1] = ",".join(cells)


def _short(lines: list[str], line: int) -> None:
    lines[line - 1] = ",".join(lines[line - 1].split(",")[:5])  # ends inside the object: a lost cell


def _locations(tmp_path, lines: list[str]) -> tuple[str, list[str]]:
    path = tmp_path / "e.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ViconCsvError) as exc:
        read_vicon_csv(path)
    return str(exc.value), exc.value.all_locations()


@pytest.mark.parametrize(
    "edit, expected",
    [
        # (what is broken, the (line, cause) of every error expected, in file order)
        (
            lambda L: (_bad(L, 10, 4, "x"), _bad(L, 20, 6, "1.2.3"), _bad(L, 30, 3, "abc")),
            [(10, "non-numeric"), (20, "non-numeric"), (30, "non-numeric")],
        ),
        (lambda L: (_bad(L, 10, 4, "x"), _short(L, 30)), [(10, "non-numeric"), (30, "missing-cell")]),
        (lambda L: (_short(L, 15), _bad(L, 30, 4, "x")), [(15, "missing-cell"), (30, "non-numeric")]),
        (lambda L: (_bad(L, 10, 4, "x"), _bad(L, 40, 1, "20")), [(10, "non-numeric"), (40, "frame-order")]),
        (lambda L: (_bad(L, 40, 1, "20"), _bad(L, 50, 4, "x")), [(40, "frame-order"), (50, "non-numeric")]),
        (lambda L: (_bad(L, 12, 1, "6"), _bad(L, 50, 7, "1e999")), [(12, "duplicate-frame"), (50, "non-finite")]),
        # a frame cell that is not a number ends the rows that can be read: the errors above it still come first
        (lambda L: (_bad(L, 36, 4, "abc"), _bad(L, 50, 1, "x12")), [(36, "non-numeric"), (50, "bad-frame")]),
        # a row that looks like a section title (one word, the rest empty) but has no 'Frame' header below it
        (
            lambda L: (_bad(L, 36, 4, "abc"), L.__setitem__(49, "Oops" + "," * 7)),
            [(36, "non-numeric"), (50, "bad-frame")],
        ),
        (lambda L: L.__setitem__(49, "Oops" + "," * 7), [(50, "bad-frame")]),
    ],
)
def test_every_error_is_collected_and_the_first_in_file_order_is_raised(tmp_path, edit, expected):
    """Before: a non-numeric cell stopped the collection (a short row, a repeated frame or an infinite value
    elsewhere was not reported), and a short row before it was reported after it or not at all."""
    lines = _export()
    edit(lines)
    msg, locs = _locations(tmp_path, lines)
    got = [(int(loc.split(":")[1]), loc.rsplit("[", 1)[1].rstrip("]")) for loc in locs]
    assert got == expected
    assert f"line {expected[0][0]}," in msg and msg.count("\n") == 0  # one line naming file, line and field


def test_at_most_twenty_errors(tmp_path):
    lines = _export()
    for ln in range(6, 60):
        _bad(lines, ln, 3, "?")
    _, locs = _locations(tmp_path, lines)
    assert len(locs) == 20 and ":6:3:" in locs[0]
