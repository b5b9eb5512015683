"""The benchmark's report of machine load: a ratio from a busy machine is never printed bare."""

from __future__ import annotations

import pytest

from rimless.sim import bench


def _result(busy: bool | None) -> dict:
    return {
        "rows": [{"model": "er", "backend": "fast-dop853", "rtol": 1e-9, "error": 5e-10, "period_error_s": 1e-11,
                  "eigenvalue_error": 1e-9, "seconds_per_map": 4e-4, "nfev": 1200, "nsteps": 90}],
        "load_average": {"before": [1.9, 1.5, 1.0], "after": [2.8, 1.7, 1.1], "cpus": 2, "busy": busy},
        "speedup_at_1e-9": 70.0,
        "speedup_at_1e-9_by_model": {},
        "fixed_point": {},
        "compile": {},
        "total_seconds": 12.0,
    }


def test_busy_is_judged_from_the_load_of_other_processes(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench.os, "cpu_count", lambda: 2)
    assert bench.machine_load([0.1, 0.2, 0.3], [1.2, 0.5, 0.4])["busy"] is False  # only the benchmark itself
    assert bench.machine_load([1.9, 1.5, 1.0], [1.4, 1.5, 1.0])["busy"] is True  # busy before
    assert bench.machine_load([0.1, 0.1, 0.1], [2.5, 1.0, 0.5])["busy"] is True  # another job started
    assert bench.machine_load(None, [1.0, 1.0, 1.0])["busy"] is None  # no load average on this platform


def test_the_table_warns_instead_of_printing_a_bare_ratio_on_a_busy_machine() -> None:
    busy = bench.format_table(_result(True))
    quiet = bench.format_table(_result(False))
    assert "load average 1/5/15 min: before 1.90 1.50 1.00, after 2.80 1.70 1.10 (2 cores)" in busy
    lines = busy.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.startswith("speed-up"))
    assert "70x (busy machine)" in lines[i] and lines[i + 1].startswith("WARNING")
    assert all(len(ln) <= 80 for ln in lines)
    line = next(ln for ln in quiet.splitlines() if ln.startswith("speed-up"))
    assert "70x" in line and "busy" not in line and "WARNING" not in quiet
