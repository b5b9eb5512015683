"""Trial names in the commands' tables: the common prefix of the file names left out, cut only at a ``_`` or
``-`` (never inside a number such as ``slope1.30deg``), and the caption that says so."""

from __future__ import annotations

import os

__all__ = ["names_shown"]


def names_shown(names: list[str]) -> tuple[list[str], str | None]:
    """The names with their common prefix (up to a ``_`` or ``-``, 6 characters or more) left out, and the
    caption that says so (None when nothing is left out)."""
    prefix = os.path.commonprefix(names) if len(names) > 1 else ""
    cut = max(prefix.rfind("_"), prefix.rfind("-")) + 1
    prefix = prefix[:cut]
    if len(prefix) < 6 or any(len(n) <= len(prefix) for n in names):
        return names, None
    return [n[len(prefix) :] for n in names], f"trial: the file name after {prefix!r}"
