"""Whether work may go to a second process: only with a second core, and not with ``RIMLESS_NO_BACKGROUND=1``
in the environment (docs/cli.md). The one rule for the simulator's compile-ahead process
(rimless.sim.fast.ahead) and the analysis's background work (rimless.analysis.inference.background).

May import: the standard library only.
"""

from __future__ import annotations

import os


def second_process_allowed() -> bool:
    """Two or more cores usable by this process, and RIMLESS_NO_BACKGROUND unset (or "0")."""
    if os.environ.get("RIMLESS_NO_BACKGROUND", "") not in ("", "0"):
        return False
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return cores > 1
