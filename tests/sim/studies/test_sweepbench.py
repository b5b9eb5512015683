"""`rimless sim sweep --bench`: the speed-up from 1 to 2 workers comes from the workers' CPU time, the wall
time beside (fakes for the cluster and the sweep: the numbers are what the fakes say, the arithmetic is the
benchmark's)."""

from __future__ import annotations

import contextlib
from types import SimpleNamespace

import pytest

from rimless.sim.studies import bench, sweep, sweepbench


class FakeCluster:
    """Workers whose CPU clocks advance by `work_s` each during a sweep, while the wall clock (shared fake)
    advances by `wall_s`: a loaded machine stretches the wall time of the 2-worker run."""

    def __init__(self, clock: dict[str, float]) -> None:
        self.clock = clock
        self.plan = {1: ([8.0], 8.0), 2: ([4.5, 4.0], 9.0)}  # worker CPU s, wall s per run
        self.workers = 0
        self.cpu: dict[str, float] = {}

    @contextlib.contextmanager
    def client(self, scheduler: str, workers: int):
        assert scheduler == "local"
        self.workers = workers
        self.cpu = {f"w{i}": 100.0 * i for i in range(workers)}
        yield SimpleNamespace(run=lambda fn: dict(self.cpu))

    def run_sweep(self, points, options, *, scheduler, client=None):
        if scheduler == "sync":
            self.clock["cpu"] += 16.0
            self.clock["wall"] += 16.0
        else:
            work, wall = self.plan[self.workers]
            for i, w in enumerate(work):
                self.cpu[f"w{i}"] += w
            self.clock["wall"] += wall
        return SimpleNamespace(rows=[{"critical_slope_rad": 0.02}], setup_s=0.5)


def test_the_worker_speed_up_is_from_cpu_time_with_the_wall_beside(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = {"cpu": 0.0, "wall": 0.0}
    fake = FakeCluster(clock)
    monkeypatch.setattr(bench, "CLOCKS", bench.Clocks(cpu=lambda: clock["cpu"], wall=lambda: clock["wall"]))
    monkeypatch.setattr(sweep, "dask_client", fake.client)
    monkeypatch.setattr(sweep, "run_sweep", fake.run_sweep)
    monkeypatch.setattr(sweepbench.time, "perf_counter", lambda: clock["wall"])
    out = sweepbench.sweep_bench([{"k": 2500.0}], None)
    assert out["sync"]["cpu_s"] == 16.0 and out["2 workers"]["worker_cpu_s"] == [4.0, 4.5]
    assert out["speedup_1_to_2_workers"] == pytest.approx(8.0 / 4.5)  # 1 worker's CPU / the busiest of 2
    assert out["speedup_1_to_2_workers_wall"] == pytest.approx(8.0 / 9.0)  # the load made 2 workers slower
    assert out["max_difference_between_schedulers"] == 0.0
    text = sweepbench.format_bench({"sweep": out})
    assert "speed-up 1 -> 2 workers: 1.78x from CPU time (1 worker's CPU / the busiest of 2), 0.89x wall" in text
    assert "2 workers  CPU     8.5 s (workers 4.0, 4.5), wall     9.0 s" in text
