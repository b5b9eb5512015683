"""Import benchmark: a synthetic Tracker export of N rows, read by our parser and by plain pandas.

Run by hand: ``python -m rimless.analysis.bench_import [ROWS]`` or ``rimless trials bench-import``.
Prints timings and rows/s; nothing is asserted (timings depend on the machine).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["make_tracker_file", "run_benchmark"]


def make_tracker_file(path: Path, rows: int, *, seed: int = 0) -> Path:
    """Write a Tracker-like ``Objects`` export with ``rows`` frames (mm, rad, 6 significant digits)."""
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / 100.0
    data = np.column_stack([
        np.zeros(rows), np.zeros(rows), -(t * 2.0) % (2 * np.pi) - np.pi,
        1000 * t, rng.normal(0, 1, rows), 150 + rng.normal(0, 1, rows),
    ])
    data[rng.random(rows) < 0.01, 3:] = np.nan  # 1 % occluded rows
    head = "Objects\n100\n,,Global Angle Wheel:Wheel,,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    import pandas as pd

    df = pd.DataFrame(data)
    df.insert(0, "sub", 0)
    df.insert(0, "frame", np.arange(1, rows + 1))
    with open(path, "w", newline="") as f:
        f.write(head)
        df.to_csv(f, header=False, index=False, float_format="%.6g", lineterminator="\n")
    return path


def run_benchmark(rows: int = 1_000_000, path: Path | None = None) -> dict[str, Any]:
    """Time `read_vicon_csv` and `build_trial` against ``pandas.read_csv`` on the same file.

    Returns a dict with ``rows``, ``bytes``, ``parse_s``, ``trial_s``, ``pandas_s``, ``rows_per_s``,
    ``pandas_rows_per_s`` and ``ratio`` (our parse time / pandas time).
    """
    import pandas as pd

    from .trial import build_trial
    from .vicon_csv import read_vicon_csv

    with tempfile.TemporaryDirectory() as tmp:
        p = path or make_tracker_file(Path(tmp) / "bench.csv", rows)
        size = p.stat().st_size
        t0 = time.perf_counter()
        base = pd.read_csv(p, skiprows=5, header=None)
        pandas_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        vf = read_vicon_csv(p)
        parse_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        build_trial(vf, hub_offset_m=(0.0, 0.0, 0.0))
        trial_s = time.perf_counter() - t0
        n = vf.sections[0].n_rows
        assert n == len(base)
    return {
        "rows": n, "bytes": size, "parse_s": parse_s, "trial_s": trial_s, "pandas_s": pandas_s,
        "rows_per_s": n / parse_s, "pandas_rows_per_s": n / pandas_s, "ratio": parse_s / pandas_s,
    }


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: optional row count."""
    args = sys.argv[1:] if argv is None else argv
    r = run_benchmark(int(args[0]) if args else 1_000_000)
    print(f"{r['rows']:,} rows, {r['bytes'] / 1e6:.1f} MB: parse {r['parse_s']:.2f} s "
          f"({r['rows_per_s']:,.0f} rows/s), trial {r['trial_s']:.2f} s; "
          f"pandas.read_csv {r['pandas_s']:.2f} s ({r['pandas_rows_per_s']:,.0f} rows/s); "
          f"parse/pandas = {r['ratio']:.2f}")


if __name__ == "__main__":
    main()
