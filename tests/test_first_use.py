"""First use of the simulator: where the compiled kernels are cached (RIMLESS_CACHE_DIR) and the notice on
stderr while they compile (rimless.progress.spinner), quiet for pipes, on stderr with --json."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from rimless import progress
from tests.support import first_use


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_rimless_cache_dir_moves_numbas_cache(tmp_path: Path) -> None:
    """Kernels are cached under $RIMLESS_CACHE_DIR/numba, also for subprocesses (NUMBA_CACHE_DIR exported)."""
    code = "import os\nfrom rimless.sim import fast\nprint(fast.cache_folder())\nprint(os.environ['NUMBA_CACHE_DIR'])\n"
    env = {k: v for k, v in __import__("os").environ.items() if k != "NUMBA_CACHE_DIR"}
    res = subprocess.run(
        [sys.executable, "-c", code],
        env={**env, "RIMLESS_CACHE_DIR": str(tmp_path / "c")},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    kernel_folder, exported = res.stdout.split()
    assert Path(exported) == tmp_path / "c" / "numba"
    assert Path(kernel_folder).is_relative_to(tmp_path / "c" / "numba")


def test_spinner_is_quiet_for_pipes_and_on_stderr_with_json(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pipe = io.StringIO()
    monkeypatch.setattr(sys, "stderr", pipe)
    with progress.spinner("compiling", done="compiled") as shown:
        pass
    assert shown is False and pipe.getvalue() == ""
    # on a terminal with --json the spinner is drawn on stderr; stdout (the JSON) is untouched
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setattr(sys, "argv", ["rimless", "sim", "fixed-point", "--json"])
    with progress.spinner("compiling", done="compiled") as shown:
        print('{"a": 1}')
    assert shown is True and re.search(r"compiled \(\d+ s\)\n$", term.getvalue()), repr(term.getvalue()[-300:])
    assert capsys.readouterr().out == '{"a": 1}\n' and '{"a": 1}' not in term.getvalue()


def test_spinner_says_what_it_did_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setattr(sys, "argv", ["rimless", "sim", "fixed-point"])
    with progress.spinner("compiling the simulator", done="compiled the simulator") as shown:
        time.sleep(0.05)
    assert shown is True
    assert re.search(r"compiled the simulator \(\d+ s\)\n$", term.getvalue()), repr(term.getvalue()[-300:])


def test_spinner_inside_a_bar_uses_that_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    """rich allows one live display: inside a command's bar the spinner's text goes into that bar."""
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setattr(sys, "argv", ["rimless", "sim", "sweep"])
    with progress.progress_bar("sweep", total=3) as bar:
        with progress.spinner("compiling the simulator", done="compiled") as shown:
            assert shown is True
            assert bar._progress.tasks[-1].description == "compiling the simulator"
        assert bar._progress.tasks[-1].description == "sweep"
        bar.advance()


def test_first_call_of_a_cold_kernel_is_announced(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A kernel neither compiled in this process nor in the on-disk cache is announced; a cached one is not."""
    from rimless.sim import fast

    calls: list[tuple] = []

    def kernel(*args):
        calls.append(args)
        return 42

    cold = SimpleNamespace(
        signatures=[],
        py_func=kernel,
        __call__=None,
        _cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(tmp_path / "none"))),
    )
    warm = SimpleNamespace(signatures=["(int64,)"], py_func=kernel)

    class Callable(SimpleNamespace):
        def __call__(self, *args):
            return self.py_func(*args)

    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setattr(sys, "argv", ["rimless", "sim", "fixed-point"])
    assert fast.compiling.call_compiling(Callable(**vars(warm)), 1) == 42
    assert term.getvalue() == ""
    assert fast.compiling.call_compiling(Callable(**vars(cold)), 2) == 42
    assert "compiled the simulator (kernel)" in term.getvalue()
    assert calls == [(1,), (2,)]


@pytest.fixture(scope="module")
def probe_lines(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """The first-use probe's output from a cold cache: the suite's warm-up's, when it found the cache cold
    (tests/conftest.py; a fresh clone), else a run here in an empty RIMLESS_CACHE_DIR."""
    tmp_path = tmp_path_factory.mktemp("first-use-cache")
    recorded = os.environ.get(first_use.RECORD_ENV)
    if recorded and Path(recorded).is_file():
        lines = Path(recorded).read_text().splitlines()
        if len(lines) == first_use.LINES and lines[0] == "cold":  # whole (a warm-up killed midway is not used)
            return lines
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(RIMLESS_CACHE_DIR=str(tmp_path), RIMLESS_NO_BACKGROUND="1")  # the whole compile in one process
    res = subprocess.run([sys.executable, "-c", first_use.PROBE], env=env, capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout.splitlines()


@pytest.mark.slow
def test_a_step_compiles_its_own_mass_model_only(probe_lines: list[str]) -> None:
    """With an empty cache, a step of the eight-leg wheel compiles the eight-leg generated code and none of the
    other two mass models' (they were all compiled before: one kernel switched on the mass model at run time)."""
    lines = probe_lines
    assert lines[0] == "cold"
    z = [float(v) for v in lines[1].split()]
    assert z == pytest.approx([-0.465155, 2.604441], abs=2e-6)  # the ER gait at Table 1 is a fixed point
    families = [line.split() for line in lines[2:-2]]
    assert [f[0] for f in families] == ["_M", "_DL", "_DLD", "_DM", "_T"]
    for name, *counts in families:
        assert counts[1:] == ["0", "0"], (name, counts)  # sliding-leg, active-feet: not compiled
        assert name not in ("_M", "_DL", "_DLD") or counts[0] != "0", (name, counts)  # eight-leg: compiled


@pytest.mark.slow
def test_a_cold_step_compiles_no_string_formatting(probe_lines: list[str]) -> None:
    """numba compiles an error message with string formatting for some operations inside a kernel (a slice
    copied from an array: its shape-mismatch message, about 2.5 s of a cold compile); the step kernel avoids
    them (a copy is a loop). Same probe, same cold compile as the tests above."""
    assert probe_lines[-2].split()[0] == "strings"
    assert probe_lines[-2].split()[1:] == [], f"numba string code compiled by one step: {probe_lines[-2]}"


@pytest.mark.slow
def test_the_ahead_plan_names_what_the_step_kernel_compiles(probe_lines: list[str]) -> None:
    """Every function rimless.sim.fast.ahead.PLAN compiles in the second process is one the step kernel calls,
    with the same argument types (else the step kernel compiles it again, and the second core's work is lost).
    Same probe, same cold compile as the test above."""
    assert probe_lines[-1].split()[0] == "stale"
    assert probe_lines[-1].split()[1:] == [], f"PLAN entries not used as written: {probe_lines[-1]}"


@pytest.mark.parametrize("given", [None, "1"])
def test_loop_vectoriser_off_unless_the_environment_says(given: str | None) -> None:
    """rimless.sim.fast compiles without LLVM's loop vectoriser (less compile time, same results,
    docs/performance.md) unless NUMBA_LOOP_VECTORIZE is set; subprocesses inherit the setting."""
    code = (
        "import os, numba\nfrom rimless.sim import fast\n"
        "print(os.environ['NUMBA_LOOP_VECTORIZE'], numba.config.LOOP_VECTORIZE)\n"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "NUMBA_LOOP_VECTORIZE"}
    if given is not None:
        env["NUMBA_LOOP_VECTORIZE"] = given
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split() == (["0", "0"] if given is None else ["1", "1"])


def _cold_kernel(tmp_path: Path, name: str = "run_phase_0") -> Any:
    """A stand-in for a numba kernel that is neither compiled in this process nor in the on-disk cache."""

    def body(*args):
        return 42

    body.__name__ = name

    class Cold(SimpleNamespace):
        def __call__(self, *args):
            return self.py_func(*args)

    folder = tmp_path / "a-long-cache-folder" / "numba" / "rimless" / "sim" / "fast"
    return Cold(
        signatures=[],
        py_func=body,
        _cache=SimpleNamespace(
            _cache_path=str(folder), _cache_file=SimpleNamespace(_index_path=str(folder / "none.nbi"))
        ),
    )


@pytest.mark.parametrize("where", ["pipe", "pipe with --json"])
def test_a_cold_compile_says_so_in_one_plain_line_where_no_spinner_is_drawn(
    where: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Fails before: a redirected run (a log, a notebook) or one with --json was silent through the whole compile.
    (On a terminal with --json the spinner is drawn on stderr: `test_spinner_is_quiet_for_pipes_and_on_stderr...`.)"""
    from rimless.sim.fast import compiling

    monkeypatch.setattr(compiling, "_told", False)
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setattr(sys, "argv", ["rimless", "sim", "fixed-point"] + (["--json"] if "json" in where else []))
    assert compiling.call_compiling(_cold_kernel(tmp_path, "step_map_contact_0"), 1) == 42
    assert compiling.call_compiling(_cold_kernel(tmp_path, "run_phase_0"), 2) == 42  # once per process
    assert err.getvalue() == "rimless: compiling the simulator (first use, about a minute)...\n"


def test_the_compile_spinner_keeps_its_elapsed_time_on_an_80_column_line(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Fails before: the kernel's name and its cache folder in the text pushed the elapsed time off the line."""
    from rimless.sim.fast import compiling

    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setenv("COLUMNS", "80")
    monkeypatch.setattr(sys, "argv", ["rimless", "sim", "fixed-point"])
    assert compiling.call_compiling(_cold_kernel(tmp_path, "step_map_contact_0"), 1) == 42
    drawn = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", term.getvalue()).replace("\r", "\n").splitlines()
    spinner_lines = [line for line in drawn if "compiling the simulator" in line]
    assert spinner_lines, drawn
    for line in spinner_lines:
        assert len(line) <= 80 and re.search(r"\d:\d\d:\d\d$", line.rstrip()), repr(line)
    assert re.search(r"compiled the simulator \(step_map_contact_0\) \(\d+ s\)\n$", term.getvalue())  # then
