"""The `rimless` command line: one typer app, a sub-app per part.

Heavy libraries are imported inside the commands, so `rimless --help` stays fast.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from typing import Any, TypeVar

import typer

from rimless.errors import UserError

F = TypeVar("F", bound=Callable[..., Any])

EXIT_USER_ERROR = 2


def user_facing(func: F) -> F:
    """Turn a `UserError` raised by a command into a one-line message and exit code 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except UserError as err:
            typer.echo(f"error: {err}", err=True)
            raise typer.Exit(EXIT_USER_ERROR) from None

    return wrapper  # type: ignore[return-value]


def print_json(obj: Any) -> None:
    """Print one JSON object on stdout (NaN/inf become null, numpy scalars become numbers)."""
    typer.echo(json.dumps(_jsonable(obj), indent=2, allow_nan=False))


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return _jsonable(obj.tolist())
    if isinstance(obj, float) and (obj != obj or obj in (float("inf"), float("-inf"))):
        return None
    return obj


app = typer.Typer(
    name="rimless",
    help="Energy-recycling rimless wheel: simulate it, run the robot, analyse Vicon trials.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _register_subapps() -> None:
    from rimless.analysis.cli import app as trials_app
    from rimless.analysis.cli import register_top_level as register_analysis_top
    from rimless.firmware.cli import app as robot_app
    from rimless.sim.cli import app as sim_app
    from rimless.sim.cli import register_top_level as register_sim_top

    app.add_typer(sim_app, name="sim", help="Hybrid simulator: gaits, fixed points, critical slope.")
    app.add_typer(robot_app, name="robot", help="The robot: run the firmware, talk to it over the LAN.")
    app.add_typer(trials_app, name="trials", help="Vicon trials: import, compare with the model, report.")
    register_sim_top(app)
    register_analysis_top(app)


_register_subapps()


def main() -> None:
    """Entry point of the `rimless` console script."""
    app()
