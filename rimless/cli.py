"""The `rimless` command line: one typer app, a sub-app per part, one behaviour for every command.

The root group (`RimlessGroup`, rimless.cli_rules) applies the rules to every command of the tree, including
commands the parts add later: one-line errors with exit 2 for usage mistakes, exit 1 for a run without a
result, `interrupted` and exit 130 on Ctrl-C. The rules live in rimless.cli_rules (re-exported here), so that
a part's command module can import them on its own. Heavy libraries are imported inside the commands, so
`rimless --help` stays fast.
"""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from rimless import __version__
from rimless.cli_rules import (  # noqa: F401  (re-exported for users' scripts; parts use rimless.cli_rules)
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USER_ERROR,
    RimlessGroup,
    click,
    fail,
    print_json,
    usage_message,
    user_facing,
    walk_commands,
)

# ------------------------------------------------------------------------------------------ the app


app = typer.Typer(
    name="rimless",
    cls=RimlessGroup,
    help="Energy-recycling rimless wheel: simulate it, run the robot, analyse Vicon trials.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"rimless {__version__}")
        raise typer.Exit(EXIT_OK)


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", is_eager=True, callback=_print_version, help="Print the version and exit.")
    ] = False,
) -> None:
    """Energy-recycling rimless wheel: simulate it, run the robot, analyse Vicon trials."""


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


def command_tree() -> click.Command:
    """The click command of the whole `rimless` app (as the console script builds it)."""
    return typer.main.get_command(app)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `rimless` console script."""
    from rimless.cli_rules import commit_result, committed_result

    try:
        app(args=argv, prog_name="rimless")
    except KeyboardInterrupt:
        code = committed_result()
        if code is not None:  # it came after the result was complete: not an interrupt of the command
            raise SystemExit(code) from None
        typer.echo("interrupted", err=True)
        _leave_interrupted()
    except SystemExit as done:
        if done.code == EXIT_INTERRUPTED:
            _leave_interrupted()
        commit_result(EXIT_OK if done.code is None else done.code if isinstance(done.code, int) else EXIT_FAILURE)
        raise


def _leave_interrupted() -> None:
    """Exit 130 at once after a Ctrl-C: the command has already cleaned up after itself (partial output removed,
    Dask clusters closed) and printed `interrupted`; the interpreter's own teardown (unloading the compiled
    kernels, joining library threads) would add seconds under load."""
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(EXIT_INTERRUPTED)
