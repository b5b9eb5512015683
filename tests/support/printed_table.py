"""The rich tables the commands print, read back: each row's name (its lines joined) and the cells of its first
line (tests of `rimless trials report` and `rimless demo` at a terminal's width)."""

from __future__ import annotations

import re

__all__ = ["parse_table", "name_lines"]


def parse_table(text: str) -> tuple[list[tuple[str, list[str]]], str | None]:
    """The printed rows: (the trial name, its lines joined; the cells of its first line), and the prefix the
    caption says was left out of the names."""
    rows: list[tuple[str, list[str]]] = []
    for line in text.splitlines():
        if "│" not in line:
            continue
        cells = [c.strip() for c in line.split("│")]
        if cells[1]:  # a row's first line: its status and numbers
            rows.append((cells[0], cells[1:]))
        else:  # the name continues
            rows[-1] = (rows[-1][0] + cells[0], rows[-1][1])
    caption = re.search(r"trial: the file name after '([^']*)'", text)
    return rows, caption.group(1) if caption else None


def name_lines(text: str) -> list[list[str]]:
    """Each row's name as printed, line by line."""
    out: list[list[str]] = []
    for line in text.splitlines():
        if "│" not in line:
            continue
        cells = [c.strip() for c in line.split("│")]
        if cells[1]:
            out.append([cells[0]])
        else:
            out[-1].append(cells[0])
    return out
