"""The first error in file order comes first (in the exception and in `all_locations`), also when the file
is truncated at its end. The export is written here by hand (an Objects section of 60 rows: data on lines 6-65)."""

from __future__ import annotations

import pytest

from rimless.analysis.io.vicon_csv import ViconCsvError, read_vicon_csv


def _export(n: int = 60) -> list[str]:
    lines = ["Objects", "100", ",,Global Angle Wheel:Wheel,,,,,", "Frame,Sub Frame,RX,RY,RZ,TX,TY,TZ",
             ",,rad,rad,rad,mm,mm,mm"]
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
