"""Import benchmark: a synthetic Tracker export of N rows, read by plain pandas, our parser and our import.

It sits with `build` because it times the whole import (parse, then `import_trial`). Run by hand:
``python -m rimless.analysis.kinematics.bench_import [ROWS]`` or ``rimless trials bench-import``.
Prints timings and rows/s; nothing is asserted (timings depend on the machine).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["make_tracker_file", "run_benchmark", "benchmark_figures", "rows_for_mb", "BYTES_PER_ROW"]


def make_tracker_file(path: Path, rows: int, *, seed: int = 0) -> Path:
    """Write a Tracker ``Objects`` export of a wheel rolling down a 2 deg slope for ``rows`` frames at 100 Hz.

    A rigid eight-legged wheel (legs 0.237 m, 0.4 s steps) rolls along +X; the object origin is 3 cm off the
    hub; 0.3 mm noise, 1 % of the rows occluded; mm and rad with 6 significant digits.
    """
    import pandas as pd

    rng = np.random.default_rng(seed)
    alpha, leg, period = np.pi / 4, 0.237, 0.4
    phi = np.radians(2.0)
    head = "Objects\n100\n,,Global Angle Wheel:Wheel,,,,,,\nFrame,Sub Frame,RX,RY,RZ,TX,TY,TZ\n,,rad,rad,rad,mm,mm,mm\n"
    with open(path, "w", newline="") as f:
        f.write(head)
        for first in range(0, rows, 500_000):  # in chunks: a 200 MB file needs no GB of memory to write
            i = np.arange(first, min(first + 500_000, rows))
            t = i / 100.0
            k, u = np.divmod(t / period, 1.0)
            theta = -alpha / 2 + alpha * u
            x = k * 2 * leg * np.sin(alpha / 2) + leg * np.sin(theta)  # slope frame: down the slope, normal
            y = leg * np.cos(theta)
            beta = k * alpha + theta
            zero = np.zeros(i.size)
            hub = np.column_stack([x * np.cos(phi) + y * np.sin(phi), zero, -x * np.sin(phi) + y * np.cos(phi)])
            # the wheel turns about -Y (rolling towards +X); the object origin sits 30 mm from the hub
            origin = hub + 0.03 * np.column_stack([np.cos(-beta), zero, -np.sin(-beta)])
            data = np.column_stack([zero, -(beta % (2 * np.pi)), zero, 1000 * origin + rng.normal(0, 0.3, (i.size, 3))])
            data[rng.random(i.size) < 0.01, :] = np.nan  # 1 % occluded rows
            df = pd.DataFrame(data)
            df.insert(0, "sub", 0)
            df.insert(0, "frame", i + 1)
            df.to_csv(f, header=False, index=False, float_format="%.6g", lineterminator="\n")
    return path


_PHASES = ("pandas", "parse", "import")


def _phase(name: str, path: str) -> dict[str, float]:
    """Run one phase in this process: seconds and peak resident memory (sampled every 2 ms from /proc) above the
    resident memory after the imports, MB."""
    import resource
    import threading

    import pandas as pd
    import scipy.signal
    import scipy.spatial.transform  # noqa: F401

    from rimless.analysis.io.vicon_csv import read_vicon_csv
    from rimless.analysis.kinematics.build import import_trial

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
    t0, c0 = time.perf_counter(), time.process_time()
    if name == "pandas":
        n = len(pd.read_csv(path, skiprows=5, header=None))
    elif name == "parse":
        n = read_vicon_csv(path).sections[0].n_rows
    else:
        n = import_trial(path).meta.n_frames
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    stop.set()
    sampler.join()
    peak[0] = max(peak[0], rss_mb())
    return {"s": dt, "cpu_s": cpu, "peak_mb": max(peak[0] - base, 0.0), "rss_mb": peak[0], "rows": float(n)}


def run_benchmark(rows: int = 1_000_000, path: Path | None = None) -> dict[str, Any]:
    """Time and measure the memory of ``pandas.read_csv``, our parse and our end-to-end import on one file.

    Each phase runs in a fresh Python process (so peak memory is its own). Returns ``rows``, ``bytes`` and, per
    phase (``pandas``, ``parse``, ``import``), ``<phase>_s`` (wall), ``<phase>_cpu_s`` (CPU time of the
    process), ``<phase>_peak_mb`` (peak resident memory above that after the imports and the warm-up) and
    ``<phase>_rss_mb`` (peak resident memory of the whole process); ``parse_ratio`` = parse / pandas time
    (``parse_cpu_ratio`` in CPU time), ``memory_ratio`` = import / pandas peak memory.
    """
    import json
    import subprocess

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        p = path or make_tracker_file(Path(tmp) / "bench.csv", rows)
        out["bytes"] = p.stat().st_size
        for name in _PHASES:
            res = subprocess.run(
                [sys.executable, "-m", "rimless.analysis.kinematics.bench_import", "--phase", name, str(p)],
                capture_output=True,
                text=True,
                check=False,
            )
            if res.returncode != 0:
                raise RuntimeError(f"benchmark phase {name} failed: {res.stderr.strip().splitlines()[-1:]}")
            r = json.loads(res.stdout.strip().splitlines()[-1])
            out[f"{name}_s"], out[f"{name}_peak_mb"] = r["s"], r["peak_mb"]
            out[f"{name}_cpu_s"], out[f"{name}_rss_mb"] = r["cpu_s"], r["rss_mb"]
            out["rows"] = int(r["rows"])
    out["parse_ratio"] = out["parse_s"] / out["pandas_s"]
    out["parse_cpu_ratio"] = out["parse_cpu_s"] / max(out["pandas_cpu_s"], 1e-9)
    out["memory_ratio"] = out["import_peak_mb"] / max(out["pandas_peak_mb"], 1e-9)
    return out


#: Bytes per row of `make_tracker_file` (measured on 1e6 rows), to size a file in MB.
BYTES_PER_ROW = 50.6


def rows_for_mb(mb: float) -> int:
    """Rows of a `make_tracker_file` export of about ``mb`` MB (at least 100)."""
    return max(100, int(mb * 1e6 / BYTES_PER_ROW))


def benchmark_figures(rows: int) -> dict[str, Any]:
    """`run_benchmark` with the load average before and after and the CPU count (``trials bench-import --json``)."""
    import os

    load_before = os.getloadavg()[0]
    res = run_benchmark(rows)
    return {**res, "load_average_before": load_before, "load_average_after": os.getloadavg()[0], "cpus": os.cpu_count()}


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: ``[ROWS]`` or ``--mb SIZE`` (a file of about SIZE MB); ``--phase NAME FILE`` is
    used internally."""
    import json
    import os

    args = sys.argv[1:] if argv is None else argv
    if args and args[0] == "--phase":
        print(json.dumps(_phase(args[1], args[2])))
        return
    if args and args[0] == "--mb":
        rows = rows_for_mb(float(args[1]))
    else:
        rows = int(args[0]) if args else 1_000_000
    print(f"writing a {rows:,}-row Tracker export and timing 3 fresh processes ...", file=sys.stderr)
    load0 = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    r = run_benchmark(rows)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"{r['rows']:,} rows, {r['bytes'] / 1e6:.1f} MB; one fresh process per line, warmed up on 2000 rows; "
        f"load average {load0:.1f} before, {load:.1f} after, on {os.cpu_count()} CPUs"
    )
    print(
        "  (cpu = CPU time of the process, which every ratio comes from; above = peak resident memory above that after the imports and "
        "the warm-up; rss = peak resident memory of the whole process)"
    )
    for key, label in (("pandas", "pandas.read_csv"), ("parse", "our parse"), ("import", "our import (e2e)")):
        line = (
            f"  {label:18s} {r[key + '_s']:6.2f} s  cpu {r[key + '_cpu_s']:6.2f} s  "
            f"{r['rows'] / r[key + '_s']:>10,.0f} rows/s  above {r[key + '_peak_mb']:7.1f} MB  "
            f"rss {r[key + '_rss_mb']:7.1f} MB"
        )
        if key == "parse":
            line += f"   parse/pandas = {r['parse_cpu_ratio']:.2f}x cpu ({r['parse_ratio']:.2f}x wall)"
        if key == "import":
            line += f"   memory/pandas = {r['memory_ratio']:.2f}x"
        print(line)


if __name__ == "__main__":
    main()
