"""How the README's commands run in the tests: the environment, and the README's `rimless demo` (shared between
tests/test_readme.py and the tests that read the demo's report, tests/conftest.py's `demo_run`)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The README's set-up line runs this command.
DEMO_COMMAND = ".venv/bin/rimless demo"
#: Where `rimless demo` writes without --out.
DEMO_FOLDER = "rimless-demo"


def readme_env() -> dict[str, str]:
    """The environment the README's commands run in: the running venv first on PATH (what `source
    .venv/bin/activate` does), 80 columns."""
    bin_dir = Path(sys.prefix) / "bin"
    return {
        **os.environ,
        "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
        "VIRTUAL_ENV": sys.prefix,
        "COLUMNS": "80",
    }
