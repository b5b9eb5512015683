"""The sweep cache is keyed by what computes a row: an edit to that code, or to the generated kernels, is a new
key (never a stale row), and RIMLESS_CACHE_DIR moves the cache."""

import sys
import textwrap
from pathlib import Path

import pytest

import rimless.sim.studies.sweep as sweep
from rimless.sim.studies.sweep import SweepOptions, code_fingerprint, point_key, run_sweep


def double_k(point, options):
    """A stand-in grid computation (module level, so a Dask worker could run it too)."""
    return {"rows": [{"k2": 2 * point["k"]}], "points": [], "seconds": 0.0}


@pytest.fixture()
def edited_package(tmp_path, monkeypatch):
    """A package `fakedyn` standing in for the code a row depends on; returns a function that edits it."""
    pkg = tmp_path / "fakedyn"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "rhs.py").write_text("def f(x):\n    return x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sweep, "CODE_PACKAGES", ("fakedyn",))
    code_fingerprint.cache_clear()

    def edit(text: str) -> None:
        (pkg / "rhs.py").write_text(textwrap.dedent(text))
        code_fingerprint.cache_clear()  # a new process (the next command) reads the files afresh

    yield edit
    sys.modules.pop("fakedyn", None)
    code_fingerprint.cache_clear()


def test_an_edit_to_the_code_is_a_new_key(edited_package):
    point, options = {"k": 2700.0}, SweepOptions()
    before = point_key(point, options, double_k)
    assert point_key(point, options, double_k) == before  # deterministic
    edited_package("def f(x):\n    return 2 * x\n")
    assert point_key(point, options, double_k) != before


def test_an_edit_returns_no_stale_row(edited_package, tmp_path):
    cache = tmp_path / "cache"
    first = run_sweep(
        [{"k": 1.0}], SweepOptions(), scheduler="sync", cache_dir=cache, compute=double_k, setup=lambda: 0.0
    )
    again = run_sweep(
        [{"k": 1.0}], SweepOptions(), scheduler="sync", cache_dir=cache, compute=double_k, setup=lambda: 0.0
    )
    assert (first.computed, again.cached) == (1, 1)
    edited_package("def f(x):\n    return -x\n")
    after_edit = run_sweep(
        [{"k": 1.0}], SweepOptions(), scheduler="sync", cache_dir=cache, compute=double_k, setup=lambda: 0.0
    )
    assert after_edit.computed == 1 and after_edit.cached == 0


def test_the_fingerprint_covers_the_generated_kernels_and_the_dynamics():
    files = {p.name for name in sweep.CODE_PACKAGES for p in sweep._package_files(name)}
    root = Path(sweep.__file__).resolve().parents[1]
    for kernel in (root / "model" / "generated").glob("*.py"):
        assert kernel.name in files
    for must in ("dynamics.py", "impact.py", "guards.py", "hybrid.py", "branches.py", "rk.py"):
        assert must in files, must


def test_the_firmware_sweep_key_covers_the_controller():
    assert code_fingerprint("rimless.sim.in_the_loop.sweep") != code_fingerprint("rimless.sim.studies.sweep")
    files = {p.name for p in sweep._package_files("rimless.firmware")}
    assert "controller.py" in files and "detector.py" in files


def test_rimless_cache_dir_moves_the_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("RIMLESS_CACHE_DIR", str(tmp_path / "c"))
    assert sweep.default_cache_dir() == tmp_path / "c" / "sweep"
    monkeypatch.delenv("RIMLESS_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert sweep.default_cache_dir() == tmp_path / "x" / "rimless" / "sweep"
