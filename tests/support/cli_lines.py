"""What a command said on stderr, less the compile notice a cold first simulator command prints there.

The notice (`rimless.sim.fast.compiling.COMPILE_NOTICE`) is information, not an error: whether a test's command
compiles depends on which kernels an earlier test compiled, so the one-line-error checks read the lines after it.
"""

from __future__ import annotations

COMPILE_NOTICE_PREFIX = "rimless: compiling the simulator"


def stderr_lines(stderr: str) -> list[str]:
    """The non-blank lines of `stderr` without the compile notice."""
    return [line for line in stderr.splitlines() if line.strip() and not line.startswith(COMPILE_NOTICE_PREFIX)]
