"""Every command in the ```bash blocks of README.md and docs/*.md runs as written, after the two set-up lines.

The commands run in README order (later ones read what earlier ones wrote, e.g. `trials show` reads what
`trials import` wrote) in a scratch folder that mirrors the repository's root through symbolic links, so
relative paths such as `analysis/data/...` resolve as in a clone while outputs land in the scratch folder.
`.venv` there points at the environment running the tests, and its `bin` folder comes first on PATH (what
`source .venv/bin/activate` does). Whatever bash blocks the pages gain later are parsed the same way. Each page
is one test (its commands in page order, in the page's own scratch folder); under pytest-xdist pages run in
parallel.
Every relative link of the pages points at a file that exists.

Each command must exit 0 without a traceback, every file or folder it names with `--out` or `--plot` must
exist afterwards and its path be printed, and every table it prints (lines drawn with box characters) fits 80 columns.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.readme_run import DEMO_COMMAND, DEMO_FOLDER, readme_env

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]  # every page whose bash blocks run
BLOCK = re.compile(r"^```bash[^\n]*\n(.*?)^```", re.M | re.S)

# Commands the test does not run, each with its reason. Keep this list short and explicit.
NOT_RUN: list[tuple[str, str]] = [
    (
        r"^python3 -m venv\b",
        "creates the environment the test is already running in (.ci/run does it on a clean clone)",
    ),
    (r"/pip install\b|^pip install\b", "installs the project; the test runs inside that installation"),
    (r"-m pytest\b|^pytest\b", "runs the test suite, which includes this test"),
    (
        r"^rimless robot (check|run)\b(?!.*--fake)",
        "needs the robot's hardware: ADNS-3080 sensors on SPI and clutch GPIO pins",
    ),
    (r"--host[\s=]+(?!127\.0\.0\.1\b|localhost\b)\S", "needs a running robot on the LAN"),
]

# Long-running commands get their quick options (appended when the README's line lacks them).
QUICK: list[tuple[str, list[str]]] = [
    (r"^rimless robot listen\b(?!.*--duration-s)", ["--duration-s", "1"]),
    (r"^rimless robot run\b(?!.*--duration-s)", ["--duration-s", "2"]),
    (r"^rimless bench\b(?!.*--quick)", ["--quick"]),
]

# Known violations in the parts' commands (regex on the command, reason): the page's test xfails while one
# of them fails, and passes (the lead deletes the entry) once the part fixes its command.
KNOWN_VIOLATIONS: list[tuple[str, str]] = []

TABLE_CHARS = re.compile("[\u2500-\u257f]")  # box drawing: the lines of a rich table
TIMEOUT_S = 900  # the first simulator command compiles the fast path (about a minute on the CI machine)


def readme_commands(text: str) -> list[str]:
    """The shell commands of every ```bash block: one per line, `&&` chains split, comments removed."""
    commands: list[str] = []
    for block in BLOCK.findall(text):
        for line in block.splitlines():
            line = re.sub(r"(^|\s)#.*$", "", line).strip()
            if not line:
                continue
            commands.extend(part.strip() for part in line.split("&&") if part.strip())
    return commands


def _normalised(command: str) -> str:
    """The command as the patterns see it: `.venv/bin/rimless` reads as `rimless`, `VAR=x rimless` as `rimless`."""
    return re.sub(r"^(\w+=\S*\s+)*(\./)?(\.venv/bin/)?", "", command)


def not_run_reason(command: str) -> str | None:
    for pattern, reason in NOT_RUN:
        if re.search(pattern, _normalised(command)):
            return reason
    return None


def with_quick_options(command: str) -> str:
    for pattern, extra in QUICK:
        if re.search(pattern, _normalised(command)):
            return command + " " + shlex.join(extra)
    return command


def named_outputs(command: str) -> list[str]:
    """Paths given to --out or --plot."""
    words = shlex.split(command)
    return [words[i + 1] for i, w in enumerate(words[:-1]) if w in ("--out", "--plot")]


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))
PAGE_COMMANDS: list[tuple[str, str]] = [
    (page.relative_to(ROOT).as_posix(), command)
    for page in PAGES
    for command in readme_commands(page.read_text(encoding="utf-8"))
]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def heading_anchors(text: str) -> set[str]:
    """The anchors GitHub gives a Markdown page's headings: lower case, every character but letters, digits,
    spaces, hyphens and underscores dropped, spaces as hyphens; a repeated one gets -1, -2, ..."""
    seen: dict[str, int] = {}
    out = set()
    in_code = False
    for line in text.splitlines():
        if line.startswith("```"):
            in_code = not in_code
        m = None if in_code else re.match(r"#{1,6} (.+)", line)
        if m is None:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def test_heading_anchors_follow_github() -> None:
    text = "# A\n## The cold step kernel's last seconds (2026-11-26, session 10)\n```\n# not a heading\n```\n## A\n"
    assert heading_anchors(text) == {"a", "the-cold-step-kernels-last-seconds-2026-11-26-session-10", "a-1"}


@pytest.mark.parametrize("page", PAGES, ids=[p.relative_to(ROOT).as_posix() for p in PAGES])
def test_every_relative_link_resolves(page: Path) -> None:
    """A newcomer following a link from the README or docs/ lands on a file that exists, and on the heading
    its anchor names."""
    broken = []
    for target in LINK.findall(page.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        file = page if not path else page.parent / path
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in heading_anchors(file.read_text(encoding="utf-8")):
            broken.append(target)
    assert not broken, f"{page.name}: broken links {broken}"


def test_docs_hold_the_reference_and_the_readme_stays_short() -> None:
    """The README is the five-minute page; the reference (every command family) lives in docs/ and still runs."""
    pages = {page for page, _ in PAGE_COMMANDS}
    assert {"docs/simulator.md", "docs/trials.md", "docs/robot.md"} <= pages, pages
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 120


def test_the_readme_has_runnable_commands():
    """The parser finds the README's commands (a README without any would make every test below vanish)."""
    runnable = [c for c in COMMANDS if not_run_reason(c) is None]
    assert any(_normalised(c).startswith("rimless demo") for c in runnable)
    assert DEMO_COMMAND in runnable  # the command of the shared demo run (tests/support/readme_run.py)
    assert any(_normalised(c).startswith("rimless sim ") for c in runnable)
    assert len(runnable) >= 6, runnable
    everywhere = [c for _, c in PAGE_COMMANDS if not_run_reason(c) is None]
    assert len(everywhere) >= 30, everywhere


def test_ci_runs_the_readmes_test_command() -> None:
    """.ci/run ends with the README's test command, verbatim (so CI times what a user runs)."""
    pytest_lines = [c for c in COMMANDS if re.search(r"-m pytest\b", c)]
    assert len(pytest_lines) == 1, pytest_lines
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert pytest_lines[0] in [line.strip() for line in ci.splitlines()], pytest_lines[0]
    # and CI runs every test: the ones marked `full` too (tests/conftest.py), exported before the command
    lines = [line.strip() for line in ci.splitlines()]
    assert lines.index("export RIMLESS_FULL_TESTS=1") < lines.index(pytest_lines[0])


def test_the_default_run_leaves_out_only_tests_marked_full(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without RIMLESS_FULL_TESTS and `-m`, exactly the tests marked `full` are deselected; with either, none."""
    from tests.conftest import full_run

    class Config:
        def __init__(self, markexpr: str) -> None:
            self.markexpr = markexpr

        def getoption(self, name: str, default: str = "") -> str:
            return self.markexpr if name == "markexpr" else default

    monkeypatch.delenv("RIMLESS_FULL_TESTS", raising=False)
    assert not full_run(Config(""))  # type: ignore[arg-type]
    assert full_run(Config("not slow"))  # type: ignore[arg-type]
    monkeypatch.setenv("RIMLESS_FULL_TESTS", "1")
    assert full_run(Config(""))  # type: ignore[arg-type]
    monkeypatch.setenv("RIMLESS_FULL_TESTS", "0")
    assert not full_run(Config(""))  # type: ignore[arg-type]


def test_parser_handles_chains_comments_and_the_setup_line():
    text = (
        'x\n```bash\npython3 -m venv .venv && .venv/bin/pip install -e ".[pc]" && .venv/bin/rimless demo\n'
        "rimless sim gaits --model ve   # every gait\n\n# a comment line\n```\n```text\nnot a command\n```\n"
    )
    cmds = readme_commands(text)
    assert cmds == [
        "python3 -m venv .venv",
        '.venv/bin/pip install -e ".[pc]"',
        ".venv/bin/rimless demo",
        "rimless sim gaits --model ve",
    ]
    assert [not_run_reason(c) is None for c in cmds] == [False, False, True, True]
    assert with_quick_options("rimless bench --plot wp.png") == "rimless bench --plot wp.png --quick"
    assert with_quick_options("rimless bench --quick") == "rimless bench --quick"
    assert named_outputs("rimless trials report a b --out report/ --json") == ["report/"]
    assert not_run_reason("RIMLESS_TOKEN=x .venv/bin/rimless robot run --config /etc/rimless/robot.toml")
    assert not_run_reason("rimless robot arm --host=10.0.0.5") == "needs a running robot on the LAN"
    assert not_run_reason("rimless robot run --fake --arm --stance-leg 0 --duration-s 5") is None


def make_mirror(where: Path) -> Path:
    """`where` made to look like the repository's root (symbolic links to its entries, `.venv` to the running
    environment); outputs land in it, not in the repository."""
    for entry in ROOT.iterdir():
        if entry.name in (".git", ".venv") or (entry.name.startswith(".") and entry.name != ".ci"):
            continue  # .ci stays: docs/architecture.md runs its checks
        (where / entry.name).symlink_to(entry)
    (where / ".venv").symlink_to(Path(sys.prefix))
    return where


def command_problem(command: str, mirror: Path) -> str | None:
    """Run one command (with its quick options) in `mirror`; what is wrong with it, or None."""
    run = with_quick_options(command)
    res = subprocess.run(
        ["bash", "-c", run],
        cwd=mirror,
        env=readme_env(),
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        stdin=subprocess.DEVNULL,
    )
    return run_problem(run, res.returncode, res.stdout + res.stderr, mirror)


def run_problem(run: str, returncode: int, out: str, mirror: Path) -> str | None:
    """What is wrong with one command's run (exit code, traceback, outputs, table width), or None."""
    if returncode != 0:
        return f"`{run}` exited {returncode}:\n{out[-3000:]}"
    if "Traceback" in out:
        return f"`{run}` printed a traceback:\n{out[-3000:]}"
    for path in named_outputs(run):
        target = (
            mirror / path
        )  # a file, a folder, or an output stem (`sim sweep --out sweep/k` writes k.parquet, k.csv)
        stem_files = list(target.parent.glob(f"{target.name}.*")) if target.parent.is_dir() else []
        if not (target.exists() or stem_files):
            return f"`{run}` did not write {path}"
        if path.rstrip("/") not in out:
            return f"`{run}` wrote {path} but does not say where"
    wide = [line for line in out.splitlines() if TABLE_CHARS.search(line) and len(line) > 80]
    if wide:
        return f"`{run}` prints table lines wider than 80 columns:\n" + "\n".join(wide)
    return None


# One test per page: its commands run in page order in one scratch folder (later ones read what earlier ones
# wrote). Not one test per command grouped with xdist_group: with pytest 9 and pytest-xdist 3.8 `--dist loadgroup`
# no longer keeps a group on one worker, and a page's commands ran on two workers in two folders (CI saw
# `trials show` miss the file `trials import` had just written).
# The README's `rimless demo` is the run shared with the tests that read the demo's report (tests/conftest.py's
# demo_run: the same command in a folder like this one, with the same environment): checked here like every other
# command, run once per test run instead of twice. Its page's test joins the demo's readers on one worker.
# The README's page runs in every run; the reference pages of docs/ (several minutes of commands between them)
# are marked `full`: CI runs them (tests/conftest.py).
@pytest.mark.slow
@pytest.mark.parametrize(
    "page",
    [
        pytest.param(page, marks=[pytest.mark.xdist_group("demo")] if page == "README.md" else [pytest.mark.full])
        for page in sorted({page for page, _ in PAGE_COMMANDS})
    ],
)
def test_page_commands_run_as_written(page: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    mirror = make_mirror(tmp_path)
    ran: list[str] = []
    known: list[str] = []
    for command in (c for p, c in PAGE_COMMANDS if p == page):
        reason = not_run_reason(command)
        if reason is not None:
            print(f"not run: {command}: {reason}")
            continue
        if command == DEMO_COMMAND:
            demo = request.getfixturevalue("demo_run")
            link = mirror / DEMO_FOLDER
            if link.is_symlink():  # the clone's own rimless-demo/ (the set-up line ran the demo there), mirrored
                link.unlink()
            link.symlink_to(demo.out, target_is_directory=True)
            problem = run_problem(command, demo.returncode, demo.stdout + demo.stderr, mirror)
        else:
            problem = command_problem(command, mirror)
        if problem is not None:
            if any(re.search(pattern, _normalised(command)) for pattern, _ in KNOWN_VIOLATIONS):
                known.append(problem)
                continue
            pytest.fail(f"{page}: {problem}\n(after {len(ran)} commands of the page ran as written)")
        ran.append(command)
    assert ran, f"{page}: no command ran"
    if known:
        pytest.xfail("known violations: " + "; ".join(k.splitlines()[0] for k in known))
