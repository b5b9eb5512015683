"""Vicon CSV reader: the public exports (fingerprints computed independently with the csv module),
every quirk on small hand-made files, one distinct located error per malformed input, writer round trips."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from rimless.analysis.io.tracker_csv import write_tracker_csv
from rimless.analysis.io.vicon_csv import ViconCsvError, parse_vicon_text, read_vicon_csv
from rimless.errors import InputFileError
from tests.support.analysis_data import PUBLIC, public

# --------------------------------------------------------------------------------- independent reference


def csv_block(path: Path, title: str, delimiter: str = ","):
    """Rows of one section with the csv module: (rate, units, data rows as lists of str, first data line)."""
    with open(path, newline="", encoding="utf-8-sig") as f:
        rows = list(csv.reader(f, delimiter=delimiter))
    start = next(i for i, r in enumerate(rows) if r and r[0] == title)
    rate = float(rows[start + 1][0])
    units = rows[start + 4]
    data = []
    for r in rows[start + 5 :]:
        if not any(c.strip() for c in r):
            break
        data.append(r)
    return rate, units, data, start + 6


def expected_array(data: list[list[str]], col0: int, ncols: int, scale: np.ndarray) -> np.ndarray:
    out = np.full((len(data), ncols), np.nan)
    for i, r in enumerate(data):
        for j in range(ncols):
            c = r[col0 + j] if col0 + j < len(r) else ""
            if c.strip():
                out[i, j] = float(c) / 1000 if scale[j] == 1e-3 else float(c) * scale[j]
    return out


def is_expected_array(arr: np.ndarray, shape, first, last, nans: int, mean: float | None = None) -> None:
    """Fingerprint like pyomeca's helper: shape, first and last rows, NaN count, optional mean."""
    assert arr.shape == shape
    np.testing.assert_array_equal(arr[0], first)
    np.testing.assert_array_equal(arr[-1], last)
    assert int(np.isnan(arr).sum()) == nans
    if mean is not None:
        assert np.nanmean(arr) == pytest.approx(mean, rel=1e-12)


UNIT = {"mm": 1e-3, "m": 1.0, "rad": 1.0, "deg": math.pi / 180}


@pytest.mark.parametrize(
    "name,title,n_rows,n_cols,nans,groups",
    [
        ("tracker_objects_vantage_tube8.csv", "Objects", 547, 6, 0, 1),
        ("nexus_trajectories_pyomeca.csv", "Trajectories", 580, 153, 915, 51),
        ("nexus_devices_pyomeca_analogs.csv", "Devices", 11600, 38, 0, None),
        ("nexus_multisection_wpi_walk.csv", "Trajectories", 448, 258, None, 130),
    ],
)
def test_public_file_fingerprint(name, title, n_rows, n_cols, nans, groups):
    path = public(name)
    vf = read_vicon_csv(path)
    sec = vf.section(title)
    assert sec is not None
    rate, units, data, first_line = csv_block(path, title)
    assert sec.rate_hz == rate
    assert sec.n_rows == len(data) == n_rows
    scale = np.array([UNIT.get(u, 1.0) for u in units[2 : 2 + n_cols]])
    exp = expected_array(data, 2, n_cols, scale)
    exp_nans = int(np.isnan(exp).sum())
    if nans is not None:
        assert exp_nans == nans  # SOURCES.md's count, checked against the csv module
    is_expected_array(sec.values, (n_rows, n_cols), exp[0], exp[-1], exp_nans, float(np.nanmean(exp)))
    np.testing.assert_array_equal(sec.frame, [int(r[0]) for r in data])
    if groups is not None:
        assert len(sec.groups()) == groups


def test_tracker_public_file_details():
    vf = read_vicon_csv(public("tracker_objects_vantage_tube8.csv"))
    sec = vf.section("Objects")
    assert vf.kinds() == ["Objects"]
    assert sec.groups() == ["DasKebab2"]  # 'Global Angle ' prefix and repeated 'Obj:Obj' removed
    assert sec.name_prefix == "Global Angle"
    assert sec.components("DasKebab2") == ("RX", "RY", "RZ", "TX", "TY", "TZ")
    assert [c.file_unit for c in sec.columns] == ["rad"] * 3 + ["mm"] * 3
    assert [c.unit for c in sec.columns] == ["rad"] * 3 + ["m"] * 3
    # first row, by hand from SOURCES.md / the file: 1,0,-0.00376106,-0.329445,-0.000771605,-237.53,-329.281,409.832
    np.testing.assert_array_equal(sec.get("DasKebab2", ("TX", "TY", "TZ"))[0], [-0.23753, -0.329281, 0.409832])
    assert sec.values[0, 2] == -0.000771605
    assert sec.frame[0] == 1 and sec.frame[-1] == 547
    np.testing.assert_allclose(sec.time_s[[0, -1]], [0.0, 5.46])
    # 3-digit exponents exist in the file and parse as ordinary floats
    assert "e-00" in (PUBLIC / "tracker_objects_vantage_tube8.csv").read_text()
    assert np.all(np.isfinite(sec.values))


def test_multisection_public_file_sections():
    vf = read_vicon_csv(public("nexus_multisection_wpi_walk.csv"))
    assert vf.kinds() == ["Devices", "Joints", "Model Outputs", "Segments", "Trajectories"]
    assert [s.line for s in vf.sections] == [3, 4489, 4943, 5397, 5851]
    dev = vf.section("Devices")
    assert dev.rate_hz == 1000 and dev.sub_frame.max() == 9 and dev.n_rows == 4480
    seg = vf.section("Segments")
    assert np.isnan(seg.values).all()  # "frame,,,,..." rows: nothing computed
    mo = vf.section("Model Outputs")
    assert {c.file_unit for c in mo.columns} >= {"deg"}


def test_devices_public_file_time_axis():
    sec = read_vicon_csv(public("nexus_devices_pyomeca_analogs.csv")).section("Devices")
    assert sec.rate_hz == 2000 and sec.sub_frame.max() == 19
    t = sec.time_s
    np.testing.assert_allclose(np.diff(t), 1 / 2000)
    assert sec.columns[0].unit == "V"  # unknown units kept as written


# --------------------------------------------------------------------------------- quirks on small files

TRACKER = (
    "Objects\n100\n,,Global Angle W:W,,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    "7,0,0.1,0.2,0.3,1000,2000,3000\n8,0,0.1,0.2,0.3,1001,2000,3000\n9,0,0.1,0.2,0.3,1002,2000,3000\n"
)


def test_quirks_crlf_bom_blank_rows_padding_first_frame():
    text = "\ufeff,,,,\r\n\r\n" + TRACKER.replace("\n", ",,,\r\n") + ",,,,\r\n"
    sec = parse_vicon_text(text, "t.csv").section("Objects")
    assert sec.frame.tolist() == [7, 8, 9]
    np.testing.assert_allclose(sec.get("W", ("TX",))[:, 0], [1.0, 1.001, 1.002])
    np.testing.assert_allclose(sec.time_s, [0, 0.01, 0.02])


def test_semicolon_delimiter_with_decimal_commas_and_deg_m_units():
    text = "Trajectories\n50\n;;P\nFrame;Sub Frame;X;Y;Z\n;;m;m;m\n1;0;0,5;1,25;-2e-003\n2;0;0,75;;\n"
    vf = parse_vicon_text(text, "semi.csv")
    assert vf.delimiter == ";" and vf.decimal == ","
    np.testing.assert_array_equal(vf.section("Trajectories").values, [[0.5, 1.25, -0.002], [0.75, np.nan, np.nan]])
    text = "Objects\n100\n,,O\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,deg,deg,deg,m,m,m\n1,0,180,90,0,1,2,3\n"
    sec = parse_vicon_text(text).section("Objects")
    np.testing.assert_allclose(sec.values[0], [math.pi, math.pi / 2, 0, 1, 2, 3])


def test_first_row_wider_than_header_is_not_silently_cut():
    text = "Trajectories\n100\n,,A\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3,,9\n2,0,1,2,3\n"
    e = err_of(text)
    assert (e.cause, e.line, e.column) == ("extra-cell", 6, 7)
    ok = parse_vicon_text(text.replace(",,9", ",,"), "padded.csv").section("Trajectories")
    np.testing.assert_allclose(ok.values, [[0.001, 0.002, 0.003]] * 2)


def test_short_rows_and_empty_cells_are_occlusions():
    text = "Trajectories\n100\n,,A,,,B\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm\n1,0,1,2,3\n2,0,,,,4,5,6\n"
    sec = parse_vicon_text(text).section("Trajectories")
    assert np.isnan(sec.get("B")[0]).all() and np.isnan(sec.get("A")[1]).all()
    np.testing.assert_allclose(sec.get("B")[1], [0.004, 0.005, 0.006])


# --------------------------------------------------------------------------------- malformed inputs


def err_of(text: str) -> ViconCsvError:
    with pytest.raises(ViconCsvError) as e:
        parse_vicon_text(text, "bad.csv")
    assert isinstance(e.value, InputFileError) and "bad.csv" in str(e.value)
    return e.value


@pytest.mark.parametrize(
    "text,cause,line,column",
    [
        (TRACKER.replace("8,0,0.1,0.2", "8,0,0.1,abc"), "non-numeric", 7, 4),
        (TRACKER.replace("8,0,", "7,0,"), "duplicate-frame", 7, 1),
        (TRACKER.replace("9,0,", "6,0,"), "frame-order", 8, 1),
        (TRACKER.replace(",,rad,rad,rad,mm,mm,mm", ",,rad,rad,rad,mm,inch,mm"), "bad-unit", 5, 7),
        (TRACKER.replace(",,rad,rad,rad,mm,mm,mm\n", ""), "missing-units", 5, 1),
        (TRACKER.replace("Objects\n", ""), "missing-title", 1, 1),
        (TRACKER.replace("100\n", "fast\n"), "bad-rate", 2, 1),
        (TRACKER.replace("Frame,Sub Frame", "Time,Sub Frame"), "bad-header", 4, 1),
        (TRACKER[:-12], "truncated", 8, 6),
        ("Objects\n100\n,,W\n", "truncated-header", 4, None),
        (TRACKER.replace("8,0,", "8.5,0,"), "bad-frame", 7, 1),
        (TRACKER.replace("9,0,0.1,0.2,0.3,1002,2000,3000", "9,0,0.1,0.2,0.3,1002,2000,3000,,7"), "extra-cell", 8, 10),
        (TRACKER.replace("8,0,0.1", "8,0,1e999"), "non-finite", 7, 3),
        (",,,\n\n", "empty", None, None),
        ("hello,world\n", "unexpected-row", 1, 1),
        (TRACKER + "x,0,1,2,3,4,5,6\n", "bad-frame", 9, 1),
    ],
)
def test_malformed_input_gets_located_distinct_error(text, cause, line, column):
    e = err_of(text)
    assert (e.cause, e.line, e.column) == (cause, line, column), str(e)
    if line is not None:
        assert f"line {line}" in str(e)


def test_malformed_errors_are_distinct_messages():
    texts = [
        TRACKER.replace("8,0,0.1,0.2", "8,0,0.1,abc"),
        TRACKER.replace("8,0,", "7,0,"),
        TRACKER.replace(",,rad,rad,rad,mm,mm,mm", ",,rad,rad,rad,mm,inch,mm"),
        TRACKER[:-12],
    ]
    msgs = {str(err_of(t)).split(": ", 1)[1] for t in texts}
    assert len(msgs) == len(texts)


def test_unreadable_file(tmp_path):
    with pytest.raises(ViconCsvError) as e:
        read_vicon_csv(tmp_path / "missing.csv")
    assert e.value.cause == "unreadable"


# --------------------------------------------------------------------------------- writer round trips


@pytest.mark.parametrize("length_unit,newline,delimiter", [("m", "\n", ","), ("mm", "\r\n", ","), ("mm", "\n", ";")])
def test_writer_round_trip(tmp_path, length_unit, newline, delimiter):
    rng = np.random.default_rng(3)
    n = 200
    obj = np.hstack([rng.uniform(-3, 3, (n, 3)), rng.normal(0, 2, (n, 3))])
    mk = rng.normal(0, 1, (n, 3))
    obj[5, :] = np.nan
    mk[[7, 9], 1] = np.nan
    p = write_tracker_csv(
        tmp_path / "rt.csv",
        rate_hz=250,
        objects={"Wheel": obj},
        markers={"wheel:M1": mk},
        first_frame=12,
        length_unit=length_unit,
        delimiter=delimiter,
        newline=newline,
    )
    vf = read_vicon_csv(p)
    assert vf.kinds() == ["Objects", "Trajectories"]
    o, t = vf.section("Objects"), vf.section("Trajectories")
    assert o.rate_hz == 250 and o.frame[0] == 12 and o.frame[-1] == 12 + n - 1
    assert o.groups() == ["Wheel"] and t.groups() == ["wheel:M1"]
    if length_unit == "m":
        np.testing.assert_array_equal(o.values, obj)
        np.testing.assert_array_equal(t.values, mk)
    else:  # mm -> m scaling costs at most an ulp or two
        np.testing.assert_allclose(o.values, obj, rtol=1e-15, atol=0)
        np.testing.assert_allclose(t.values, mk, rtol=1e-15, atol=0)
        np.testing.assert_array_equal(np.isnan(o.values), np.isnan(obj))


# --------------------------------------------------------------------------------- the three entry points agree


def _outcome(read):
    """(sections as plain data) or (error cause, line, column, message, all locations)."""
    try:
        vf = read()
    except ViconCsvError as e:
        return ("error", e.cause, e.line, e.column, e.detail, e.all_locations())
    return [
        (
            s.kind,
            s.line,
            s.frame.tolist(),
            s.sub_frame.tolist(),
            [c.column for c in s.columns],
            np.where(np.isnan(s.values), -1e300, s.values).tolist(),
        )
        for s in vf.sections
    ]


MIXED = (
    "Objects\n100\n,,W,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    + "".join(f"{k},0,0.1,0.2,{0.01 * k},{1000 + k},2000,3000\n" for k in range(1, 8))
    + "8,0,,,,,,\n9,0\n10,0,0.1,0.2,0.3,1010,2000,3000\n\n"
    "Trajectories\n100\n,,A,,,B\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm\n"
    "1,0,1,2,3\n2,0,,,,4,5,6\n3,0,1,2,3,4,5,6\n4,0,1,2,3,4,5,6\n5,0,1,2,3,4,5,6\n"
)


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r"])
@pytest.mark.parametrize(
    "text",
    [
        MIXED,
        MIXED.replace("3,0,1,2,3,4,5,6", "3,0,1,2,3,4"),  # a lost cell in a later chunk of the second section
        MIXED.replace("3,0,1,2,3,4,5,6", "3,0,1,2,3,4").replace("5,0,1,2,3,4,5,6", "5,0,1,2"),
        MIXED.replace("4,0,1,2,3,4,5,6", "4,0,1,2,3,4,5,6,,9"),  # a value beyond the header in a later chunk
        MIXED.replace("6,0,0.1,0.2", "6,0,0.1,x"),
        MIXED.replace("1005,2000", "1e999,2000"),
        MIXED.replace("2,0,,,,4,5,6", "2,0,,,,4,5,٦"),  # non-ASCII digit
        TRACKER,
        "\ufeff" + TRACKER,
        TRACKER[:-12],
        TRACKER.replace("9,0,", "6,0,"),
    ],
)
def test_file_bytes_and_text_paths_agree_in_small_chunks(tmp_path, monkeypatch, text, newline):
    """read_vicon_csv (data blocks streamed back from the file), parse_vicon_bytes (from memory) and
    parse_vicon_text (encoded copy) give the same sections or the same errors, also when blocks span chunks."""
    from rimless.analysis.io import vicon_csv

    monkeypatch.setattr(vicon_csv._Parser, "CHUNK_ROWS", 2)
    text = text.replace("\n", newline)
    p = tmp_path / "f.csv"
    p.write_bytes(text.encode("utf-8"))
    a = _outcome(lambda: read_vicon_csv(p))
    b = _outcome(lambda: vicon_csv.parse_vicon_bytes(text.encode("utf-8"), str(p)))
    c = _outcome(lambda: parse_vicon_text(text, str(p)))
    assert a == b == c
