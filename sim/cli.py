"""`rimless sim ...`: thin commands over the simulator library."""

from __future__ import annotations

import typer

app = typer.Typer(no_args_is_help=True)
