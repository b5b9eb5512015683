"""Sweeps: the same numbers on every scheduler (a real local Dask cluster with 1 and 2 workers, and in-process),
the on-disk cache, the CLI's contract (`--json` rows and their keys, files written, errors)."""

import json
import math

import pytest
from typer.testing import CliRunner

from rimless.cli import app
from rimless.sim.model.params import WheelParams
from rimless.sim.studies.sweep import SweepOptions, grid_points, point_key, run_sweep
from rimless.values import parse_range
from tests.support.cli_lines import stderr_lines
from tests.support.simcli_truth import NEAR_1_26_DEG, er_stall_by_bisection

OPTIONS = SweepOptions(n_guesses=4)
NUMBERS = ("critical_slope_rad", "max_abs_eigenvalue", "step_period_s", "energy_ratio", "theta_dot_plus_rad_s")


@pytest.fixture(scope="module")
def points():
    return grid_points(WheelParams(), ["er"], {"k": [2600.0, 2700.0]}, ["eight-leg"])


@pytest.fixture(scope="module")
def sync_result(points):
    return run_sweep(points, OPTIONS, scheduler="sync")


@pytest.fixture(scope="module", params=[1, 2])
def cluster_client(request):
    """A real dask.distributed LocalCluster of worker processes, closed after the tests."""
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(
        n_workers=request.param, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=40
    )
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


def _numbers(rows):
    return [[r[k] for k in NUMBERS] for r in rows]


def test_parse_range_includes_the_stop_and_names_the_option():
    assert parse_range("1500:3500:250", "--k") == [1500 + 250 * i for i in range(9)]
    assert parse_range("1,2.5", "--c") == [1.0, 2.5]
    with pytest.raises(ValueError, match="--k"):
        parse_range("3500:1500:250", "--k")
    with pytest.raises(ValueError, match="--c"):
        parse_range("abc", "--c")


def test_sync_sweep_finds_the_er_stall_at_table_1(sync_result):
    er2700 = [r for r in sync_result.rows if r["k"] == 2700.0]
    assert len(er2700) == 1
    r = er2700[0]
    assert r["reason"] == "stall" and r["stable_at_start"] and r["contact_valid_at_start"]
    reason, slope_rad = er_stall_by_bisection(2700.0)  # the same end by another method
    assert r["reason"] == reason and r["critical_slope_rad"] == pytest.approx(slope_rad, abs=1e-6)
    assert r["cot"] == pytest.approx(math.tan(r["critical_slope_rad"]))


def test_cluster_gives_the_same_numbers_as_the_synchronous_scheduler(points, sync_result, cluster_client):
    n = len(cluster_client.scheduler_info()["workers"])
    res = run_sweep(points, OPTIONS, scheduler="local", client=cluster_client)
    assert res.workers == n
    assert _numbers(res.rows) == _numbers(sync_result.rows)


def test_cache_recomputes_nothing_already_done(points, tmp_path):
    first = run_sweep(points[:1], OPTIONS, scheduler="sync", cache_dir=tmp_path)
    assert (first.computed, first.cached) == (1, 0)
    again = run_sweep(points, OPTIONS, scheduler="sync", cache_dir=tmp_path)  # an extended grid
    assert (again.computed, again.cached) == (1, 1)
    assert _numbers(again.rows[:1]) == _numbers(first.rows)
    assert point_key(points[0], OPTIONS) != point_key(points[0], SweepOptions(n_guesses=5))


def test_sweep_cli_json_rows_carry_the_contract_keys(tmp_path):
    out = tmp_path / "s"
    res = CliRunner().invoke(
        app,
        [
            "sim",
            "sweep",
            "--k",
            "2700",
            "--model",
            "ve",
            "--scheduler",
            "sync",
            "--guesses",
            "6",
            "--out",
            str(out),
            "--cache-dir",
            str(tmp_path / "cache"),
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    keys = {
        "model",
        "k",
        "c",
        "mass_model",
        "branch",
        "theta_plus_rad",
        "theta_dot_plus_rad_s",
        "step_period_s",
        "stable_at_start",
        "contact_valid_at_start",
        "contact_reason",
        "critical_slope_rad",
        "critical_slope_deg",
        "reason",
        "cot",
        "energy_ratio",
        "max_abs_eigenvalue",
    }
    assert data["rows"] and all(keys <= set(r) for r in data["rows"])
    assert {r["model"] for r in data["rows"]} == {"VE"}
    medium = [r for r in data["rows"] if r["branch_label"] == "medium"]
    assert medium and medium[0]["reason"] == "fold"
    assert NEAR_1_26_DEG[0] < medium[0]["critical_slope_deg"] < NEAR_1_26_DEG[1]  # model.md section 9
    unstable = [r for r in data["rows"] if not r["stable_at_start"]]
    assert unstable and all(r["critical_slope_rad"] is None and r["reason"] == "unstable-at-start" for r in unstable)
    import pyarrow.parquet as pq

    table = pq.read_table(out.with_suffix(".parquet"))
    assert table.num_rows == len(data["rows"])
    meta = json.loads(table.schema.metadata[b"rimless"])
    assert meta["grid"] == {"k": [2700.0]} and meta["base_params"]["mass_model"] == "eight-leg"
    assert out.with_suffix(".csv").exists()


def _sweep(tmp_path, *args):
    return CliRunner().invoke(
        app,
        ["sim", "sweep", "--model", "er", "--guesses", "4", "--scheduler", "sync", "--no-cache"]
        + ["--out", str(tmp_path / "out" / "s"), *args],
    )


def test_sweep_without_a_gait_at_any_point_is_exit_1_and_writes_no_table(tmp_path):
    res = _sweep(tmp_path, "--model", "er,ve", "--k", "2700", "--start-slope-rad", "0.0087", "--guesses", "3")
    assert res.exit_code == 1, res.output
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: no period-1 gait at any of the 2 grid points"), lines
    assert "0.4985 deg" in lines[0]
    assert res.stdout.strip() == ""
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


def test_sweep_where_some_points_have_gaits_is_exit_0_with_a_no_gait_row(tmp_path):
    # at 0.0225 rad the ER wheel of k = 3500 N/m walks (its branch stalls at 1.21 deg), that of 1500 N/m does not
    res = _sweep(tmp_path, "--k", "1500,3500", "--start-slope-rad", "0.0225", "--json")
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)["rows"]
    assert [(r["k"], r["reason"]) for r in rows] == [(1500.0, "no-gait"), (3500.0, "stall")]
    assert (tmp_path / "out" / "s.parquet").exists() and (tmp_path / "out" / "s.csv").exists()


@pytest.mark.parametrize(
    "args, option",
    [
        (["--k", "1:2:0"], "--k"),
        (["--k", "-5"], "--k"),
        (["--model", "xx"], "--model"),
        (["--scheduler", "bogus"], "--scheduler"),
        (["--mass-model", "wrong"], "--mass-model"),
    ],
)
def test_sweep_cli_bad_values_are_one_line_errors(args, option, tmp_path):
    res = CliRunner().invoke(app, ["sim", "sweep", *args, "--out", str(tmp_path / "s")])
    assert res.exit_code == 2
    lines = stderr_lines(res.stderr)
    assert len(lines) == 1 and lines[0].startswith("error:") and option in lines[0]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # the dropped interrupt, on purpose
def test_the_commands_local_cluster_leaves_no_gc_callback_to_swallow_a_ctrl_c():
    """Python reports and drops an exception raised inside a gc callback; the in-process Dask scheduler installs
    one, so a Ctrl-C landing in it was lost (`rimless paper` ran on and exited 0). The command's cluster runs
    without it: first that a KeyboardInterrupt raised in a gc callback is indeed lost, then that none is left."""
    import gc

    from rimless.sim.studies.sweep import dask_client

    def interrupt(phase, info):
        raise KeyboardInterrupt

    gc.callbacks.append(interrupt)
    try:
        gc.collect()  # prints "Exception ignored in ..." and goes on
    finally:
        gc.callbacks.remove(interrupt)
    from distributed.gc import GCDiagnosis

    with dask_client("local", 1):  # (another test's cluster in this worker may have installed one before)
        assert not [cb for cb in gc.callbacks if isinstance(getattr(cb, "__self__", None), GCDiagnosis)]
