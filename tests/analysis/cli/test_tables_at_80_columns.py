"""`trials import` and `trials report` at 80 columns: long file names wrap, numbers and headers are never cut
(rich's ellipsis "…" appears nowhere), every line fits. Before: the import table cut its headers to `slop…`
and `ste…` to keep the 44-character file name on one line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

CRITICAL = Path(__file__).resolve().parents[3] / "analysis" / "data" / "critical"
FILES = [
    CRITICAL / "SYNTHETIC_crit_slope1.45deg_release1.9.csv",
    CRITICAL / "SYNTHETIC_crit_slope2.05deg_release2.5.csv",
]


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "rimless", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        env={**os.environ, "COLUMNS": "80"},
        timeout=600,
        stdin=subprocess.DEVNULL,
    )


#: a trial the comparison finds ok: the report exits 1 when none is (since session 21 the 1.45 deg trial is suspect,
#: its second period 168 ms off, and the 2.05 deg one was already)
OK_TRIAL = CRITICAL.parent / "SYNTHETIC_er_slope1.5deg_run1.csv"


@pytest.mark.parametrize("command", ["import", "report"])
def test_the_table_reads_at_80_columns(tmp_path: Path, command: str) -> None:
    files = FILES if command == "import" else [*FILES, OK_TRIAL]
    res = _run(["trials", command, *map(str, files), "--out", str(tmp_path / "out")], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    table = [line for line in res.stdout.splitlines() if "│" in line or "┃" in line]
    assert table, res.stdout
    assert all(len(line) <= 80 for line in table), res.stdout
    assert "…" not in res.stdout, res.stdout
    headers = " ".join(line for line in res.stdout.splitlines() if "┃" in line)
    for word in (
        ["status", "slope°", "outcome", "steps"]
        if command == "import"
        else ["status", "slope", "deg", "steps", "RMS", "rad/s"]
    ):
        assert word in headers, (word, res.stdout)
    for row in (line for line in table if "│" in line and ("imported" in line or "ok" in line or "suspect" in line)):
        cells = [c.strip() for c in row.split("│")]
        slope = next(c for c in cells if c.count(".") == 1 and c.replace(".", "").isdigit())
        assert len(slope.split(".")[1]) == 3  # the slope with its three decimals, whole


def test_the_calibration_residuals_name_every_trial_at_80_columns(tmp_path: Path) -> None:
    """Before: the residual table cut every name to `SYNTHETIC_crit_slope1.45deg_r…`, so two trials read the
    same. Now the common prefix goes to the caption and what differs is shown whole.

    Cheaper (session 23; the test took about 260 s alone and once hit its 600 s limit under load): the held
    parameters given exact at Table 1's values (a wheel file of plain numbers: no refits with each at +- 1 sd, which
    were most of the run) and --no-critical (no critical slopes: no table of names). The same four trials, the same
    residual table's names. Measured, CPU of the command: 164 s as before, 148 s with --no-critical alone (load
    7-20), 27 s with both (load 7)."""
    files = sorted(CRITICAL.glob("SYNTHETIC_crit_slope1.[46]*deg_release*.csv"))
    exact = tmp_path / "exact.toml"  # Table 1's values as plain numbers: exact; c is fitted
    exact.write_text("m_H = 1.892\nm = 0.0378\nI_c = 0.036\nL0 = 0.237\nk = 2700\nF_c = 0.0\n", encoding="utf-8")
    res = _run(["trials", "calibrate", *map(str, files), "--no-critical", "--params", str(exact)], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "…" not in res.stdout, res.stdout
    shown = [f for f in files if f.stem.removeprefix("SYNTHETIC_crit_slope1.") in res.stdout]
    assert len(shown) >= 3, res.stdout
    for f in set(files) - set(shown):  # left out of the calibration, and said so
        assert f.name in (res.stdout + res.stderr).replace("\n", ""), (f.name, res.stdout, res.stderr)
