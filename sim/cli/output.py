"""What the sim commands print through: a console on stdout or stderr and the two-column quantity table."""

from __future__ import annotations

from typing import Any


def console(stderr: bool = False) -> Any:
    """A rich Console on stdout (or stderr)."""
    from rich.console import Console

    return Console(stderr=stderr)


def table(title: str, rows: list[tuple[str, Any]]) -> Any:
    """A rich table of (quantity, value) rows; floats shown with 6 significant digits."""
    from rich.table import Table

    out = Table(title=title, show_header=True)
    out.add_column("quantity")
    out.add_column("value", justify="right")
    for key, value in rows:
        if isinstance(value, float):
            value = f"{value:.6g}"
        out.add_row(key, str(value))
    return out
