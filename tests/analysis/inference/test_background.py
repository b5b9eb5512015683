"""A function in a second process: its value, its exception, a child that dies, Ctrl-C, and the one-core path."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import psutil  # with dask.distributed
import pytest

from rimless.analysis.inference.background import Background, BackgroundFailed, background_allowed

two_cores = pytest.mark.skipif(not background_allowed(), reason="one core: nothing runs in a second process")


@two_cores
def test_value_and_exception_come_back_from_the_child():
    with Background(math.factorial, 20) as job:
        assert job.in_background and job.pid not in (None, os.getpid())
        assert job.result() == 2432902008176640000
    with pytest.raises(ValueError, match="invalid literal"):
        Background(int, "not a number").result()


@two_cores
def test_a_child_that_dies_without_an_answer_is_a_failure_not_a_hang():
    """Once the child has died, result() raises at once: the child's end of the pipe is closed, and no wait for
    an answer that cannot come runs out (counted, not timed)."""
    job = Background(os._exit, 3)
    job._proc.join()  # the event: the child has died without an answer
    poll = job._conn.poll
    waits_run_out: list[float] = []

    def counting_poll(timeout: float = 0.0) -> bool:
        ready = poll(timeout)
        if not ready and timeout:
            waits_run_out.append(timeout)
        return ready

    job._conn.poll = counting_poll
    with pytest.raises(BackgroundFailed, match="exit code 3"):
        job.result()
    assert waits_run_out == []


@two_cores
def test_close_stops_a_running_child():
    job = Background(time.sleep, 60)
    pid = job.pid
    job.close()
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_without_background_the_function_runs_here(monkeypatch):
    monkeypatch.setenv("RIMLESS_NO_BACKGROUND", "1")
    job = Background(os.getpid)
    assert not job.in_background and job.pid is None
    assert job.result() == os.getpid()


SCRIPT = textwrap.dedent("""
    import os, sys, time
    from rimless.analysis.inference.background import Background

    def work():
        os.write(1, b"running\\n")  # in the child, inside the function (its sys.stdout is os.devnull)
        time.sleep(60)

    if __name__ == "__main__":
        try:
            with Background(work) as job:
                print(job.pid, flush=True)
                job.result()
        except KeyboardInterrupt:
            sys.stderr.write("interrupted\\n")
            sys.exit(130)
""")


@two_cores
@pytest.mark.parametrize("moment", ["started", "running"])
def test_ctrl_c_to_the_group_is_one_line_and_leaves_no_child(tmp_path, moment):
    """SIGINT to the whole process group (a terminal's Ctrl-C), as soon as the child has started (its pid is
    known) and once it runs the function (it said so): the caller prints its one line, the child prints nothing
    and is gone."""
    script = tmp_path / "job.py"
    script.write_text(SCRIPT)
    proc = subprocess.Popen(
        [sys.executable, str(script)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    lines = [proc.stdout.readline()]
    if moment == "running":
        lines.append(proc.stdout.readline())
    assert lines[-1].strip() == ("running" if moment == "running" else lines[0].strip()), lines
    child = psutil.Process(int(next(line for line in lines if line.strip().isdigit())))
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert err == "interrupted\n"
    gone, _ = psutil.wait_procs([child], timeout=60)  # the event: the child's end (a zombie until reaped)
    assert gone, f"the child {child.pid} still runs"


@two_cores
def test_started_before_its_arguments_then_submitted():
    job = Background.started(math.factorial, prepare=os.getpid)
    assert job.in_background
    with pytest.raises(RuntimeError, match="no arguments"):
        job.result()
    job.submit(10)
    with pytest.raises(RuntimeError, match="given already"):
        job.submit(11)
    assert job.result() == 3628800


@two_cores
def test_a_failing_preparation_is_the_result():
    job = Background.started(math.factorial, prepare=_fails)
    job.submit(3)
    with pytest.raises(ZeroDivisionError):
        job.result()


@two_cores
def test_closed_before_its_arguments_the_child_ends_quietly():
    job = Background.started(math.factorial)
    pid = job.pid
    job.close()
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def _fails() -> None:
    1 / 0  # noqa: B018
