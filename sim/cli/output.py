"""What the sim commands print through: a console on stdout or stderr and the two-column quantity table."""

from __future__ import annotations

from typing import Any


def console(stderr: bool = False) -> Any:
    """A rich Console on stdout (or stderr)."""
    from rich.console import Console

    return Console(stderr=stderr)


def table(title: str, rows: list[tuple[str, Any]]) -> Any:
    """A rich table of (quantity, value) rows; floats shown with 6 significant digits.

    On a narrow terminal the names wrap, never the numbers: the value column is at least as wide as its
    longest word (a list of numbers wraps between them) and nothing is cut with an ellipsis."""
    from rich.table import Table

    texts = [(key, f"{value:.6g}" if isinstance(value, float) else str(value)) for key, value in rows]
    widest_word = max((len(w) for _, v in texts for w in v.split()), default=5)
    out = Table(title=title, show_header=True)
    out.add_column("quantity", overflow="fold", min_width=8)
    out.add_column("value", justify="right", overflow="fold", min_width=max(5, widest_word))
    for key, value in texts:
        out.add_row(key, value)
    return out
