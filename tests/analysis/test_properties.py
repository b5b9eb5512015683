"""Property-based tests: the parser never crashes with an unhandled exception; writer/reader round trips."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rimless.analysis.vicon_csv import ViconCsvError, parse_vicon_bytes, parse_vicon_text, write_tracker_csv

VALID = (
    "Objects\n100\n,,Global Angle W:W,,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    "1,0,0.1,0.2,0.3,1000,2000,3000\n2,0,0.1,0.2,0.3,1001,2000,3000\n\n"
    "Trajectories\n100\n,,M,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,,,\n"
)
TOKENS = st.sampled_from(["Objects", "Trajectories", "Devices", "Frame", "Sub Frame", "X", "RX", "TX", "mm",
                          "rad", "deg", "100", "1", "0", "-2.5", "7e-006", "nan", "inf", "abc", "", ",", ";",
                          "\n", "\r\n", "\t", " ", "\ufeff", "Global Angle W:W", "1e999", ".", "-"])


def parse_ok_or_located(text: str) -> None:
    try:
        vf = parse_vicon_text(text, "fuzz.csv")
    except ViconCsvError as e:
        assert str(e).startswith("fuzz.csv") and e.cause
        return
    for s in vf.sections:
        assert s.values.shape == (s.frame.size, len(s.columns))
        assert not np.isinf(s.values).any()
        assert np.all(np.diff(s.frame * (s.sub_frame.max() + 1 if s.frame.size else 1) + s.sub_frame) > 0)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(TOKENS, max_size=80).map("".join))
def test_token_soup_never_crashes(text):
    parse_ok_or_located(text)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, len(VALID)), st.integers(0, len(VALID)), st.text(max_size=12))
def test_mutated_valid_file_never_crashes(i, j, insert):
    i, j = sorted((i, j))
    parse_ok_or_located(VALID[:i] + insert + VALID[j:])


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_never_crash(raw):
    try:
        parse_vicon_bytes(raw, "fuzz.bin")
    except ViconCsvError:
        pass


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    arrays(np.float64, st.tuples(st.integers(1, 30), st.just(3)),
           elements=st.one_of(st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=False), st.just(np.nan))),
    st.sampled_from([",", ";"]),
    st.sampled_from(["\n", "\r\n"]),
    st.integers(0, 10_000),
)
def test_round_trip_in_metres_is_exact(tmp_path, data, delimiter, newline, first_frame):
    p = write_tracker_csv(tmp_path / "p.csv", rate_hz=120, markers={"m": data}, length_unit="m",
                          delimiter=delimiter, newline=newline, first_frame=first_frame)
    sec = parse_vicon_bytes(p.read_bytes(), "p.csv").section("Trajectories")
    np.testing.assert_array_equal(sec.values, data)
    assert sec.frame[0] == first_frame and sec.frame.size == data.shape[0]
