"""A function in a second process: its value, its exception, a child that dies, Ctrl-C, and the one-core path."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import time

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
    t0 = time.monotonic()
    with pytest.raises(BackgroundFailed, match="exit code 3"):
        Background(os._exit, 3).result()
    assert time.monotonic() - t0 < 30


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
    import sys, time
    from rimless.analysis.inference.background import Background
    if __name__ == "__main__":
        try:
            with Background(time.sleep, 60) as job:
                print(job.pid, flush=True)
                job.result()
        except KeyboardInterrupt:
            sys.stderr.write("interrupted\\n")
            sys.exit(130)
""")


@two_cores
@pytest.mark.parametrize("delay_s", [0.0, 1.0])
def test_ctrl_c_to_the_group_is_one_line_and_leaves_no_child(tmp_path, delay_s):
    """SIGINT to the whole process group (a terminal's Ctrl-C), just after the child started and while it
    runs: the caller prints its one line, the child prints nothing and is gone."""
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
    child = int(proc.stdout.readline())
    time.sleep(delay_s)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130
    assert err == "interrupted\n"
    time.sleep(0.2)
    with pytest.raises(ProcessLookupError):
        os.kill(child, 0)


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
