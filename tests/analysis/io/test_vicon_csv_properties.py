"""Property-based tests: the parser never crashes with an unhandled exception; writer/reader round trips."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rimless.analysis.io.tracker_csv import write_tracker_csv
from rimless.analysis.io.vicon_csv import ViconCsvError, parse_vicon_bytes, parse_vicon_text
from rimless.analysis.kinematics.build import import_trial
from rimless.errors import UserError
from tests.support import analysis_truth_wheel as tw
from tests.support.work_budget import call_budget

VALID = (
    "Objects\n100\n,,Global Angle W:W,,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    "1,0,0.1,0.2,0.3,1000,2000,3000\n2,0,0.1,0.2,0.3,1001,2000,3000\n\n"
    "Trajectories\n100\n,,M,,\nFrame,Sub Frame,X,Y,Z\n,,mm,mm,mm\n1,0,1,2,3\n2,0,,,\n"
)
TOKENS = st.sampled_from(
    [
        "Objects",
        "Trajectories",
        "Devices",
        "Frame",
        "Sub Frame",
        "X",
        "RX",
        "TX",
        "mm",
        "rad",
        "deg",
        "100",
        "1",
        "0",
        "-2.5",
        "7e-006",
        "nan",
        "inf",
        "abc",
        "",
        ",",
        ";",
        "\n",
        "\r\n",
        "\t",
        " ",
        "\ufeff",
        "Global Angle W:W",
        "1e999",
        ".",
        "-",
    ]
)


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
    arrays(
        np.float64,
        st.tuples(st.integers(1, 30), st.just(3)),
        elements=st.one_of(st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=False), st.just(np.nan)),
    ),
    st.sampled_from([",", ";"]),
    st.sampled_from(["\n", "\r\n"]),
    st.integers(0, 10_000),
)
def test_round_trip_in_metres_is_exact(tmp_path, data, delimiter, newline, first_frame):
    p = write_tracker_csv(
        tmp_path / "p.csv",
        rate_hz=120,
        markers={"m": data},
        length_unit="m",
        delimiter=delimiter,
        newline=newline,
        first_frame=first_frame,
    )
    sec = parse_vicon_bytes(p.read_bytes(), "p.csv").section("Trajectories")
    np.testing.assert_array_equal(sec.values, data)
    assert sec.frame[0] == first_frame and sec.frame.size == data.shape[0]


# ------------------------------------------------------------------ whole import (header rows and data block)


def _wheel_lines():
    truth = tw.make_truth(periods_s=(0.42, 0.40, 0.39), hold_s=0.2, ending="caught", after_s=0.3)
    pts = tw.noisy(tw.body_points(truth, tw.EVEN_MARKERS), 0.3e-3, 1)
    return tw.markers_section({f"w:M{i}": pts[:, i] for i in range(4)})


WHEEL_LINES = _wheel_lines()


def _warm_up() -> None:
    """Import once so that module imports (scipy, pandas) do not count against the time limit below."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "w.csv"
        p.write_text("\n".join(WHEEL_LINES) + "\n")
        import_trial(p)


_warm_up()
HEADER_TOKENS = st.one_of(
    st.sampled_from(
        [
            "100",
            "5e-154",
            "1e308",
            "5e-324",
            "0",
            "-1",
            "nan",
            "inf",
            "1e999",
            "12,5",
            "١٠٠",
            "",
            "mm",
            "m",
            "cm",
            "rad",
            "deg",
            "V",
            "X",
            "Y",
            "Z",
            "Frame",
            "Sub Frame",
            "w:M0",
            "2 1937",
            "*3",
            "Ramp:R1",
            ",",
            ",,",
            "\t",
        ]
    ),
    st.text(max_size=8),
)


#: calls (Python functions and calls into C) one import may make: a normal import of these files makes about
#: 24,000; a hang, or work out of proportion to the file, runs past the budget (whatever the machine's speed)
IMPORT_CALL_BUDGET = 1_000_000


def import_ok_or_refused(text: str, tmp_path) -> None:
    p = tmp_path / "fuzz.csv"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    with call_budget(IMPORT_CALL_BUDGET):  # no hang: WorkBudgetExceeded past the budget
        try:
            trial = import_trial(p)
        except UserError as e:
            assert str(e)
        else:
            assert np.isfinite(trial.meta.slope_deg)
            assert np.all(np.isfinite(trial.step_period_s)) and np.all(trial.step_period_s > 0)
            assert trial.meta.outcome in ("walked", "stalled", "fell", "caught", "unknown")


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(st.integers(1, 4), st.lists(HEADER_TOKENS, min_size=1, max_size=6))
def test_fuzzed_header_rows_never_crash_or_hang(tmp_path, row, cells):
    lines = list(WHEEL_LINES)
    lines[row] = ",".join(cells) if row != 1 else cells[0]
    import_ok_or_refused("\n".join(lines) + "\n", tmp_path)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    st.lists(
        st.tuples(
            st.integers(5, len(WHEEL_LINES) - 1),
            st.integers(0, 13),
            st.one_of(
                st.sampled_from(["", "0", "nan", "inf", "1e308", "-1e308", "x", "٣", "0,0"]),
                st.floats(allow_nan=False, allow_infinity=False).map(repr),
            ),
        ),
        min_size=1,
        max_size=30,
    )
)
def test_fuzzed_data_block_never_crashes_or_hangs(tmp_path, edits):
    lines = list(WHEEL_LINES)
    for r, c, v in edits:
        cells = lines[r].split(",")
        if c < len(cells):
            cells[c] = v
        lines[r] = ",".join(cells)
    import_ok_or_refused("\n".join(lines) + "\n", tmp_path)
