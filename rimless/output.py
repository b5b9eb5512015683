"""Outputs written whole or not at all: write to a temporary name beside the target, rename when done.

An interrupted or failed command leaves neither a half-written file nor an empty folder at the path the
user asked for (the temporary is removed); an earlier complete output there stays until the new one is
complete. A path that cannot be written is a `OutputFileError` naming the path (and the option).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from rimless.errors import OutputFileError


def _where(target: Path, option: str | None) -> str:
    return f"{option} {target}" if option else str(target)


def _prepare_parent(target: Path, option: str | None) -> Path:
    parent = target.parent if str(target.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputFileError(
            f"{_where(target, option)}: cannot create the folder {parent} ({err.strerror or err})"
        ) from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputFileError(f"{_where(target, option)}: the folder {parent} is not writable")
    return parent


def writable_dir(folder: os.PathLike[str] | str, *, option: str | None = None) -> Path:
    """Create `folder` if needed and check that it is writable; `OutputFileError` naming `option` otherwise."""
    target = Path(folder)
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputFileError(f"{_where(target, option)}: cannot create the folder ({err.strerror or err})") from None
    if not os.access(target, os.W_OK | os.X_OK):
        raise OutputFileError(f"{_where(target, option)}: the folder is not writable")
    return target


def check_output_folder(out: os.PathLike[str] | str, *, option: str | None = None) -> None:
    """Refuse an output folder that cannot be written, before any work; `OutputFileError` naming `option`.

    Unlike `writable_dir` it leaves nothing behind: a folder it had to create to try is removed again.
    """
    import shutil

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputFileError(f"{_where(out, option)}: exists and is not a folder")
    first_new = None
    probe = out
    while not probe.exists() and probe != probe.parent:
        first_new, probe = probe, probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise OutputFileError(f"{_where(out, option)}: cannot write in {probe}")
    if first_new is not None:  # try for real (access() says yes to root everywhere), then leave no trace
        try:
            out.mkdir(parents=True)
        except OSError as err:
            raise OutputFileError(f"{_where(out, option)}: cannot create the folder ({err.strerror or err})") from None
        shutil.rmtree(first_new, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(target: os.PathLike[str] | str, *, option: str | None = None) -> Iterator[Path]:
    """Yield a temporary path (same folder and suffix as `target`); rename it onto `target` when the block ends.

    The suffix is kept so writers that choose the format by extension (matplotlib, pandas) still work.
    """
    target = Path(target)
    if target.is_dir():
        raise OutputFileError(f"{_where(target, option)}: is a folder, expected a file name")
    parent = _prepare_parent(target, option)
    fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".part{target.suffix}", dir=parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        if not tmp.exists():
            raise OutputFileError(f"{_where(target, option)}: nothing was written")
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_files(*targets: tuple[os.PathLike[str] | str | None, str | None]) -> Iterator[list[Path | None]]:
    """Several outputs of one command, all or none: `targets` are (path or None, option) pairs; yield one
    temporary path per target (same folder and suffix; None for a None target).

    When the block ends, every temporary is renamed onto its target with SIGINT held back (in the main thread),
    so a Ctrl-C never leaves some outputs renamed and others not: one arriving meanwhile is delivered once all
    are in place. If the block raises (a Ctrl-C included), every temporary is removed and no target changes.
    """
    planned: list[tuple[Path, Path, str | None] | None] = []
    try:
        for target, option in targets:
            if target is None:
                planned.append(None)
                continue
            target = Path(target)
            if target.is_dir():
                raise OutputFileError(f"{_where(target, option)}: is a folder, expected a file name")
            parent = _prepare_parent(target, option)
            fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".part{target.suffix}", dir=parent)
            os.close(fd)
            planned.append((Path(name), target, option))
        yield [None if p is None else p[0] for p in planned]
        written = [p for p in planned if p is not None]
        for tmp, target, option in written:
            if not tmp.exists():
                raise OutputFileError(f"{_where(target, option)}: nothing was written")
            os.chmod(tmp, 0o666 & ~_umask())
        with ctrl_c_held():
            for tmp, target, _option in written:
                os.replace(tmp, target)
    except BaseException:
        for p in planned:
            if p is not None:
                p[0].unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def ctrl_c_held() -> Iterator[None]:
    """Hold a Ctrl-C back for the block: SIGINT only noted meanwhile, then sent again once the block is over
    (main thread only; elsewhere Python raises no KeyboardInterrupt anyway). Not a signal mask: the signal may
    be delivered to any thread of the process, and Python raises it in the main thread all the same."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if noted and previous is not signal.SIG_IGN:
            signal.raise_signal(signal.SIGINT)


@contextlib.contextmanager
def atomic_dir(target: os.PathLike[str] | str, *, option: str | None = None) -> Iterator[Path]:
    """Yield a temporary folder beside `target`; when the block ends it replaces `target` as a whole.

    An existing `target` folder is replaced only after the new one is complete; an existing file there
    is an `OutputFileError`.
    """
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise OutputFileError(f"{_where(target, option)}: exists and is not a folder")
    parent = _prepare_parent(target, option)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".part", dir=parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=parent))
            os.replace(target, old / target.name)
            os.replace(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
