"""The benchmark's report of machine load: a ratio from a busy machine is never printed bare."""

from __future__ import annotations

import pytest

from rimless.sim.studies import bench


def _result(busy: bool | None) -> dict:
    return {
        "rows": [
            {
                "model": "er",
                "backend": "fast-dop853",
                "rtol": 1e-9,
                "error": 5e-10,
                "period_error_s": 1e-11,
                "eigenvalue_error": 1e-9,
                "seconds_per_map": 4e-4,
                "nfev": 1200,
                "nsteps": 90,
            }
        ],
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


def test_the_loosest_tolerance_counts_only_if_every_tighter_one_meets_the_target() -> None:
    rows = [
        {"model": "er", "backend": "b", "rtol": r, "error": e}
        for r, e in [(1e-4, 5e-10), (1e-5, 2e-9), (1e-6, 4e-10), (1e-7, 1e-11)]
    ]
    rows.append({"model": "ve", "backend": "b", "rtol": 1e-3, "error": 1e-12})
    # 1e-4 meets 1e-9 by chance above 1e-5, which does not
    assert bench.loosest_meeting(rows, "er", "b")["rtol"] == 1e-6
    assert bench.loosest_meeting(rows, "er", "b", target=1e-12) is None
    assert bench.loosest_meeting(rows, "ve", "b")["rtol"] == 1e-3


def test_per_phase_counts_and_the_peer_row_fit_the_table() -> None:
    res = _result(False)
    res["rows"][0].update(phase_nfev=[60, 155, 336], phase_steps=[2, 8, 24])
    res["speedup_at_1e-9_by_model"] = {
        "er": {
            "fast_rtol": 1e-9,
            "fast_seconds_per_map": 4e-4,
            "dop853_rtol": 1e-8,
            "dop853_seconds_per_map": 0.08,
            "speedup": 200.0,
        }
    }
    res["peer"] = {
        "phase": "ER clutched single support",
        "duration_s": 0.2,
        "peer_first_call_s": 65.0,
        "rows": [{"backend": "nbkode-DOP853", "rtol": 1e-8, "error": 5.6e-12, "seconds": 7e-4}],
    }
    lines = bench.format_table(res).splitlines()
    assert "    per phase (dlsp/free/clutched): nfev 60/155/336, steps 2/8/24" in lines
    assert any(ln.startswith("  nbkode-DOP853") and "5.6e-12" in ln and "0.700 ms" in ln for ln in lines)
    assert all(len(ln) <= 80 for ln in lines)
    res["peer"] = {"skipped": "--quick (nbkode compiles for minutes in each process)"}
    assert all(len(ln) <= 80 for ln in bench.format_table(res).splitlines())


def test_the_guide_friction_rows_compare_both_paths_and_fit_the_table() -> None:
    """The compiled and reference step maps with guide friction side by side: both close to the tight reference,
    the ratio is what the times say (no timing is asserted), and the table prints each row."""
    from rimless.sim.studies.bench import FRICTION_N, format_table, friction_bench

    fr = friction_bench(True, lambda _msg: None)
    assert fr["guide_friction_n"] == FRICTION_N and [r["model"] for r in fr["rows"]] == ["er", "ve"]
    for r in fr["rows"]:
        assert r["fast_error"] < 1e-8 and r["reference_error"] < 1e-8 and r["fast_vs_reference"] < 1e-8
        assert r["fast_friction_work_error_J"] < 1e-9 and r["friction_work_J"] > 0
        assert r["ratio"] == pytest.approx(r["reference_seconds_per_map"] / r["fast_seconds_per_map"])
    text = format_table(
        {
            "rows": [],
            "speedup_at_1e-9": None,
            "speedup_at_1e-9_by_model": {},
            "fixed_point": {},
            "guide_friction": fr,
            "compile": {},
            "total_seconds": 0.0,
        }
    )
    assert "guide friction 0.5 N" in text and text.count("fast vs reference") == 2
