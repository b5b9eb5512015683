"""Calling a compiled kernel on first use: say on stderr that it is being compiled (a spinner with the elapsed
time, quiet when stderr is not a terminal or with --json) when it is neither compiled in this process nor in
numba's on-disk cache; otherwise just call it.

May import: numba (through the kernels' dispatchers), rimless.progress.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


def cache_folder(kernel: Any) -> str:
    """Where numba caches `kernel` on disk."""
    try:
        return str(kernel._cache._cache_path)  # noqa: SLF001 (numba's cache locator)
    except AttributeError:
        return "numba's cache"


def is_cached(kernel: Any) -> bool:
    """Whether `kernel` is compiled in this process or has an entry in the on-disk cache (loading it takes
    about a second; compiling it a minute or more)."""
    if kernel.signatures:
        return True
    try:
        return Path(kernel._cache._cache_file._index_path).exists()  # noqa: SLF001 (numba's cache index)
    except AttributeError:
        return True  # another numba: say nothing rather than something wrong


def call_compiling(kernel: Any, *args: Any) -> Any:
    """kernel(*args), announced on stderr while it compiles on first use."""
    if is_cached(kernel):
        return kernel(*args)
    from rimless.progress import spinner

    name = kernel.py_func.__name__
    with spinner(f"compiling the simulator ({name}; first use only, cached in {cache_folder(kernel)})",
                 done=f"compiled the simulator ({name})"):
        return kernel(*args)
