"""The benchmark's ratios come from CPU time, wall time beside, and its report of machine load."""

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
                "cpu_seconds_per_map": 3.5e-4,
                "nfev": 1200,
                "nsteps": 90,
            }
        ],
        "load_average": {"before": [1.9, 1.5, 1.0], "after": [2.8, 1.7, 1.1], "cpus": 2, "busy": busy},
        "speedup_at_1e-9": 70.0,
        "speedup_at_1e-9_wall": 300.0,
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


def test_the_table_prints_the_cpu_ratio_and_marks_the_wall_one_on_a_busy_machine() -> None:
    busy = bench.format_table(_result(True))
    quiet = bench.format_table(_result(False))
    assert "load average 1/5/15 min: before 1.90 1.50 1.00, after 2.80 1.70 1.10 (2 cores)" in busy
    lines = busy.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.startswith("speed-up"))
    assert lines[i].endswith("worst): 70x (wall 300x, busy machine)") and lines[i + 1].startswith("WARNING")
    assert all(len(ln) <= 80 for ln in lines)
    line = next(ln for ln in quiet.splitlines() if ln.startswith("speed-up"))
    assert line.endswith(": 70x (wall 300x)") and "WARNING" not in quiet
    assert "3.50e-04 4.00e-04" in quiet  # the row: CPU then wall seconds per map


class FakeClocks:
    """A CPU clock and a wall clock that the fake work below moves by what it says: other processes on the
    machine stretch the wall time of the reference path tenfold, not its CPU time."""

    def __init__(self) -> None:
        self.cpu_s = 0.0
        self.wall_s = 1000.0

    def work(self, cpu_s: float, stretch: float):
        def fn() -> None:
            self.cpu_s += cpu_s
            self.wall_s += cpu_s * stretch

        return fn

    def clocks(self) -> bench.Clocks:
        return bench.Clocks(cpu=lambda: self.cpu_s, wall=lambda: self.wall_s)


def test_the_printed_speed_up_is_the_ratio_of_cpu_times_not_of_wall_times(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = FakeClocks()
    monkeypatch.setattr(bench, "CLOCKS", fake.clocks())
    fast = bench._time_per_call(fake.work(1.4e-4, 1.0), budget_s=0.01, max_reps=50)
    ref = bench._time_per_call(fake.work(5.6e-2, 10.0), budget_s=1.0, max_reps=5)
    assert (fast.cpu_s, fast.wall_s) == pytest.approx((1.4e-4, 1.4e-4))
    assert (ref.cpu_s, ref.wall_s) == pytest.approx((5.6e-2, 0.56))
    rows = []
    for backend, t in (("fast-dop853", fast), ("scipy-DOP853", ref)):
        rows.append(
            {
                "model": "er",
                "backend": backend,
                "rtol": 1e-9,
                "error": 5e-10,
                "period_error_s": 0.0,
                "eigenvalue_error": 0.0,
                "seconds_per_map": t.wall_s,
                "cpu_seconds_per_map": t.cpu_s,
                "nfev": 1,
            }
        )
    speedups = bench.speedups_at_target(rows)
    assert speedups["er"]["speedup"] == pytest.approx(400.0)  # 5.6e-2 / 1.4e-4, the CPU times
    assert speedups["er"]["speedup_wall"] == pytest.approx(4000.0)
    res = _result(False)
    res.update(
        {"rows": rows, "speedup_at_1e-9": 400.0, "speedup_at_1e-9_wall": 4000.0, "speedup_at_1e-9_by_model": speedups}
    )
    lines = bench.format_table(res).splitlines()
    assert any(ln.endswith("worst): 400x (wall 4000x)") for ln in lines)
    assert "  er: fast rtol 1e-09 0.140 ms, DOP853 rtol 1e-09 56.0 ms: 400x" in lines
    assert "    wall: fast 0.140 ms, DOP853 560.0 ms: 4000x" in lines


def test_the_repetitions_fill_a_budget_of_cpu_time_whatever_the_wall_clock_does(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    for stretch in (1.0, 25.0):  # a quiet and a loaded machine: the same four repetitions
        fake = FakeClocks()
        monkeypatch.setattr(bench, "CLOCKS", fake.clocks())
        bench._time_per_call(fake.work(0.3, stretch), budget_s=1.0, max_reps=100)
        assert fake.cpu_s == pytest.approx(1.2)


def test_time_once_reads_both_clocks(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = FakeClocks()
    monkeypatch.setattr(bench, "CLOCKS", fake.clocks())
    out, t = bench.time_once(lambda: (fake.work(2.0, 3.0)(), "done")[1])
    assert out == "done" and (t.cpu_s, t.wall_s) == pytest.approx((2.0, 6.0))
    assert bench.cpu_ratio(1.0, 0.0) is None and bench.cpu_ratio(None, 1.0) is None


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
        assert r["ratio"] == pytest.approx(r["reference_cpu_seconds_per_map"] / r["fast_cpu_seconds_per_map"])
        assert r["ratio_wall"] == pytest.approx(r["reference_seconds_per_map"] / r["fast_seconds_per_map"])
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
