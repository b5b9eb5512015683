"""The rules every `rimless` command follows, apart from the app itself (rimless.cli), so that the parts'
command modules can import them without importing the whole command tree.

- a usage mistake (bad choice, non-number, missing or unknown option) prints one line `error: ...` naming
  the option and exits 2; so does a `UserError` raised by a command, or an `OSError` naming a file;
- a `RunFailure` (valid input, no result) prints one line and exits 1;
- Ctrl-C (KeyboardInterrupt, also when numba wraps it in a SystemError) prints `interrupted` and exits 130;
  once the command's result (or its `error:` line) is complete it is committed (`commit_result`): a Ctrl-C
  after that no longer interrupts it (the `rimless` entry point then ignores SIGINT for the interpreter's
  teardown, rimless.__main__);
- a negative number is read as a value, not as an option (`robot set touch_velocity_m_s -3`);
- `--help` shows upper-case metavars (`FLOAT`, `PATH`, `[er|ve]`), none on flags, and prints help text
  literally (square brackets are not rich markup).
"""

from __future__ import annotations

import contextlib
import functools
import json
import re
from collections.abc import Callable, Iterator
from typing import Any, NoReturn, TypeVar

import typer

# typer's own copy of click (typer >= 0.29 vendors it as the private `typer._click`): this is the one place that
# imports it; the pin typer<0.30 in pyproject.toml bounds the private API to the version tested here.
from typer import _click as click
from typer.core import TyperGroup

from rimless.errors import RunFailure, UserError, interrupted_by_user

F = TypeVar("F", bound=Callable[..., Any])

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130

# A token that is a number, not an option: -3, -0.5, -.5, -1e-3, -inf is not a number here.
_NEGATIVE_NUMBER = re.compile(r"-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def user_facing(func: F) -> F:
    """Turn a `UserError` raised by a command into one line and exit 2, a `RunFailure` into exit 1.

    The root group does the same for every command; the decorator keeps a command correct when it is
    invoked on its own (a sub-app in a test).
    """

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with _rules():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def fail(message: str) -> NoReturn:
    """Stop a command whose input was valid but which has no result: one line on stderr, exit 1."""
    raise RunFailure(message)


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


# ------------------------------------------------------------------------------------------ the end of a run

_committed: list[int] = []  # the exit code of the run whose result is complete (empty while it runs)
_after_result: list[Callable[[int], None]] = []  # what the entry point does then (rimless.__main__)


def commit_result(code: int) -> None:
    """Record that the run's result is complete (printed, outputs renamed into place), to exit with `code`:
    from here a Ctrl-C is not an interrupt of the command. Calls the hooks of `after_result` once."""
    if _committed:
        return
    _committed.append(code)
    for hook in _after_result:
        hook(code)


def committed_result() -> int | None:
    """The exit code of the committed result, or None while the command still runs."""
    return _committed[0] if _committed else None


def after_result(hook: Callable[[int], None]) -> None:
    """Call `hook(code)` when the result is committed (the entry point installs its SIGINT policy here)."""
    _after_result.append(hook)


def start_run() -> None:
    """A new run in this process (the root group parses its command line): nothing committed yet."""
    _committed.clear()


# ------------------------------------------------------------------------------------------ the rules


def _error(message: str, code: int) -> NoReturn:
    typer.echo(f"error: {_one_line(message)}", err=True)
    commit_result(code)  # the error line is the run's result
    raise typer.Exit(code)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


@contextlib.contextmanager
def _rules() -> Iterator[None]:
    """Map what a command raises onto the CLI's exit codes and one-line messages."""
    try:
        yield
    except (typer.Exit, click.exceptions.NoArgsIsHelpError):
        raise
    except click.exceptions.ClickException as err:
        _error(usage_message(err), EXIT_USER_ERROR)
    except typer.Abort:
        typer.echo("interrupted", err=True)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    except UserError as err:
        _error(str(err), EXIT_USER_ERROR)
    except RunFailure as err:
        _error(str(err), EXIT_FAILURE)
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    except SystemError as err:
        if interrupted_by_user(err):
            typer.echo("interrupted", err=True)
            raise typer.Exit(EXIT_INTERRUPTED) from None
        raise
    except OSError as err:
        if err.filename is None:
            raise
        where = err.filename if err.filename2 is None else f"{err.filename} -> {err.filename2}"
        _error(f"{where}: {err.strerror or err}", EXIT_USER_ERROR)


def _param_name(err: click.exceptions.ClickException) -> str | None:
    param = getattr(err, "param", None)
    if param is None:
        return None
    if getattr(param, "param_type_name", "") == "argument":
        return (param.metavar or param.name or "").upper() or None
    longs = [o for o in param.opts if o.startswith("--")]
    return (longs or param.opts or [param.name])[0]


def _pydantic_detail(err: click.exceptions.BadParameter) -> str | None:
    """The offending value and the rule it broke, from the validation error typer wraps (if any)."""
    cause = err.__cause__
    errors = getattr(cause, "errors", None)
    if not callable(errors):
        return None
    try:
        first = errors()[0]
    except Exception:  # noqa: BLE001 - any shape we do not know falls back to click's text
        return None
    kind, value, bounds = first.get("type", ""), first.get("input"), first.get("ctx") or {}
    got = f"got {value!r}"
    if kind in ("float_parsing", "float_type"):
        return f"must be a number, {got}"
    if kind in ("int_parsing", "int_type", "int_from_float"):
        return f"must be a whole number, {got}"
    if kind.startswith(("greater", "less")):
        low, high = getattr(err.param, "min", None), getattr(err.param, "max", None)
        if low is not None and high is not None:
            return f"must be between {low:g} and {high:g}, {got}"
        for key, word in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
            if key in bounds:
                return f"must be {word} {bounds[key]}, {got}"
    if kind == "enum" and "expected" in bounds:
        choices = str(bounds["expected"]).replace("'", "").replace(" or ", ", ")
        return f"must be one of {choices}, {got}"
    return None


def usage_message(err: click.exceptions.ClickException) -> str:
    """One line for a usage error, naming the option or argument; no box, no `Usage:` block."""
    name = _param_name(err)
    ctx = getattr(err, "ctx", None)
    see = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    if isinstance(err, click.exceptions.MissingParameter):
        kind = "argument" if getattr(err.param, "param_type_name", "") == "argument" else "option"
        return f"missing {kind} {name}{see}"
    if isinstance(err, click.exceptions.BadParameter) and name:
        detail = _pydantic_detail(err)
        if detail is None:
            detail = err.message.replace("Value error, ", "").strip().rstrip(".")
            choice = re.fullmatch(r"(.+) is not one of (.+)", detail)
            if choice:
                detail = f"must be one of {choice.group(2).replace(chr(39), '')}, got {choice.group(1)}"
            detail = detail[:1].lower() + detail[1:]
        return f"{name} {detail}" if detail.startswith("must ") else f"{name}: {detail}"
    text = err.format_message().strip().rstrip(".").replace("(Possible options:", "(did you mean")
    text = re.sub(r"\(did you mean ([^)]*)\)", r"(did you mean \1?)", text)
    text = text[:1].lower() + text[1:]
    return f"{text}{see}"


# ------------------------------------------------------------------------------- the root group


class RimlessGroup(TyperGroup):
    """The root command group: applies the rules above to every command below it."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        for command in walk_commands(self):
            _adapt_command(command)

    def make_context(self, info_name: str | None, args: list[str], parent: Any = None, **extra: Any) -> Any:
        if parent is None:
            start_run()
        with _rules():
            return super().make_context(info_name, args, parent=parent, **extra)

    def invoke(self, ctx: click.Context) -> Any:
        with _rules():
            result = super().invoke(ctx)
        if ctx.parent is None:  # the command returned: its result is complete
            commit_result(EXIT_OK)
        return result


def walk_commands(root: click.Command) -> Iterator[click.Command]:
    """Every command of the tree under `root`, `root` included (depth first, sorted by name)."""
    yield root
    for name in sorted(getattr(root, "commands", {}) or {}):
        yield from walk_commands(root.commands[name])  # type: ignore[attr-defined]


def _adapt_command(command: click.Command) -> None:
    from rich.markup import escape

    if command.help:
        command.help = escape(command.help)
    if command.short_help:
        command.short_help = escape(command.short_help)
    for param in command.params:
        if getattr(param, "help", None):
            param.help = escape(param.help)  # type: ignore[attr-defined]
        _adapt_metavar(param)
    command.get_help_option = functools.partial(_help_option_without_metavar, command.get_help_option)  # type: ignore[method-assign]
    if not hasattr(command, "commands"):
        original = command.make_parser
        command.make_parser = functools.partial(_parser_reading_negative_numbers, original)  # type: ignore[method-assign]


def _help_option_without_metavar(get_help_option: Callable[[Any], Any], ctx: click.Context) -> Any:
    option = get_help_option(ctx)
    if option is not None:
        _adapt_metavar(option)
    return option


def _parser_reading_negative_numbers(make_parser: Callable[[Any], Any], ctx: click.Context) -> Any:
    """The command's parser, with `-3` or `-0.5` read as a value where no option has that name."""
    parser = make_parser(ctx)
    process_opts = parser._process_opts

    def _process_opts(arg: str, state: Any) -> None:
        if _NEGATIVE_NUMBER.fullmatch(arg) and arg not in parser._short_opt and arg not in parser._long_opt:
            state.largs.append(arg)
            return
        process_opts(arg, state)

    parser._process_opts = _process_opts
    return parser


_TYPE_METAVARS = {
    "float": "FLOAT",
    "int": "INTEGER",
    "str": "TEXT",
    "bool": "BOOLEAN",
    "path": "PATH",
    "file": "FILE",
    "directory": "DIRECTORY",
    "float range": "FLOAT",
    "int range": "INTEGER",
}


def _adapt_metavar(param: click.Parameter) -> None:
    """Upper-case metavars in help: FLOAT, PATH, [er|ve], NAME; nothing after a flag."""
    if param.metavar is not None:
        return
    if getattr(param, "is_flag", False) or getattr(param, "count", False):
        param.display_type_rich = lambda ctx: None  # type: ignore[attr-defined]
        return
    original = getattr(param, "display_type_rich", None)
    choices = _choices(param)
    if choices and len("|".join(choices)) + 2 > _MAX_CHOICE_METAVAR:
        # a long list of choices would be folded mid-word in the metavar column: name them in the help
        param.help = f"{param.help or ''} One of: {', '.join(choices)}.".strip()  # type: ignore[attr-defined]
        param.display_type_rich = lambda ctx: "CHOICE"  # type: ignore[attr-defined]
    elif original is not None:
        param.display_type_rich = functools.partial(_metavar_of, original)  # type: ignore[attr-defined]
    if getattr(param, "param_type_name", "") == "argument":
        name = (param.name or "value").upper()
        param.metavar = name

        def usage_name() -> str:
            text = name + ("..." if param.nargs != 1 else "")
            return text if param.required else f"[{text}]"

        param._usage_display_name = usage_name  # type: ignore[attr-defined]


_MAX_CHOICE_METAVAR = 24


def _choices(param: click.Parameter) -> list[str]:
    desc = getattr(param, "type_descriptor", None)
    if desc is None or not desc.is_choice or not desc.choices:
        return []
    return [str(getattr(c, "value", c)) for c in desc.choices]


def _metavar_of(original: Callable[..., str | None], ctx: click.Context) -> str | None:
    shown = original(ctx=ctx)
    if shown is None:
        return None
    dots = shown.endswith("...")
    label = shown.removesuffix("...").strip("<>")
    if label.startswith("list[") and label.endswith("]"):
        label, dots = label[5:-1], True
    if "|" in label:
        label = f"[{label}]"
    else:
        label = _TYPE_METAVARS.get(label, label.upper())
    return label + ("..." if dots else "")
