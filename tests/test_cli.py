"""The `rimless` command line: fast help, thin commands, user errors as one line with exit code 2."""

import json
import re
import signal
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.cli import app

runner = CliRunner()
HEAVY = ("scipy", "numpy", "pandas", "matplotlib", "sympy", "numba")


def test_help_imports_no_heavy_library():
    code = (
        "import sys\nsys.argv = ['rimless', '--help']\nfrom rimless.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        f"print('HEAVY', [m for m in {HEAVY!r} if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "HEAVY []" in out
    assert "sim" in out


@pytest.mark.parametrize(
    "module",
    [
        "rimless.sim.cli",
        "rimless.analysis.cli",
        "rimless.firmware.cli",
        "rimless.sim.cli.firmware",
        "rimless.sim.cli.app",
        "rimless.sim.cli.fixed_point",
        "rimless.sim.cli.gait",
        "rimless.sim.cli.sweep",
        "rimless.sim.cli.replay",
        "rimless.sim.cli.studies",
        "rimless.cli",
    ],
)
def test_each_command_module_imports_on_its_own(module):
    """A part's command module imports first, before rimless.cli registers the parts (no circular import)."""
    res = subprocess.run([sys.executable, "-c", f"import {module}"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-1500:]


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["sim", "fixed-point", "--hub-mass-kg", "-1"], "hub_mass_kg"),
        (["sim", "fixed-point", "--k", "0"], "--k"),
        (["sim", "fixed-point", "--slope-deg", "22.5"], "slope"),
        (["sim", "critical-slope", "--model", "rigid", "--c", "nan"], "--c"),
        (["sim", "fixed-point", "--slope-deg", "1", "--slope-rad", "0.02"], "slope"),
        (["sim", "gait", "--out", "traj.txt"], "traj.txt"),
    ],
)
def test_bad_parameters_exit_2_with_one_line(args, named):
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert named in res.output
    assert "Traceback" not in res.output


def test_params_file_errors_name_the_file(tmp_path):
    f = tmp_path / "wheel.toml"
    f.write_text("k = -5\n")
    res = runner.invoke(app, ["sim", "critical-slope", "--model", "rigid", "--params", str(f)])
    assert res.exit_code == 2
    # the file's key, not `--k` (not given): tests/sim/cli/test_wheel_file_error_names_key.py
    assert "wheel.toml" in res.output and "parameter k must be > 0" in res.output


def test_rigid_critical_slope_json_is_the_papers_2_80_deg():
    res = runner.invoke(app, ["sim", "critical-slope", "--model", "rigid", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert round(out["critical_slope_deg"], 2) == 2.80
    assert out["cot"] == pytest.approx(0.0489, abs=1e-4)
    assert "m_H" in out["mass_convention"]
    assert out["eight_leg_consistent"]["critical_slope_deg"] == pytest.approx(2.600, abs=1e-3)


def test_fixed_point_json_has_the_contract_keys():
    res = runner.invoke(app, ["sim", "fixed-point", "--model", "er", "--json", "--rtol", "1e-9"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    for key in (
        "model",
        "slope_rad",
        "k",
        "c",
        "theta_plus_rad",
        "theta_dot_plus_rad_s",
        "step_period_s",
        "eigenvalues",
        "max_abs_eigenvalue",
        "stable",
        "energy_ratio",
        "min_normal_force_N",
        "phase_durations_s",
    ):
        assert key in out
    assert out["model"] == "er" and out["k"] == 2700 and out["c"] == 8 and out["slope_rad"] == 0.05
    assert len(out["eigenvalues"]) == 2 and all(len(e) == 2 for e in out["eigenvalues"])
    assert out["stable"] is True
    assert set(out["phase_durations_s"]) == {"dlsp", "slsp_free", "slsp_clutched"}


def test_firmware_imports_and_runs_without_numeric_libraries(tmp_path):
    """The robot install has no numpy/scipy/pandas/matplotlib: block them and import every firmware module."""
    code = (
        "import sys, importlib, pkgutil\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        f"        if name.split('.')[0] in {HEAVY!r}:\n"
        "            raise ImportError('blocked on the robot: ' + name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "import rimless.firmware as fw\n"
        "names = [m.name for m in pkgutil.walk_packages(fw.__path__, 'rimless.firmware.')]\n"
        "for n in names:\n"
        "    importlib.import_module(n)\n"
        "print('OK', len(names))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("OK")
    assert int(out.stdout.split()[1]) > 25, out.stdout  # the subpackages' modules too, not only the folders
    # and the fake robot runs end to end for a moment without them
    run = (
        "import sys\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        f"        if name.split('.')[0] in {HEAVY!r}:\n"
        "            raise ImportError('blocked on the robot: ' + name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "sys.argv = ['rimless', 'robot', 'run', '--fake', '--arm', '--stance-leg', '0', '--duration-s', '1']\n"
        "from rimless.cli import main\n"
        "main()\n"
    )
    res = subprocess.run([sys.executable, "-c", run], capture_output=True, text=True, cwd=tmp_path, timeout=60)
    assert res.returncode == 0, res.stderr[-2000:]


@pytest.mark.parametrize(("model", "reason"), [("er", "stall"), ("ve", "fold")])
def test_critical_slope_of_the_compliant_wheels(model, reason):
    """model.md section 9: both near 1.26 deg; ER ends in a stall, the VE medium branch in a fold."""
    res = runner.invoke(app, ["sim", "critical-slope", "--model", model, "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert 1.2 < out["critical_slope_deg"] < 1.32
    assert out["reason"] == reason
    assert out["cot"] == pytest.approx(np.tan(out["critical_slope_rad"]), rel=1e-12)
    # Algorithm 1 stops at the last converged multiple of its step, at or above the refined boundary
    assert (
        out["critical_slope_rad"]
        <= out["algorithm1_slope_rad"]
        < out["critical_slope_rad"] + out["algorithm1_step_rad"] + 1e-12
    )
    assert out["refine_tol_rad"] == 1e-6
    assert out["at_critical"]["max_abs_eigenvalue"] < 1


def test_stress_sweep_classifies_every_point():
    res = runner.invoke(
        app,
        [
            "sim",
            "stress",
            "--k-values",
            "300,2700,1e6",
            "--c-values",
            "0,8",
            "--slopes-deg",
            "0.1,2.9,22",
            "--mass-ratios",
            "0.02",
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["points"] == 3 * 2 * 3 * 1 * 2 * 3
    assert sum(sum(c.values()) for c in out["counts"].values()) == out["points"]
    assert out["unclassified"] == []
    assert out["counts"]["er"].get("valid", 0) > 0 and len(out["counts"]["er"]) >= 3
    bad = runner.invoke(app, ["sim", "stress", "--slopes-deg", "30"])
    assert bad.exit_code == 2 and "--slopes-deg" in bad.output


# ------------------------------------------------------------------------ the root's shared mechanisms


def _toy_app():
    """A small app under the root group, with commands that fail in each way a real command can."""
    import typer

    from rimless.cli import RimlessGroup, fail
    from rimless.errors import ParameterError

    toy = typer.Typer(cls=RimlessGroup, add_completion=False)

    @toy.command()
    def user(x: float = 1.0) -> None:
        raise ParameterError(f"--x must be positive, got {x}")

    @toy.command()
    def nogait() -> None:
        fail("no period-1 gait exists at this slope (stall)")

    @toy.command()
    def ctrlc() -> None:
        raise KeyboardInterrupt

    @toy.command()
    def numba_ctrlc() -> None:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:  # what numba does when Ctrl-C lands in a callback
            raise SystemError("<numba> returned a result with an exception set") from err

    @toy.command()
    def missing(path: str = "nope.csv") -> None:
        open(path)

    @toy.command()
    def negative(value: float) -> None:
        print(f"value={value}")

    return toy


@pytest.mark.parametrize(
    ("args", "code", "line"),
    [
        (["user", "--x", "-2"], 2, "error: --x must be positive, got -2.0"),
        (["nogait"], 1, "error: no period-1 gait exists at this slope (stall)"),
        (["ctrlc"], 130, "interrupted"),
        (["numba-ctrlc"], 130, "interrupted"),
        (["missing", "--path", "/no/such/file.csv"], 2, "error: /no/such/file.csv: No such file or directory"),
        (["user", "--x", "abc"], 2, "error: --x must be a number, got 'abc'"),
        (["negative"], 2, "error: missing argument VALUE (see 'rimless negative --help')"),
    ],
)
def test_root_group_maps_every_failure_to_one_line_and_its_exit_code(args, code, line):
    res = CliRunner().invoke(_toy_app(), args, prog_name="rimless")
    assert res.exit_code == code, res.output
    assert res.stderr.strip().splitlines() == [line]
    assert res.stdout == ""


def test_negative_numbers_reach_the_command_as_values():
    res = CliRunner().invoke(_toy_app(), ["negative", "-3.5e-2"])
    assert res.exit_code == 0 and res.stdout.strip() == "value=-0.035"


def _number_app():
    """Options of each kind the rules word and label: bounded float and int, a repeated float, a path, a flag,
    and an argument of several paths."""
    from pathlib import Path
    from typing import Annotated

    import typer

    from rimless.cli import RimlessGroup

    toy = typer.Typer(cls=RimlessGroup, add_completion=False)

    @toy.command()
    def num(
        x: Annotated[float, typer.Option(min=0.0, help="A length, m.")] = 1.0,
        n: Annotated[int, typer.Option(min=0, max=5, help="A leg index.")] = 0,
        xs: Annotated[list[float] | None, typer.Option(help="Unbounded numbers.")] = None,
        where: Annotated[Path, typer.Option(help="A folder.")] = Path("."),
        loud: Annotated[bool, typer.Option("--loud", help="A flag.")] = False,
    ) -> None:
        """Print what it read."""
        print(f"x={x!r} n={n!r} xs={xs!r}")

    @toy.command()
    def files(paths: Annotated[list[Path], typer.Argument(help="Some files.")]) -> None:
        """Take files."""

    return toy


# The words are the rules' own (rimless.cli_rules), the same whichever typer converts: 0.29 on the PC (pydantic),
# 0.28 on the robot (click's types; .ci/wheel-check runs the robot's cases there). Expected lines written from the
# rule: the option, what it must be, and the text as typed.
@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--x", "abc"], "error: --x must be a number, got 'abc'"),
        (["--x", "-1"], "error: --x must be >= 0.0, got '-1'"),
        (["--x", "nan"], "error: --x must be >= 0.0, got 'nan'"),  # NaN is within no bounds
        (["--n", "x"], "error: --n must be a whole number, got 'x'"),
        (["--n", "1.5"], "error: --n must be a whole number, got '1.5'"),
        (["--n", "1e3"], "error: --n must be a whole number, got '1e3'"),
        (["--n", "9"], "error: --n must be between 0 and 5, got '9'"),
        (["--n", "-1"], "error: --n must be between 0 and 5, got '-1'"),
        (["--n", "6.0"], "error: --n must be between 0 and 5, got '6.0'"),
        (["--xs", "1", "--xs", "abc"], "error: --xs must be a number, got 'abc'"),
    ],
)
def test_a_bad_number_says_what_was_expected(args, line):
    res = CliRunner().invoke(_number_app(), ["num", *args], prog_name="rimless")
    assert res.exit_code == 2, res.output
    assert res.stderr.strip().splitlines() == [line]
    assert res.stdout == ""


@pytest.mark.parametrize(
    ("args", "printed"),
    [
        (["--x", "0"], "x=0.0 n=0 xs=None"),  # a bound is inside
        (["--n", "3.0"], "x=1.0 n=3 xs=None"),  # a whole number with a zero fraction, as pydantic reads it
        (["--n", "5", "--xs", "nan", "--xs", "-2"], "x=1.0 n=5 xs=[nan, -2.0]"),  # no bounds, no check
    ],
)
def test_good_numbers_reach_the_command(args, printed):
    res = CliRunner().invoke(_number_app(), ["num", *args], prog_name="rimless")
    assert res.exit_code == 0, res.output
    assert res.stdout.strip() == printed


def test_help_labels_types_in_upper_case_and_flags_not_at_all():
    env = {"COLUMNS": "100", "TERM": "dumb"}
    out = CliRunner().invoke(_number_app(), ["num", "--help"], prog_name="rimless", env=env).output
    rows = {line.split()[1]: line.split()[2] for line in out.splitlines() if line.startswith("│ --")}
    assert rows == {
        "--x": "FLOAT",
        "--n": "INTEGER",
        "--xs": "FLOAT...",
        "--where": "PATH",
        "--loud": "A",
        "--help": "Show",
    }, out
    assert "[x>=0.0]" in out and "[0<=x<=5]" in out
    out = CliRunner().invoke(_number_app(), ["files", "--help"], prog_name="rimless", env=env).output
    assert "Usage: rimless files [OPTIONS] PATHS..." in out
    assert re.search(r"│ \*\s+PATHS\s+PATH\.\.\.\s+Some files\.", out), out


def test_a_list_of_numbers_says_what_is_expected():
    res = runner.invoke(app, ["robot", "bench", "--fake", "--rate-hz", "abc"])
    assert res.exit_code == 2 and res.stderr == "error: --rate-hz must be numbers separated by commas, got 'abc'\n"
    res = runner.invoke(app, ["robot", "bench", "--fake", "--rate-hz", "300,abc"])
    assert res.exit_code == 2
    assert res.stderr == "error: --rate-hz must be numbers separated by commas, got 'abc' in '300,abc'\n"


def test_a_real_bug_still_shows_its_traceback():
    """Only deliberate failures are turned into one line: a programming error must stay visible."""
    import typer

    from rimless.cli import RimlessGroup

    toy = typer.Typer(cls=RimlessGroup, add_completion=False)

    @toy.command()
    def bug() -> None:
        raise ZeroDivisionError("bug")

    @toy.command()
    def other() -> None:
        pass

    res = CliRunner().invoke(toy, ["bug"])
    assert res.exit_code == 1 and isinstance(res.exception, ZeroDivisionError)


def test_console_script_version_and_a_usage_error():
    res = subprocess.run([sys.executable, "-m", "rimless", "--version"], capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.startswith("rimless ")
    res = subprocess.run(
        [sys.executable, "-m", "rimless", "sim", "fixed-point", "--model", "xx"], capture_output=True, text=True
    )
    assert res.returncode == 2
    assert res.stderr == "error: --model must be one of er, ve, got 'xx'\n"


def test_atomic_file_appears_only_when_complete(tmp_path):
    from rimless.output import atomic_file

    target = tmp_path / "sub" / "traj.csv"
    with atomic_file(target) as tmp:
        assert tmp.parent == target.parent and tmp.suffix == ".csv" and tmp != target
        tmp.write_text("a,b\n1,2\n")
        assert not target.exists()
    assert target.read_text() == "a,b\n1,2\n"
    assert sorted(p.name for p in target.parent.iterdir()) == ["traj.csv"]
    # an interrupted rewrite keeps the old complete file and leaves no temporary behind
    with pytest.raises(KeyboardInterrupt):
        with atomic_file(target) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert target.read_text() == "a,b\n1,2\n"
    assert sorted(p.name for p in target.parent.iterdir()) == ["traj.csv"]


def test_atomic_files_renames_all_or_none(tmp_path, monkeypatch):
    import os
    from pathlib import Path

    from rimless.output import atomic_files

    traj, fig = tmp_path / "traj.csv", tmp_path / "fig.png"
    with pytest.raises(KeyboardInterrupt):  # interrupted after the first output was written: neither appears
        with atomic_files((traj, "--out"), (None, "--json"), (fig, "--plot")) as (t, none, f):
            assert none is None and t.suffix == ".csv" and f.suffix == ".png"
            t.write_text("a\n")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    # a SIGINT while the outputs are renamed waits until every one is in place
    renamed = []
    real_replace = os.replace

    def replace(src, dst):
        real_replace(src, dst)
        renamed.append(Path(dst).name)
        if len(renamed) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # held back: no KeyboardInterrupt between the two renames

    monkeypatch.setattr(os, "replace", replace)
    # Python's own handler, as in a terminal (a suite started in the background inherits SIGINT ignored)
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with atomic_files((traj, "--out"), (fig, "--plot")) as (t, f):
                t.write_text("a\n")
                f.write_bytes(b"png")
    finally:
        signal.signal(signal.SIGINT, before)
    assert renamed == ["traj.csv", "fig.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png", "traj.csv"]


def test_atomic_dir_replaces_the_folder_whole(tmp_path):
    from rimless.output import atomic_dir

    out = tmp_path / "report"
    with pytest.raises(RuntimeError):
        with atomic_dir(out) as tmp:
            (tmp / "report.html").write_text("<html>")
            raise RuntimeError("every trial failed")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    with atomic_dir(out) as tmp:
        (tmp / "report.html").write_text("v1")
    with atomic_dir(out) as tmp:
        (tmp / "report.html").write_text("v2")
        assert (out / "report.html").read_text() == "v1"
    assert (out / "report.html").read_text() == "v2"
    assert [p.name for p in tmp_path.iterdir()] == ["report"]


def test_unwritable_output_names_the_option_and_path(tmp_path):
    from rimless.errors import OutputFileError, UserError
    from rimless.output import atomic_dir, atomic_file

    with pytest.raises(OutputFileError, match=r"^--plot /proc/rimless-nope/x.png: cannot create") as err:
        with atomic_file("/proc/rimless-nope/x.png", option="--plot"):
            pass
    assert isinstance(err.value, UserError)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(OutputFileError, match="--out .*afile: exists and is not a folder"):
        with atomic_dir(tmp_path / "afile", option="--out"):
            pass
    with pytest.raises(OutputFileError, match="is a folder"):
        with atomic_file(tmp_path, option="--out"):
            pass


def test_progress_bar_is_quiet_off_a_terminal_and_drawn_on_one_with_json(capsys, monkeypatch):
    import io

    from rimless.progress import progress_bar, progress_is_shown

    monkeypatch.delenv("RIMLESS_PROGRESS_EVERY_S", raising=False)
    with progress_bar("work", total=3) as bar:  # pytest's stderr is not a terminal
        bar.advance()
        bar.update(completed=3, description="done")
    assert capsys.readouterr().err == ""

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stderr", Tty())
    assert progress_is_shown(json_out=False) and progress_is_shown(json_out=True)


@pytest.mark.parametrize(
    ("option", "si", "text"),
    [
        ("--slope-deg", np.radians(30.0), "--slope-deg 30"),
        ("--max-gap-ms", 0.05, "--max-gap-ms 50"),
        ("--hub-offset-mm", 0.0125, "--hub-offset-mm 12.5"),
        ("--slope-rad", 0.05, "--slope-rad 0.05"),
        ("--k", 2700.0, "--k 2700"),
    ],
)
def test_values_are_echoed_in_the_unit_of_the_option(option, si, text):
    from rimless.units import typed

    assert typed(option, float(si)) == text


def test_ctrl_c_in_compiled_code_is_not_classified_as_a_failed_step(monkeypatch):
    """numba turns a Ctrl-C inside compiled code into a SystemError; the stress sweep, which classifies
    every exception of a step, must let it stop the command instead of counting it as 'unclassified'."""
    from rimless.errors import interrupted_by_user
    from rimless.sim import fast
    from rimless.sim.model.params import WheelParams
    from rimless.sim.studies.stress import stress_sweep

    def interrupted_step(*args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as err:
            raise SystemError("<CPUDispatcher> returned a result with an exception set") from err

    monkeypatch.setattr(fast, "fast_step", interrupted_step)
    with pytest.raises(KeyboardInterrupt):
        stress_sweep(WheelParams(), k_values=[2700.0], c_values=[8.0], slopes_rad=[0.05], mass_ratios=[0.02])
    assert not interrupted_by_user(SystemError("a real numba failure"))
    assert interrupted_by_user(KeyboardInterrupt())


# A Ctrl-C whose KeyboardInterrupt is raised inside a weakref callback (as in `rimless paper`, inside a library's
# WeakKeyDictionary): Python drops it there and prints "Exception ignored in ...". Then the script blocks on its
# stdin, which only a Ctrl-C or the end of its input ends: no clock decides the outcome.
DROPPED_CTRL_C = """
import sys, weakref
if sys.argv[1] == "main":
    from rimless.__main__ import main
    sys.argv = ["rimless", "--version"]
    try:
        main()
    except SystemExit:
        pass
    # the entry point ignores Ctrl-C once its result is complete (the interpreter's teardown follows); this
    # script runs on as a command would, with the entry point's unraisable hook still installed
    import signal
    signal.signal(signal.SIGINT, signal.default_int_handler)
class Referent:
    pass
def callback(ref):
    raise KeyboardInterrupt
r = weakref.ref(obj := Referent(), callback)
try:
    del obj
    print("callback ran", flush=True)
    sys.stdin.readline()
    print("ran on")
except KeyboardInterrupt:
    print("interrupted")
"""


@pytest.mark.parametrize("entry", ["main", "plain"])
def test_a_ctrl_c_python_dropped_in_a_callback_still_interrupts(entry):
    """The `rimless` entry point sends the interrupt again (rimless.__main__.redeliver_swallowed_interrupts): the
    script, blocked on an input that never comes, is interrupted. A plain interpreter, the control, prints
    Python's "Exception ignored" traceback and runs on to the end of its input."""
    # SIGINT as on a terminal: a suite started in the background of a non-interactive shell inherits it ignored
    proc = subprocess.Popen(
        [sys.executable, "-c", DROPPED_CTRL_C, entry],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        if entry == "plain":
            assert proc.stdout.readline().strip() == "callback ran"
            proc.stdin.close()  # the end of its input: the only way on for a script whose interrupt was dropped
        proc.wait(timeout=60)  # "main": stdin stays open, only the interrupt sent again ends the wait
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        out, err = proc.stdout.read(), proc.stderr.read()
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            stream.close()
    lines = out.splitlines()
    if entry == "plain":
        assert lines[-1:] == ["ran on"] and "Exception ignored" in err, out + err
        return
    assert lines[-2:] == ["callback ran", "interrupted"] or lines[-1:] == ["interrupted"], out + err
    assert "Exception ignored" not in err and "Traceback" not in err, err


def test_other_exceptions_python_drops_still_reach_the_hook_before():
    code = (
        "import sys\nfrom rimless.__main__ import redeliver_swallowed_interrupts\n"
        "redeliver_swallowed_interrupts()\n"
        "class Noisy:\n    def __del__(self):\n        raise ValueError('from __del__')\n"
        "Noisy()\nprint('ran on')\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.stdout.strip() == "ran on" and "ValueError: from __del__" in res.stderr


# The `rimless` entry point with a stop that waits for the test's SIGINT after the command's result: as click
# closes the root context (the command has returned), or as the interpreter tears the modules down (Python has
# put SIGINT back to its default there unless it is ignored).
CTRL_C_AFTER_THE_RESULT = """
import sys

WHEN = sys.argv.pop(1)


def wait_for_the_signal():
    print(WHEN, file=sys.stderr, flush=True)
    sys.stdin.readline()  # the test sends SIGINT, then this line


if WHEN == "closing":
    from typer import _click

    close = _click.Context.close

    def closing(self):
        if self.parent is None:
            wait_for_the_signal()
        close(self)

    _click.Context.close = closing
else:

    class Last:
        def __del__(self):
            wait_for_the_signal()

    last = Last()  # deleted with this module's globals, late in the interpreter's teardown

from rimless.__main__ import main

sys.argv = ["rimless", *sys.argv[1:]]
main()
"""


@pytest.mark.parametrize(
    ("when", "args", "code"),
    [
        ("closing", ["trials", "import", "SYNTHETIC_er_slope1.5deg_run1.csv", "--out", "imp", "--json"], 0),
        ("finalizing", ["trials", "import", "SYNTHETIC_er_slope1.5deg_run1.csv", "--out", "imp", "--json"], 0),
        ("finalizing", ["sim", "gait", "--model", "xx"], 2),
    ],
)
def test_a_ctrl_c_after_the_result_neither_interrupts_nor_kills(when, args, code, tmp_path):
    """Once the result is printed and the outputs are complete, a Ctrl-C is not reported `interrupted` (it was,
    as click closed its context: exit 130 after the JSON) and does not kill the process by the signal (it did
    in the teardown: exit -2, nothing said); the run ends with its own exit code."""
    import shutil

    from rimless.analysis.examples.bundled import data_files

    shutil.copy(next(f for f in data_files() if f.name == "SYNTHETIC_er_slope1.5deg_run1.csv"), tmp_path)
    proc = subprocess.Popen(
        [sys.executable, "-c", CTRL_C_AFTER_THE_RESULT, when, *args],
        cwd=tmp_path,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert proc.stderr is not None
        before = []
        for line in proc.stderr:
            if line.strip() == when:
                break
            before.append(line)
        else:
            raise AssertionError("".join(before))
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate("go\n", timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, f"exit {proc.returncode}: {before} {stderr}"
    assert stderr == "", stderr  # nothing after the stop: no `interrupted`, no traceback
    if code == 0:
        assert json.loads(stdout)[0]["status"] == "imported" and (tmp_path / "imp").is_dir()
    else:
        assert [line for line in before if line.strip()] == ["error: --model must be one of er, ve, got 'xx'\n"]
