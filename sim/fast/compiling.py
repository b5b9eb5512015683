"""Calling a compiled kernel on first use: say on stderr that it is being compiled (a spinner with the elapsed
time; one plain line, once per process, when stderr is not a terminal or with --json) when it is neither
compiled in this process nor in numba's on-disk cache; otherwise just call it.

`kernel` is the decorator of the compiled kernels (numba.njit(cache=True) with one difference, see there).
Importing this module also makes numba's on-disk cache safe for processes that compile at the same time
(`lock_cache_saves`).

May import: numba, rimless.progress.
"""

from __future__ import annotations

import os
from contextlib import nullcontext
from pathlib import Path
from typing import Any, Literal

import numba
from numba.core import types as _types
from numba.core.registry import CPUDispatcher


def lock_cache_saves() -> None:
    """Make numba's cache entries safe to add from several processes at once (idempotent).

    numba adds an entry by reading the function's index file, taking the first data file name the index does
    not use and writing the index and the data back, with no lock. Two processes compiling different
    specialisations of one function at the same time (two mass models: test workers, Dask workers) can both
    take the same name; the index of one may then name the machine code of the other, which a later process
    loads for the wrong mass model. A lock file per index (`fcntl.flock`, where the platform has it) makes
    read, pick and write one step."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: numba's behaviour as it is
        return
    from numba.core import caching

    cls = caching.IndexDataCacheFile
    if getattr(cls.save, "_rimless_locked", False):
        return
    unlocked = cls.save

    def save(self: Any, key: Any, data: Any) -> None:
        os.makedirs(self._cache_path, exist_ok=True)
        with open(f"{self._index_path}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
            unlocked(self, key, data)

    save._rimless_locked = True  # type: ignore[attr-defined]
    cls.save = save  # type: ignore[method-assign]  # the point: numba's own save, wrapped in the lock


lock_cache_saves()

# The one argument whose literal value a kernel is specialised on when called from compiled code: the mass
# model index (rimless.sim.fast.model picks that model's generated code at compile time from it).
LITERAL_ARGUMENT = "mi"


class _KernelDispatcher(CPUDispatcher):
    """A numba dispatcher that, called from compiled code, is compiled for the non-literal type of every
    argument except `mi`.

    numba specialises a jitted function called from jitted code on every literal argument (a constant int or
    bool at the call site: a phase code, a guard code, `with_diss=False`): one more copy of the function, and
    of everything below it, per combination of constants, each optimised and emitted by LLVM again. The
    kernels need the literal only for the mass model index (one model's generated code compiled); every other
    argument is an ordinary run-time value, as it is when the kernels are called from Python. Same code, same
    floating-point operations: only fewer copies to compile."""

    def get_call_template(self, args, kws):
        pysig, folded = self._compiler.fold_argument_types(args, kws)
        names = list(pysig.parameters)
        folded = tuple(
            a if i < len(names) and names[i] == LITERAL_ARGUMENT else _types.unliteral(a) for i, a in enumerate(folded)
        )
        return super().get_call_template(folded, {})


def kernel(func: Any = None, *, inline: Literal["never", "always"] = "never", python: bool = True) -> Any:
    """numba.njit(cache=True)(func), specialised from compiled code on the mass model index only (see
    _KernelDispatcher). inline="always": the function's numba IR is inlined into its compiled callers (no
    library of its own to optimise, link and emit again above it; for a function with one or two call sites).

    Without numba's C-ABI wrapper (for first-class function values, not used here), and with python=False
    without the wrapper that calls it from Python (for a kernel called from compiled code only): less code
    to optimise and emit per kernel, the same compiled function."""
    if func is None:
        return lambda f: kernel(f, inline=inline, python=python)
    # numba's stubs list only the public jit options; its njit takes every target option (these two included)
    disp = numba.njit(  # type: ignore[call-overload]
        cache=True, inline=inline, no_cfunc_wrapper=True, no_cpython_wrapper=not python
    )(func)
    disp.__class__ = _KernelDispatcher
    return disp


def cache_folder(kernel: Any) -> str:
    """Where numba caches `kernel` on disk."""
    try:
        return str(kernel._cache._cache_path)
    except AttributeError:
        return "numba's cache"


def is_cached(kernel: Any) -> bool:
    """Whether `kernel` is compiled in this process or has an entry in the on-disk cache (loading it takes
    about a second; compiling it a minute or more)."""
    if kernel.signatures:
        return True
    try:
        return Path(kernel._cache._cache_file._index_path).exists()
    except AttributeError:
        return True  # another numba: say nothing rather than something wrong


# what a first use costs, as the notice says it (docs/performance.md: 25-45 s on a quiet 2-core machine, more
# when the machine is busy)
COMPILE_TIME = "about a minute"
#: the one line a cold compile prints on stderr where no spinner is drawn (a pipe, a log, a notebook, --json)
COMPILE_NOTICE = f"rimless: compiling the simulator (first use, {COMPILE_TIME})..."
_told = False  # the plain notice (no terminal, or --json) was printed in this process: once is enough


def call_compiling(kernel: Any, *args: Any, ahead: Any = None) -> Any:
    """kernel(*args), announced on stderr while it compiles on first use. ``ahead``: a context manager
    factory entered around that first compile only (`rimless.sim.fast.ahead.compiling_ahead`)."""
    if getattr(kernel, "_rimless_called", False):  # skips `is_cached`: its `signatures` costs ~17 us a call
        return kernel(*args)
    if is_cached(kernel):
        out = kernel(*args)
    else:
        from rimless.progress import spinner

        global _told
        name = kernel.py_func.__name__
        plain = None if _told else COMPILE_NOTICE
        _told = True
        with (
            spinner(
                f"compiling the simulator (first use, {COMPILE_TIME})",
                done=f"compiled the simulator ({name})",
                plain=plain,
            ),
            ahead() if ahead is not None else nullcontext(),
        ):
            out = kernel(*args)
    try:
        kernel._rimless_called = True  # compiled or loaded in this process from now on
    except AttributeError:
        pass
    return out
