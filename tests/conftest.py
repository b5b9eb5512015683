"""Fixtures shared across the test folders."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass(frozen=True)
class DemoRun:
    """One `rimless demo --out DIR` run as a user starts it: its folder, stdout, stderr and exit code."""

    out: Path
    stdout: str
    stderr: str
    returncode: int


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> DemoRun:
    """The demo, run once per session (it takes about a minute) for the tests that read what it wrote."""
    out = tmp_path_factory.mktemp("demo") / "demo"
    res = subprocess.run([sys.executable, "-m", "rimless", "demo", "--out", str(out)], capture_output=True,
                         text=True, timeout=900, stdin=subprocess.DEVNULL)
    return DemoRun(out=out, stdout=res.stdout, stderr=res.stderr, returncode=res.returncode)
