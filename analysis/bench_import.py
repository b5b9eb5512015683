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
    """Write a Tracker ``Objects`` export of a wheel rolling down a 2 deg slope for ``rows`` frames at 100 Hz.

    A rigid eight-legged wheel (legs 0.237 m, 0.4 s steps) rolls along +X; the object origin is 3 cm off the
    hub; 0.3 mm noise, 1 % of the rows occluded; mm and rad with 6 significant digits.
    """
    rng = np.random.default_rng(seed)
    alpha, leg, period = np.pi / 4, 0.237, 0.4
    t = np.arange(rows) / 100.0
    k, u = np.divmod(t / period, 1.0)
    theta = -alpha / 2 + alpha * u
    phi = np.radians(2.0)
    x = k * 2 * leg * np.sin(alpha / 2) + leg * np.sin(theta)  # slope frame: down the slope, normal
    y = leg * np.cos(theta)
    beta = k * alpha + theta
    hub = np.column_stack([x * np.cos(phi) + y * np.sin(phi), np.zeros(rows), -x * np.sin(phi) + y * np.cos(phi)])
    # the wheel turns about -Y (rolling towards +X); the object origin sits 30 mm from the hub
    rx, ry, rz = np.zeros(rows), -(beta % (2 * np.pi)), np.zeros(rows)
    origin = hub + 0.03 * np.column_stack([np.cos(-beta), np.zeros(rows), -np.sin(-beta)])
    data = np.column_stack([rx, ry, rz, 1000 * origin + rng.normal(0, 0.3, (rows, 3))])
    data[rng.random(rows) < 0.01, :] = np.nan  # 1 % occluded rows
    head = "Objects\n100\n,,Global Angle Wheel:Wheel,,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    import pandas as pd

    df = pd.DataFrame(data)
    df.insert(0, "sub", 0)
    df.insert(0, "frame", np.arange(1, rows + 1))
    with open(path, "w", newline="") as f:
        f.write(head)
        df.to_csv(f, header=False, index=False, float_format="%.6g", lineterminator="\n")
    return path


_PHASES = ("pandas", "parse", "import")


def _phase(name: str, path: str) -> dict[str, float]:
    """Run one phase in this process: seconds and peak resident memory (sampled every 2 ms from /proc) above the
    resident memory after the imports, MB."""
    import resource

    import pandas as pd

    from .trial import import_trial
    from .vicon_csv import read_vicon_csv

    import scipy.signal  # noqa: F401
    import scipy.spatial.transform  # noqa: F401

    import threading

    def rss_mb() -> float:
        try:
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * resource.getpagesize() / 2**20
        except OSError:  # not Linux: the lifetime peak is the best available
            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    # Warm-up on a 2000-row file, the same for every phase: first-call costs (lazy imports inside pandas and
    # scipy, compiled regexes) are not throughput.
    with tempfile.TemporaryDirectory() as tmp:
        small = make_tracker_file(Path(tmp) / "warm.csv", 2000)
        pd.read_csv(small, skiprows=5, header=None)
        if name != "pandas":
            (read_vicon_csv if name == "parse" else import_trial)(small)
    base = rss_mb()
    peak = [base]
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(0.002):
            peak[0] = max(peak[0], rss_mb())

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    t0 = time.perf_counter()
    if name == "pandas":
        n = len(pd.read_csv(path, skiprows=5, header=None))
    elif name == "parse":
        n = read_vicon_csv(path).sections[0].n_rows
    else:
        n = import_trial(path).meta.n_frames
    dt = time.perf_counter() - t0
    stop.set()
    sampler.join()
    peak[0] = max(peak[0], rss_mb())
    return {"s": dt, "peak_mb": max(peak[0] - base, 0.0), "rows": float(n)}


def run_benchmark(rows: int = 1_000_000, path: Path | None = None) -> dict[str, Any]:
    """Time and measure the memory of ``pandas.read_csv``, our parse and our end-to-end import on one file.

    Each phase runs in a fresh Python process (so peak memory is its own). Returns ``rows``, ``bytes`` and, per
    phase (``pandas``, ``parse``, ``import``), ``<phase>_s`` and ``<phase>_peak_mb``; ``parse_ratio`` = parse /
    pandas time, ``memory_ratio`` = import / pandas peak memory.
    """
    import json
    import subprocess

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        p = path or make_tracker_file(Path(tmp) / "bench.csv", rows)
        out["bytes"] = p.stat().st_size
        for name in _PHASES:
            res = subprocess.run([sys.executable, "-m", "rimless.analysis.bench_import", "--phase", name, str(p)],
                                 capture_output=True, text=True, check=False)
            if res.returncode != 0:
                raise RuntimeError(f"benchmark phase {name} failed: {res.stderr.strip().splitlines()[-1:]}")
            r = json.loads(res.stdout.strip().splitlines()[-1])
            out[f"{name}_s"], out[f"{name}_peak_mb"] = r["s"], r["peak_mb"]
            out["rows"] = int(r["rows"])
    out["parse_ratio"] = out["parse_s"] / out["pandas_s"]
    out["memory_ratio"] = out["import_peak_mb"] / max(out["pandas_peak_mb"], 1e-9)
    return out


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: optional row count (or ``--phase NAME FILE``, used internally)."""
    import json

    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == "--phase":
        print(json.dumps(_phase(args[1], args[2])))
        return
    rows = int(args[0]) if args else 1_000_000
    print(f"writing a {rows:,}-row Tracker export and timing 3 fresh processes ...", file=sys.stderr)
    r = run_benchmark(rows)
    import os

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{r['rows']:,} rows, {r['bytes'] / 1e6:.1f} MB; one fresh process per line, warmed up on 2000 rows; "
          f"memory = peak resident memory above that after the imports; load average {load:.1f} on "
          f"{os.cpu_count()} CPUs")
    print(f"  pandas.read_csv      {r['pandas_s']:6.2f} s  {r['rows'] / r['pandas_s']:>12,.0f} rows/s  "
          f"peak {r['pandas_peak_mb']:7.1f} MB")
    print(f"  our parse            {r['parse_s']:6.2f} s  {r['rows'] / r['parse_s']:>12,.0f} rows/s  "
          f"peak {r['parse_peak_mb']:7.1f} MB   parse/pandas = {r['parse_ratio']:.2f}x")
    print(f"  our import (e2e)     {r['import_s']:6.2f} s  {r['rows'] / r['import_s']:>12,.0f} rows/s  "
          f"peak {r['import_peak_mb']:7.1f} MB   memory/pandas = {r['memory_ratio']:.2f}x")


if __name__ == "__main__":
    main()
