"""Every command of the `rimless` tree, found by walking it, held to the CLI's rules.

For every command and sub-command: `--help` (exit 0, fits 80 columns, proper metavars, every option
explained); for every option taking a number or a choice, a bad value (exit 2, one line `error: ...` naming
the option); an unknown option and missing required ones (exit 2, one line); for every file or folder
parameter, a missing input or an unwritable output (exit 2, one line naming the path); and for every command
that can run long, a SIGINT to the running process (exit 130, last line `interrupted`, no traceback, no
half-written output left behind).

The tree is enumerated when the tests are collected, so commands added later are checked too. A new leaf
command must be put either in LONG_RUNS (arguments that keep it busy long enough to be interrupted) or in
QUICK (with the reason it cannot run long); the test says so when it is in neither.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, get_args

import pytest
from typer.testing import CliRunner

from rimless.cli import app, command_tree
from tests.support.cli_lines import stderr_lines
from tests.support.interrupt import STAGE_TIMEOUT_S, NotReached, Watched

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "analysis" / "data"
BUNDLED_CSVS = sorted(str(p) for p in DATA.glob("SYNTHETIC_*.csv"))
CRITICAL_CSVS = sorted(str(p) for p in (DATA / "critical").glob("SYNTHETIC_*.csv"))
WIDTH = 80

TREE = command_tree()


def _walk(cmd: Any, path: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], Any]]:
    out = [(path, cmd)]
    for name in sorted(getattr(cmd, "commands", {}) or {}):
        out.extend(_walk(cmd.commands[name], (*path, name)))
    return out


ALL = _walk(TREE)
LEAVES = [(p, c) for p, c in ALL if not hasattr(c, "commands")]


def _name(path: tuple[str, ...]) -> str:
    return " ".join(path) or "rimless"


def kind(param: Any) -> str:
    """flag, number, choice, path or text: what kind of value the parameter takes."""
    if getattr(param, "is_flag", False) or getattr(param, "count", False):
        return "flag"
    desc = param.type_descriptor
    inner = get_args(desc.annotation)[0] if desc.is_list and get_args(desc.annotation) else desc.annotation
    if desc.is_choice:
        return "choice"
    if desc.is_path or inner is Path:
        return "path"
    if inner in (int, float):
        return "number"
    return "text"


def flag(param: Any) -> str:
    longs = [o for o in param.opts if o.startswith("--")]
    return (longs or param.opts)[0]


# Outputs (files or folders the command writes) are recognised by name.
OUTPUT_PARAMS = {"out", "plot", "cache_dir", "csv"}

# ------------------------------------------------------------------------------------------ help


def _invoke(args: list[str]) -> Any:
    return CliRunner().invoke(app, args, env={"COLUMNS": str(WIDTH), "TERM": "dumb"}, prog_name="rimless")


@pytest.mark.parametrize("path", [p for p, _ in ALL], ids=[_name(p) for p, _ in ALL])
def test_help(path: tuple[str, ...]) -> None:
    res = _invoke([*path, "--help"])
    out = res.output
    assert res.exit_code == 0, out
    assert f"Usage: rimless {' '.join(path)}".rstrip() in out
    assert "Traceback" not in out
    too_wide = [line for line in out.splitlines() if len(line) > WIDTH]
    assert not too_wide, f"help lines wider than {WIDTH} columns: {too_wide}"
    assert not re.search(r"<(bool|float|int|str|path|text|list)[^>]*>|\{[A-Z_]+\.\.\.\}", out), (
        f"typer's raw metavars in help:\n{out}"
    )


@pytest.mark.parametrize("path", [p for p, _ in LEAVES], ids=[_name(p) for p, _ in LEAVES])
def test_every_parameter_is_explained(path: tuple[str, ...]) -> None:
    cmd = dict(ALL)[path]
    assert (cmd.help or "").strip(), f"{_name(path)} has no help text"
    silent = [p.name for p in cmd.params if not (getattr(p, "help", None) or "").strip()]
    assert not silent, f"{_name(path)}: parameters without help: {silent}"


# Commands without --json, each with its reason.
NO_JSON: dict[tuple[str, ...], str] = {
    ("robot", "run"): "the firmware itself: it logs to stderr while it runs, its results are the telemetry",
    ("robot", "listen"): "records telemetry to --out and shows a live summary; the records are JSON Lines",
    ("robot", "heartbeat"): "keeps the link alive; it prints a line only when the robot's state changes",
}
# Known violations (strict=False xfails; the lead deletes an entry when it turns into XPASS).
KNOWN_NO_JSON: dict[tuple[str, ...], str] = {}


@pytest.mark.parametrize("path", [p for p, _ in LEAVES], ids=[_name(p) for p, _ in LEAVES])
def test_every_command_that_prints_results_has_json(path: tuple[str, ...], request: pytest.FixtureRequest) -> None:
    if path in NO_JSON:
        pytest.skip(f"no --json: {NO_JSON[path]}")
    if path in KNOWN_NO_JSON:
        request.applymarker(pytest.mark.xfail(reason=f"known: {KNOWN_NO_JSON[path]}", strict=False))
    cmd = dict(ALL)[path]
    assert any("--json" in p.opts for p in cmd.params), f"`rimless {_name(path)}` has no --json"


def test_flags_show_no_metavar_and_values_show_theirs() -> None:
    out = _invoke(["sim", "gait", "--help"]).output
    json_line = next(line for line in out.splitlines() if "--json " in line)
    assert "BOOL" not in json_line.upper().split("--JSON", 1)[1].split("PRINT")[0]
    assert re.search(r"--steps\s+INTEGER", out) and re.search(r"--model\s+\[er\|ve\]", out)
    usage = _invoke(["robot", "set", "--help"]).output
    assert "rimless robot set [OPTIONS] NAME VALUE" in usage


# ------------------------------------------------------------------------------------------ bad values


def _one_error_line(
    stderr: str, code: int, returncode: int, names: list[str], out: str, cwd: Path | None = None
) -> None:
    assert returncode == code, f"exit {returncode}, expected {code}:\n{out}"
    lines = stderr_lines(stderr)
    assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}:\n{stderr}"
    assert lines[0].startswith("error: "), lines[0]
    for name in names:  # a path may be shown relative to the working folder (as the trials commands do)
        shown = [name] + ([os.path.relpath(name, cwd)] if cwd is not None and os.path.isabs(name) else [])
        assert any(n in lines[0] for n in shown), f"the message does not name {name}: {lines[0]}"
    assert "Traceback" not in out


BAD_VALUE_CASES = [
    (path, flag(p), "abc" if kind(p) == "number" else "xx")
    for path, cmd in LEAVES
    for p in cmd.params
    if p.param_type_name == "option" and kind(p) in ("number", "choice")
]


@pytest.mark.parametrize(
    ("path", "option", "bad"), BAD_VALUE_CASES, ids=[f"{_name(p)} {o} {b}" for p, o, b in BAD_VALUE_CASES]
)
def test_bad_value_is_one_line_naming_the_option(path: tuple[str, ...], option: str, bad: str) -> None:
    res = _invoke([*path, option, bad])
    _one_error_line(res.stderr, 2, res.exit_code, [option, repr(bad)], res.output)


@pytest.mark.parametrize("path", [p for p, _ in LEAVES], ids=[_name(p) for p, _ in LEAVES])
def test_unknown_option_is_one_line(path: tuple[str, ...]) -> None:
    res = _invoke([*path, "--no-such-option", "1"])
    _one_error_line(res.stderr, 2, res.exit_code, ["--no-such-option"], res.output)


REQUIRED = [(p, c) for p, c in LEAVES if any(x.required for x in c.params)]


@pytest.mark.parametrize("path", [p for p, _ in REQUIRED], ids=[_name(p) for p, _ in REQUIRED])
def test_missing_required_parameter_is_one_line(path: tuple[str, ...]) -> None:
    cmd = dict(ALL)[path]
    first = next(x for x in cmd.params if x.required)
    name = flag(first) if first.param_type_name == "option" else (first.name or "").upper()
    res = _invoke(list(path))
    _one_error_line(res.stderr, 2, res.exit_code, ["missing", name], res.output)


def test_negative_numbers_are_values_not_options() -> None:
    """`robot set NAME -3` parses (and fails later only because no robot listens there)."""
    res = _invoke(["robot", "set", "touch_velocity_m_s", "-3", "--host", "127.0.0.1", "--port", "9", "--token", "t"])
    assert "no such option" not in res.output.lower()
    assert res.exit_code == 2 and "127.0.0.1" in res.stderr, res.output
    res = _invoke(["robot", "set", "touch_velocity_m_s", "-1e-3x", "--host", "h"])
    assert res.exit_code == 2 and "no such option: -1" in res.stderr


def test_version() -> None:
    from rimless import __version__

    res = _invoke(["--version"])
    assert res.exit_code == 0 and res.output.strip() == f"rimless {__version__}"


# ------------------------------------------------------------------------------------------ files


def _run(args: list[str], cwd: Path, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "COLUMNS": str(WIDTH)}
    try:
        return subprocess.run(
            [sys.executable, "-m", "rimless", *args],
            cwd=cwd,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"`rimless {' '.join(args)}` hung for {timeout} s")


def _placeholders(cmd: Any, skip: str, tmp: Path) -> list[str]:
    """Values for the required parameters other than `skip`, so the command reaches the one under test."""
    args: list[str] = []
    for p in cmd.params:
        if not p.required or p.name == skip:
            continue
        k = kind(p)
        if p.param_type_name == "argument":
            value = BUNDLED_CSVS[0] if k == "path" else ("1" if k == "number" else "x")
            args.append(value)
        else:
            value = str(tmp / "placeholder-out") if k == "path" else ("1" if k == "number" else "127.0.0.1")
            args.extend([flag(p), value])
    return args


FILE_CASES = [(path, p.name, p.name in OUTPUT_PARAMS) for path, cmd in LEAVES for p in cmd.params if kind(p) == "path"]
SUFFIX = {"params_file": ".toml", "config": ".toml", "trial": ".parquet", "plot": ".png"}

# Known violations in commands owned by the parts, as (reason, run): strict=False, so the lead sees an
# XPASS once a part fixes its command, and deletes the entry. `run=False` where the violation costs minutes.
KNOWN_FILE_VIOLATIONS: dict[tuple[tuple[str, ...], str], tuple[str, bool]] = {}


@pytest.mark.parametrize(
    ("path", "param", "is_output"),
    FILE_CASES,
    ids=[f"{_name(p)} {n}{' (output)' if o else ''}" for p, n, o in FILE_CASES],
)
def test_missing_input_or_unwritable_output_is_one_line(
    path: tuple[str, ...], param: str, is_output: bool, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    if (path, param) in KNOWN_FILE_VIOLATIONS:
        reason, run = KNOWN_FILE_VIOLATIONS[(path, param)]
        request.applymarker(pytest.mark.xfail(reason=f"known: {reason}", strict=False, run=run))
        if not run:
            pytest.xfail(f"known, not run: {reason}")
    cmd = dict(ALL)[path]
    p = next(x for x in cmd.params if x.name == param)
    suffix = SUFFIX.get(param, ".csv")
    if is_output:
        target = f"/proc/rimless-nope/out{suffix}"  # /proc refuses new entries, even to root
        named = "/proc/rimless-nope"
    else:
        target = str(tmp_path / "no-such-folder" / f"missing{suffix}")
        named = target
    given = [target] if p.param_type_name == "argument" else [flag(p), target]
    extra = ["--duration-s", "3"] if path == ("robot", "listen") else []
    if path == ("robot", "run") and param == "pin_log":
        extra = ["--fake"]  # the pin log records the fake's pins; without --fake it is refused as such
    placeholders = _placeholders(cmd, param, tmp_path)
    if path == ("robot", "set"):  # a valid KEY VALUE, so the command reaches the file
        placeholders = ["touch_velocity_m_s", "-0.01", *placeholders[2:]]
    res = _run([*path, *given, *placeholders, *extra], cwd=tmp_path)
    _one_error_line(res.stderr, 2, res.returncode, [named], res.stdout + res.stderr, cwd=tmp_path)


# ------------------------------------------------------------------------------------------ Ctrl-C


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# replaced by the address of a UDP socket of the test, which waits for the command's first datagram there
TELEMETRY_TO_TEST = "<the test's UDP socket>"

# Arguments that keep each long-running command busy, and the event on which the test sends SIGINT: a stage the
# command reaches inside its work (`rimless.progress.stage`: the bar or the text beside it it shows, or a stage
# named in the library, reported through RIMLESS_TEST_STAGE_FILE), or a line it prints on stderr (the firmware's
# commands, whose code reports no stage). Never a delay: the machine's speed does not matter.
LONG_RUNS: dict[tuple[str, ...], tuple[list[str], dict[str, str]]] = {
    ("bench",): (["--plot", "wp.png"], {"stage": "benchmark"}),
    # the calibration of c runs in a second process beside the comparisons (on one core: after them, here)
    ("demo",): (["--out", "demo-out"], {"stage": "calibration started"}),
    ("sim", "critical-slope"): (["--model", "er", "--backend", "reference"], {"stage": "continuation in slope"}),
    ("sim", "fixed-point"): (["--backend", "reference", "--rtol", "1e-13"], {"stage": "period-1 gait"}),  # 8.4 s
    ("sim", "gait"): (["--steps", "10000", "--out", "traj.parquet", "--plot", "gait.png"], {"stage": "simulating"}),
    ("sim", "gaits"): (["--guesses", "200", "--backend", "reference"], {"stage": "scanning guesses"}),
    ("sim", "firmware-sweep"): (
        ["--rates-hz", "300,1000", "--delays-ms", "0,5,10", "--scheduler", "sync"],
        {"stage": "firmware sweep"},
    ),
    ("sim", "stress"): (
        ["--k-values", ",".join(str(300 + 10 * i) for i in range(200))],
        {"stage": "stress sweep"},
    ),
    ("sim", "basin"): (["--grid", "100", "--out", "basin-out"], {"stage": "basin of attraction"}),
    ("sim", "mfpt"): (["--terrain-sd-deg", "3"], {"stage": "MFPT (mesh)"}),
    # "comparing": the six trials, the critical slope and the held parameters' sensitivities follow (8-26 s)
    ("trials", "report"): ([*BUNDLED_CSVS, "--out", "report-out"], {"stage": "comparing"}),
    ("trials", "bench-import"): (["--rows", "5000000"], {"stderr": "writing a 5,000,000-row Tracker export"}),
    # the first telemetry datagram: the firmware's loop runs and sends (its "running" line, printed from the loop,
    # is an event too: tests/firmware/test_cli_signals.py)
    ("robot", "run"): (
        ["--fake", "--arm", "--stance-leg", "0", "--telemetry", TELEMETRY_TO_TEST],
        {"datagram": "telemetry"},
    ),
    # its first "waiting for telemetry" line comes after --summary-every-s (1 s): inside its receiving loop
    ("robot", "listen"): (["--port", str(_free_udp_port()), "--out", "tel.jsonl"], {"stderr": "waiting for telemetry"}),
    ("robot", "bench"): (["--fake", "--duration-s", "20"], {"stderr": "bench: "}),
    ("paper",): (["--out", "paper-out", "--scheduler", "sync", "--no-cache"], {"stage": "paper"}),
    ("sim", "sweep"): (
        ["--k", "1500:3500:50", "--model", "er,ve", "--scheduler", "sync", "--no-cache", "--out", "sweep-out/k"],
        {"stage": "sweep: "},
    ),
    ("trials", "calibrate"): ([*CRITICAL_CSVS], {"stage": "calibration started"}),
    # --calibrated: without it the command takes about 3 s once compiled; the interrupt lands in its calibration
    ("trials", "critical-slope"): (
        [*CRITICAL_CSVS, "--calibrated", "--model", "er,ve"],
        {"stage": "calibration started"},
    ),
    ("trials", "coverage"): (["--series", "500"], {"stage": "coverage"}),
    ("trials", "floquet-coverage"): (["--series", "500"], {"stage": "floquet coverage"}),
    ("trials", "slope-coverage"): (["--series", "500"], {"stage": "slope coverage"}),
    ("trials", "adequacy-coverage"): (["--series", "500"], {"stage": "adequacy coverage"}),
    # after the imports: the model's eigenvalue at each of the seven slopes with the held parameters' differences
    ("trials", "floquet"): ([*CRITICAL_CSVS], {"stage": "model at"}),
    ("trials", "leg-fit-coverage"): (["--tests", "1000"], {"stage": "leg-fit coverage"}),
    ("robot", "leg-test"): (
        ["--fake", "--leg", "0", "--fake-compression-mm", "0", "--timeout-s", "120", "--out", "leg.jsonl"],
        {"stderr": "leg test: compress leg 0"},
    ),
}

# Commands that finish quickly by design, so there is nothing to interrupt; each with its reason.
QUICK: dict[tuple[str, ...], str] = {
    ("sim", "sensitivity"): "one fixed point and a few hundred compiled steps: about 2 s of CPU once compiled",
    ("robot", "arm"): "one request to the robot, bounded by the command timeout",
    ("robot", "disarm"): "one request to the robot, bounded by the command timeout",
    ("robot", "set"): "one request to the robot, bounded by the command timeout",
    ("robot", "status"): "one request to the robot, bounded by the command timeout",
    ("robot", "trial-start"): "one request to the robot, bounded by the command timeout",
    ("robot", "trial-stop"): "one request to the robot, bounded by the command timeout",
    ("robot", "check"): "needs the hardware; with --fake it clicks 8 clutches in about 2.4 s, too short to "
    "aim a signal at reliably",
    ("trials", "show"): "reads one Parquet file (well under a second)",
    ("sim", "replay"): "reads one trial log and simulates one step (about a second)",
    ("trials", "import"): "parses a few files in about a second; the long import is `trials bench-import`",
    ("robot", "ping"): "one request to the robot, bounded by the command timeout",
    ("robot", "release"): "drives the clutch pins low once and exits",
    ("robot", "heartbeat"): "without a robot on the loopback it stops at once with one line; its Ctrl-C path "
    "needs a running robot",
    ("trials", "leg-fit"): "fits a few leg-test logs in a second or two",
}


def _free_tcp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


KNOWN_QUICK_RUN_VIOLATIONS: dict[tuple[str, ...], str] = {}


@pytest.mark.parametrize("path", sorted(QUICK), ids=[_name(p) for p in sorted(QUICK)])
def test_quick_command_run_as_is_ends_cleanly(
    path: tuple[str, ...], tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    """Run with only its required parameters (a robot on a closed local port, a bundled CSV as the file):
    success, or one line `error: ...` with exit 1 or 2; never a traceback or a hang."""
    if path in KNOWN_QUICK_RUN_VIOLATIONS:
        request.applymarker(pytest.mark.xfail(reason=f"known: {KNOWN_QUICK_RUN_VIOLATIONS[path]}", strict=False))
    cmd = dict(ALL)[path]
    args = [*path, *_placeholders(cmd, "", tmp_path)]
    if any("--port" in p.opts for p in cmd.params) and path[0] == "robot":
        args += (
            ["--port", str(_free_tcp_port()), "--token", "t"]
            if any("--token" in p.opts for p in cmd.params)
            else ["--port", str(_free_tcp_port())]
        )
    res = _run(args, cwd=tmp_path, timeout=120)
    out = res.stdout + res.stderr
    assert "Traceback" not in out, out[-3000:]
    assert res.returncode in (0, 1, 2), out[-3000:]
    if res.returncode:
        lines = stderr_lines(res.stderr)
        assert lines and lines[-1].startswith("error: "), out[-3000:]


# Known violations of the Ctrl-C rule in commands owned by the parts: strict=False so the lead sees them
# turn into XPASS once fixed, and then deletes the entry.
KNOWN_INTERRUPT_VIOLATIONS: dict[tuple[str, ...], str] = {}


# What an interrupted command may leave: a recording is complete up to the interrupt (every line is a whole
# JSON object), and Ctrl-C is how a recording ends.
ALLOWED_AFTER_INTERRUPT: dict[tuple[str, ...], set[str]] = {
    ("robot", "listen"): {"tel.jsonl"},
}


def _leftovers(folder: Path, before: set[str], allowed: set[str]) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in before | allowed)


# Interrupted in every run: one command per kind of machinery (the reference integrator, a synchronous Dask
# sweep with partial output, the demo with its second process and report, the firmware's asyncio loop, a
# telemetry recording, a least-squares calibration); the other long commands are marked `full` (CI runs them).
INTERRUPTED_IN_EVERY_RUN = {
    ("sim", "fixed-point"),
    ("sim", "sweep"),
    ("demo",),
    ("robot", "run"),
    ("robot", "listen"),
    ("trials", "calibrate"),
}


def _interrupt_case(path: tuple[str, ...]) -> Any:
    full = path in LONG_RUNS and path not in INTERRUPTED_IN_EVERY_RUN
    return pytest.param(path, id=_name(path), marks=[pytest.mark.full] if full else [])


@pytest.mark.parametrize("path", [_interrupt_case(p) for p, _ in LEAVES])
def test_interrupt_exits_130_and_leaves_no_partial_output(
    path: tuple[str, ...], tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    if path in QUICK:
        pytest.skip(f"not interrupted: {QUICK[path]}")
    assert path in LONG_RUNS, (
        f"`rimless {_name(path)}` is new: add it to LONG_RUNS (arguments that keep it "
        "busy) or to QUICK (with the reason it cannot run long) in this file"
    )
    if path in KNOWN_INTERRUPT_VIOLATIONS:
        request.applymarker(pytest.mark.xfail(reason=KNOWN_INTERRUPT_VIOLATIONS[path], strict=False))
    args, event = LONG_RUNS[path]
    before = {p.name for p in tmp_path.iterdir()}
    env = {**os.environ, "COLUMNS": str(WIDTH)}
    with contextlib.ExitStack() as stack:
        if "datagram" in event:
            import socket

            sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            sock.bind(("127.0.0.1", 0))
            args = [f"127.0.0.1:{sock.getsockname()[1]}" if a == TELEMETRY_TO_TEST else a for a in args]
        cmd = stack.enter_context(Watched([sys.executable, "-m", "rimless", *path, *args], cwd=tmp_path, env=env))
        try:
            if "datagram" in event:
                sock.settimeout(STAGE_TIMEOUT_S)
                try:
                    sock.recv(65536)
                except TimeoutError:
                    raise NotReached(f"no {event['datagram']} datagram within {STAGE_TIMEOUT_S:g} s") from None
            else:
                cmd.wait_for(**event)
        except NotReached as err:
            pytest.fail(f"`rimless {_name(path)} {' '.join(args)}` never reached {event}; give it longer work:\n{err}")
        cmd.interrupt()
        try:
            res = cmd.finish(timeout_s=60)
        except subprocess.TimeoutExpired:
            pytest.fail(f"`rimless {_name(path)}` did not stop within 60 s of SIGINT:\n{''.join(cmd.lines['stderr'])}")
    stdout, stderr = res.stdout, res.stderr
    out = stdout + stderr
    # a run whose result was complete when the signal came ends with its own exit code (the entry point ignores
    # SIGINT from then on: rimless.__main__.ignore_ctrl_c_from_here); -2 with the result and nothing said was how
    # such a run ended before
    finished_at_the_signal = res.returncode in (0, 1, 2) or (
        res.returncode == -signal.SIGINT and not stderr.strip() and stdout.strip()
    )
    assert not finished_at_the_signal, (
        f"`rimless {_name(path)} {' '.join(args)}` finished (exit {res.returncode}) as the interrupt came at "
        f"{event}; give it longer work:\n{out[-2000:]}"
    )
    # 130, or killed by SIGINT (-2): a shell shows both as $? = 130. Python ends itself with SIGINT when a
    # KeyboardInterrupt passed through C code that records it (e.g. during an import), even once handled.
    assert res.returncode in (130, -signal.SIGINT), f"exit {res.returncode} after SIGINT:\n{out[-3000:]}"
    assert "Traceback" not in out and "CancelledError" not in out, out[-3000:]
    lines = stderr_lines(stderr)
    assert lines and lines[-1] == "interrupted", f"last line on stderr: {lines[-1:]}"
    left = _leftovers(tmp_path, before, ALLOWED_AFTER_INTERRUPT.get(path, set()))
    assert not left, f"an interrupted `rimless {_name(path)}` left {left} behind"


# ------------------------------------------------------------------------------------------ no result

# Valid inputs without a result: exit 1, one line `error: ...` on stderr naming what is missing, nothing on
# stdout, no output left behind. (Bad values are walked above, Ctrl-C below.)
NO_RESULT: dict[str, tuple[list[str], list[str], bool]] = {  # id: (args, words in the error, slow)
    "sim gait from a state that stalls": (
        ["sim", "gait", "--theta-dot", "0.5", "--out", "traj.csv"],
        ["no step completed", "stall"],
        False,
    ),
    "sim gaits on a slope without gaits": (
        ["sim", "gaits", "--model", "er", "--slope-deg", "0.5", "--guesses", "3"],
        ["no period-1 gait", "0.5000 deg"],
        False,
    ),
    "sim critical-slope below the ER branch": (
        ["sim", "critical-slope", "--model", "er", "--slope-deg", "1"],
        ["critical slope of the er wheel", "no fixed point"],
        False,
    ),
    "paper on the level": (
        ["paper", "--slope-deg", "0", "--k", "2500:2750:250", "--scheduler", "sync", "--out", "p"],
        ["no period-1 gait", "0.0000 deg"],
        True,
    ),
    "paper on a 20 deg slope": (
        ["paper", "--slope-deg", "20", "--k", "2500:2750:250", "--scheduler", "sync", "--out", "p"],
        ["no period-1 gait", "20.0000 deg"],
        True,
    ),
    "paper with c = 60": (
        ["paper", "--c", "60", "--k", "2500:2750:250", "--scheduler", "sync", "--out", "p"],
        ["no period-1 gait", "c = 60"],
        True,
    ),
}


# The slow cases beyond the first (one `paper` run on the level) are marked `full` (CI runs them).
@pytest.mark.parametrize(
    "case",
    [
        pytest.param(k, marks=[pytest.mark.slow, *([pytest.mark.full] if k != "paper on the level" else [])])
        if v[2]
        else k
        for k, v in NO_RESULT.items()
    ],
)
def test_valid_input_without_a_result_is_one_line_and_exit_1(case: str, tmp_path: Path) -> None:
    args, words, _ = NO_RESULT[case]
    res = _run(args, cwd=tmp_path)
    _one_error_line(res.stderr, 1, res.returncode, words, res.stdout + res.stderr)
    assert res.stdout.strip() == "", res.stdout
    assert not list(tmp_path.iterdir()), f"left behind: {sorted(p.name for p in tmp_path.iterdir())}"


# ------------------------------------------------------------------------------------------ Dask


def _group_processes(pgid: int) -> list[str]:
    """Command lines of the live (not zombie) processes of process group `pgid`."""
    out = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[2]) == pgid and fields[0] != "Z":
                out.append(Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " "))
        except (OSError, IndexError, ValueError):
            continue
    return out


_SWEEP_81 = ["sim", "sweep", "--k", "1500:3500:25", "--no-cache", "--workers", "2", "--out", "sweep-out/k"]
# (arguments, the event on which the Ctrl-C is sent: a stage the command reaches (rimless.progress.stage), or
# "workers": N, the first time the process group holds N processes besides the command)
LOCAL_CLUSTER_RUNS: dict[str, tuple[list[str], dict[str, Any]]] = {
    # in the figures' sweeps, the grid points handed to the two workers: there the KeyboardInterrupt was raised
    # inside the in-process Dask scheduler's gc callback, where Python swallows it, and the paper ran on to exit
    # 0 (rimless.sim.studies.sweep._no_gc_callback)
    "paper": (["paper", "--no-cache", "--out", "paper-out", "--workers", "2"], {"stage": "grid points submitted"}),
    # 162 grid points (81 per model; minutes of work) handed to the two workers: the interrupt lands while they compute
    "sim sweep": (_SWEEP_81, {"stage": "grid points submitted to 2 worker(s)"}),
    # the interrupt as the first worker process appears: while the local cluster starts
    "sim sweep, cluster starting": (_SWEEP_81, {"workers": 1}),
}


def _wait_for_workers(pgid: int, count: int, timeout_s: float = 300.0) -> None:
    """Wait until the process group holds `count` processes besides the command (its Dask workers): the event
    is a process appearing, which nothing announces, so /proc is looked at every 0.2 s."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and len(_group_processes(pgid)) < count + 1:
        time.sleep(0.2)


def _wait_until_gone(pgid: int, timeout_s: float = 60.0) -> list[str]:
    """The group's processes (but the resource tracker) still alive after waiting up to `timeout_s` for them
    to end (the killed workers are reaped by init once the command has exited)."""
    import psutil

    procs = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            with contextlib.suppress(psutil.Error):
                p = psutil.Process(int(pid))
                if os.getpgid(p.pid) == pgid and "resource_tracker" not in " ".join(p.cmdline()):
                    procs.append(p)
    _, alive = psutil.wait_procs(procs, timeout=timeout_s)
    return [" ".join(p.cmdline()) for p in alive if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


@pytest.mark.slow
# Strict: multiprocessing's resource tracker is started with its leaked-semaphore warning ignored (the killed
# workers' semaphores are still unlinked), and after an interrupt nothing of the command's process prints
# (Dask's logging, thread and finalizer tracebacks silenced) before it exits (rimless.sim.studies.sweep).
# "sim sweep" in every run; the other two are marked `full` (CI runs them)
@pytest.mark.parametrize(
    "case", [pytest.param(c, marks=[] if c == "sim sweep" else [pytest.mark.full]) for c in sorted(LOCAL_CLUSTER_RUNS)]
)
def test_ctrl_c_to_the_process_group_with_a_local_dask_cluster(case: str, tmp_path: Path) -> None:
    """A terminal's Ctrl-C reaches every process of the group (the command and its Dask workers): the command
    prints `interrupted` last, exits 130, leaves no output and no worker behind; the workers print nothing."""
    args, event = LOCAL_CLUSTER_RUNS[case]
    env = {**os.environ, "COLUMNS": str(WIDTH)}
    with Watched([sys.executable, "-m", "rimless", *args], cwd=tmp_path, env=env, new_session=True) as cmd:
        if "workers" in event:
            _wait_for_workers(cmd.proc.pid, event["workers"])
        else:
            cmd.wait_for(**event)
        assert cmd.proc.poll() is None, "".join(cmd.lines["stderr"])[-2000:]
        cmd.interrupt()  # to the process group, as a terminal's Ctrl-C
        res = cmd.finish(timeout_s=60)
        left = _wait_until_gone(cmd.proc.pid)
    out = res.stdout + res.stderr
    assert res.returncode == 130, f"exit {res.returncode}:\n{out[-3000:]}"
    lines = stderr_lines(res.stderr)
    assert lines == ["interrupted"], f"stderr:\n{res.stderr[-3000:]}"
    assert "Traceback" not in out
    assert not left, f"left running: {left}"
    assert not list(tmp_path.iterdir())


@pytest.fixture()
def scheduler_whose_worker_lacks_rimless(tmp_path: Path) -> Any:
    """A Dask scheduler on the loopback with one worker that cannot import rimless (a stand-in package that
    raises ModuleNotFoundError comes first on its path, as on a machine where rimless is not installed)."""
    fake = tmp_path / "nopkg" / "rimless"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ModuleNotFoundError(\"No module named 'rimless'\", name='rimless')\n")
    port = _free_tcp_port()
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    sched = subprocess.Popen(
        [*dask, "--port", str(port), "--no-dashboard"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    worker = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "distributed.cli.dask_worker",
            f"tcp://127.0.0.1:{port}",
            "--nthreads",
            "1",
            "--no-dashboard",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env={**os.environ, "PYTHONPATH": str(tmp_path / "nopkg")},
        cwd=tmp_path / "nopkg",
    )
    try:
        from distributed import Client

        deadline = time.monotonic() + 60
        while True:  # wait until the worker has joined
            try:
                with Client(f"tcp://127.0.0.1:{port}", timeout=5) as client:
                    if client.scheduler_info().get("workers"):
                        break
            except OSError:
                pass
            assert time.monotonic() < deadline, "the test's Dask worker did not start"
            time.sleep(0.5)
        yield f"tcp://127.0.0.1:{port}"
    finally:
        for p in (worker, sched):
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


@pytest.mark.slow
@pytest.mark.parametrize(
    "command",
    [
        pytest.param(["sim", "sweep", "--k", "2700", "--model", "er", "--out", "s/k"], id="sim sweep"),
        pytest.param(["paper", "--k", "2700", "--out", "paper-out"], id="paper", marks=pytest.mark.full),
    ],
)  # `full`: CI runs it
def test_a_dask_worker_without_the_package_is_one_error_line(
    command: list[str], tmp_path: Path, scheduler_whose_worker_lacks_rimless: str
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    res = _run([*command, "--no-cache", "--scheduler", scheduler_whose_worker_lacks_rimless], cwd=work)
    _one_error_line(res.stderr, 2, res.returncode, ["--scheduler", "cannot import rimless"], res.stdout + res.stderr)
    assert not list(work.iterdir())
