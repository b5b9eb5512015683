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
- a bad number says what was expected (`--duration-s must be >= 0.0, got '-1'`), and NaN is no value of an
  option with bounds;
- plain text for a terminal breaks only between words (`echo_text`), never inside a number or a path; piped
  output keeps each line whole;
- `--help` shows upper-case metavars (`FLOAT`, `PATH`, `[er|ve]`), none on flags, and prints help text
  literally (square brackets are not rich markup).

The same words and labels with the robot's typer 0.28 (click types convert and name the values) and the
PC's 0.29 (pydantic converts, the parameter names its type): each rule acts where both versions look
(a parameter's `process_value`, `metavar`, `get_usage_pieces`); only the type's own name is read where each
version keeps it (`_typer_type_label`), and an argument's type column is set where each version reads it.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import json
import math
import re
import shutil
import sys
import textwrap
from collections.abc import Callable, Iterator
from typing import Any, NoReturn, TypeVar

import typer

# typer's own copy of click (typer 0.28 and 0.29 vendor it as the private `typer._click`): this is the one place
# that imports it; the pin typer>=0.28,<0.30 in pyproject.toml bounds the private API to the versions tested here
# (0.28 on the robot, 0.29 on the PC; .ci/wheel-check runs the rules on the robot's install).
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


def wrap_words(text: str, width: int) -> list[str]:
    """The lines of ``text`` folded to ``width`` columns between words only (a number, a path or any other
    word longer than the line stays whole); a folded line continues two spaces deeper than its own indent."""
    out: list[str] = []
    for line in text.splitlines() or [""]:
        indent = line[: len(line) - len(line.lstrip(" "))]
        out.extend(
            textwrap.wrap(
                line,
                width=max(width, 20),
                subsequent_indent=indent + "  ",
                break_long_words=False,
                break_on_hyphens=False,
                drop_whitespace=True,
            )
            or [line]
        )
    return out


def echo_text(text: str, *, err: bool = False) -> None:
    """Print ``text``: folded between words to the terminal's width when the stream is a terminal (the terminal
    would otherwise cut a number in two), unchanged when piped or redirected (one result a line, for grep)."""
    stream = sys.stderr if err else sys.stdout
    if not getattr(stream, "isatty", lambda: False)():
        typer.echo(text, err=err)
        return
    width = shutil.get_terminal_size((80, 24)).columns - 1
    typer.echo("\n".join(wrap_words(text, width)), err=err)


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
    """The offending value and the rule it broke, from the validation error typer 0.29 wraps (if any): the
    choices of an enum (typer 0.28's click words it as `'x' is not one of ...`, read in `usage_message`).
    Numbers are worded before typer sees them fail (`_number_problem`)."""
    cause = err.__cause__
    errors = getattr(cause, "errors", None)
    if not callable(errors):
        return None
    try:
        first = errors()[0]
    except Exception:  # noqa: BLE001 - any shape we do not know falls back to click's text
        return None
    kind, value, bounds = first.get("type", ""), first.get("input"), first.get("ctx") or {}
    if kind == "enum" and "expected" in bounds:
        choices = str(bounds["expected"]).replace("'", "").replace(" or ", ", ")
        return f"must be one of {choices}, got {value!r}"
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
    ctx = click.Context(command)  # what typer needs to name a type (a choice's spelling), outside a run
    for param in command.params:
        if getattr(param, "help", None):
            param.help = escape(param.help)  # type: ignore[attr-defined]
        _adapt_param(param, ctx)
    command.get_help_option = functools.partial(_help_option_without_metavar, command.get_help_option)  # type: ignore[method-assign]
    if not hasattr(command, "commands"):
        original = command.make_parser
        command.make_parser = functools.partial(_parser_reading_negative_numbers, original)  # type: ignore[method-assign]


def _help_option_without_metavar(get_help_option: Callable[[Any], Any], ctx: click.Context) -> Any:
    option = get_help_option(ctx)
    if option is not None and option.metavar is None:
        option.metavar = ""  # a flag: nothing in the type column
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


# ------------------------------------------------------------------------------- parameters: numbers and help


def _adapt_param(param: click.Parameter, ctx: click.Context) -> None:
    """Numbers worded by the rules, upper-case metavars: the same with typer 0.28 and 0.29."""
    flag = bool(getattr(param, "is_flag", False) or getattr(param, "count", False))
    label = None if flag else _type_label(param, ctx)
    if label is not None and label.removesuffix("...") in _NUMBER_WORDS:
        whole = label.startswith("INTEGER")
        param.process_value = functools.partial(_process_number, param.process_value, param, whole)  # type: ignore[method-assign]
    if param.metavar is not None:
        return
    if flag:
        param.metavar = ""  # nothing in the type column (typer 0.28 and 0.29 both show an option's metavar)
        return
    choices = label[1:-1].split("|") if label and label.startswith("[") else []
    if label and choices and len(label) > _MAX_CHOICE_METAVAR:
        # a long list of choices would be folded mid-word in the metavar column: name them in the help
        param.help = f"{param.help or ''} One of: {', '.join(choices)}.".strip()  # type: ignore[attr-defined]
        label = "CHOICE"
    if getattr(param, "param_type_name", "") != "argument":
        param.metavar = label  # the one label both versions' help shows for an option, before its type's own
        return
    name = (param.name or "value").upper()
    param.metavar = name
    if label:
        _show_argument_type(param, label)

    def usage_pieces(ctx: click.Context) -> list[str]:
        text = name + ("..." if param.nargs != 1 else "")
        return [text if param.required else f"[{text}]"]

    param.get_usage_pieces = usage_pieces  # type: ignore[method-assign]


_MAX_CHOICE_METAVAR = 24

# the labels of numbers, and the noun a bad value is told it is not
_NUMBER_WORDS = {"FLOAT": "a number", "INTEGER": "a whole number"}

_TYPE_METAVARS = {
    "float": "FLOAT",
    "int": "INTEGER",
    "str": "TEXT",
    "text": "TEXT",
    "bool": "BOOLEAN",
    "path": "PATH",
    "file": "FILE",
    "filename": "FILE",
    "directory": "DIRECTORY",
    "float range": "FLOAT",
    "int range": "INTEGER",
}


def _typer_type_label(param: click.Parameter, ctx: click.Context) -> str | None:
    """The type as the installed typer names it (`<float range>`, `<er|ve>`, `<list[Path]>`), its metavar aside.

    Typer 0.29 describes the parameter itself (`display_type`); 0.28 leaves it to the parameter's click type
    (`get_metavar`, else its `name`), as click does.
    """
    describe = getattr(param, "display_type", None)
    if describe is not None:  # typer 0.29
        return describe(ctx)
    kind = getattr(param, "type", None)  # typer 0.28
    if kind is None:
        return None
    return kind.get_metavar(param, ctx) or f"<{kind.name}>"


def _type_label(param: click.Parameter, ctx: click.Context) -> str | None:
    """The upper-case label of the parameter's type in help: FLOAT, INTEGER, PATH, [er|ve], PATH... (several)."""
    shown = _typer_type_label(param, ctx)
    if not shown:
        return None
    label = shown.removesuffix("...")
    if label[:1] + label[-1:] in ("<>", "[]", "{}"):
        label = label[1:-1]
    several = shown.endswith("...") or param.nargs != 1 or bool(getattr(param, "multiple", False))
    if label.startswith("list[") and label.endswith("]"):
        label, several = label[5:-1], True
    if "|" in label:
        label = f"[{label}]"
    else:
        label = _TYPE_METAVARS.get(label.lower(), label.upper())
    return label + ("..." if several else "")


def _show_argument_type(param: click.Parameter, label: str) -> None:
    """Show `label` in an argument's type column, which is not its metavar (that is its name there): typer 0.29
    asks the parameter (`display_type_rich`), 0.28 the parameter's click type (`get_metavar`)."""
    if hasattr(param, "display_type_rich"):  # typer 0.29
        param.display_type_rich = lambda ctx: label
        return
    kind = getattr(param, "type", None)  # typer 0.28: a copy, as click shares one instance per type (STRING)
    if kind is not None:
        kind = copy.copy(kind)
        kind.get_metavar = lambda param, ctx: label
        param.type = kind  # type: ignore[attr-defined]  # typer 0.29's parameter has none


def _bounds(param: click.Parameter) -> tuple[Any, Any]:
    """The inclusive bounds typer was given (`min=`, `max=`): typer 0.29 keeps them on the parameter, 0.28 on its
    click range type."""
    holder = param if hasattr(param, "min") else getattr(param, "type", None)
    return getattr(holder, "min", None), getattr(holder, "max", None)


def _number_problem(text: Any, whole: bool, low: Any, high: Any) -> str | None:
    """What is wrong with `text` as a value of a number option (inclusive bounds, None for none), or None.

    NaN is within no bounds; None (no value) is no problem here."""
    if text is None:
        return None
    try:
        number = int(_whole_number_text(text)) if whole else float(text)
    except (TypeError, ValueError):
        return f"must be {_NUMBER_WORDS['INTEGER' if whole else 'FLOAT']}, got {text!r}"
    if (low is None or number >= low) and (high is None or number <= high):
        return None
    if low is not None and high is not None:
        return f"must be between {low:g} and {high:g}, got {text!r}"
    return f"must be >= {low}, got {text!r}" if low is not None else f"must be <= {high}, got {text!r}"


# a whole number written with a zero fraction, `5.0`: typer 0.29 (pydantic) reads it as 5, 0.28 (click) did not
_ZERO_FRACTION = re.compile(r"\s*([-+]?[\d_]+)\.0+\s*")


def _whole_number_text(text: Any) -> Any:
    """`5.0` -> `5`, as pydantic reads it; anything else as it is."""
    match = _ZERO_FRACTION.fullmatch(text) if isinstance(text, str) else None
    return match.group(1) if match else text


def _process_number(
    process_value: Callable[[click.Context, Any], Any],
    param: Any,  # the installed typer's parameter class (the one BadParameter takes)
    whole: bool,
    ctx: click.Context,
    value: Any,
) -> Any:
    """The parameter's own conversion (click's types in typer 0.28, pydantic in 0.29), its failure worded by the
    rules; a NaN that typer 0.28 let through bounds (0.29 does not) fails the same way."""
    items = value if isinstance(value, (list, tuple)) else [value]
    if whole:  # the same whole numbers with either typer
        value = (
            type(value)(map(_whole_number_text, value))
            if isinstance(value, (list, tuple))
            else _whole_number_text(value)
        )
    low, high = _bounds(param)
    try:
        result = process_value(ctx, value)
    except click.exceptions.MissingParameter:
        raise
    except click.exceptions.BadParameter as err:
        problem = next((p for p in (_number_problem(v, whole, low, high) for v in items) if p), None)
        if problem is None:
            raise
        raise click.exceptions.BadParameter(problem, ctx=ctx, param=param) from err
    if low is not None or high is not None:
        for item, number in zip(items, result if isinstance(result, (list, tuple)) else [result]):
            if isinstance(number, float) and math.isnan(number):
                raise click.exceptions.BadParameter(_number_problem(item, whole, low, high) or "", ctx=ctx, param=param)
    return result
