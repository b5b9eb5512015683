"""The import graph of the package, read with `ast` (no import is executed): the rules of docs/architecture.md.

Every `import` counts, at module level or inside a function: a cycle hidden in a function is still a cycle.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOPS = {"rimless": "rimless", "sim": "rimless.sim", "firmware": "rimless.firmware", "analysis": "rimless.analysis"}
GENERATED = "rimless.sim.model.generated"

# Layers inside each part, lowest first. A module may import its own layer (no cycle) and every lower one.
LAYERS = {
    "rimless.sim": ["model", "integrate|fast", "step", "continuation", "studies", "in_the_loop", "api", "cli"],
    "rimless.firmware": ["errors|clock", "drivers", "control", "link", "service", "cli"],
    "rimless.analysis": ["io", "kinematics", "inference", "examples|report|validation|bench", "api", "cli"],
}
# What a part may import of the other parts (the shared root modules are open to all, the CLI root to none).
CROSS = {
    # the firmware in the loop runs the robot's own controller with its config and reads its trial logs
    "rimless.sim": {
        "rimless.firmware.errors",
        "rimless.firmware.drivers",
        "rimless.firmware.control",
        "rimless.firmware.service.config",
        "rimless.firmware.service.triallog",
    },
    "rimless.firmware": set(),
    "rimless.analysis": {"rimless.sim"},
}
SHARED_ROOT = {
    "rimless",
    "rimless.errors",
    "rimless.units",
    "rimless.output",
    "rimless.progress",
    "rimless.values",
    "rimless.second_process",
    "rimless.lazy",
}
CLI_ROOT = {"rimless.cli", "rimless.cli_rules", "rimless.__main__"}
HEAVY = ("numpy", "scipy", "pandas", "matplotlib", "dask", "numba", "sympy", "pyarrow", "ezc3d")


def _modules() -> dict[str, Path]:
    mods: dict[str, Path] = {}
    for top, name in TOPS.items():
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT / top).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            mods[".".join([name, *parts])] = path
    return mods


MODULES = _modules()


def _imports(module: str, path: Path) -> list[tuple[str, str | None, int]]:
    """(imported module, imported name or None, line) for every import of rimless code in `path`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[tuple[str, str | None, int]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, None, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor) + (f".{node.module}" if node.module else "")
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub, None, node.lineno) if sub in MODULES else (base, a.name, node.lineno))
    resolved = []
    for target, name, line in out:
        if target.split(".")[0] != "rimless":
            continue
        while target not in MODULES and "." in target:
            target = target.rpartition(".")[0]
        if target != module:
            resolved.append((target, name, line))
    return resolved


EDGES = {m: _imports(m, p) for m, p in MODULES.items()}


def _part(module: str) -> str | None:
    for part in LAYERS:
        if module == part or module.startswith(part + "."):
            return part
    return None


def _rank(module: str) -> int | None:
    part = _part(module)
    if part is None or module == part:
        return None
    sub = module[len(part) + 1 :].split(".")[0]
    for i, layer in enumerate(LAYERS[part]):
        if sub in layer.split("|"):
            return i
    return None


def _is_cli(module: str) -> bool:
    return module in CLI_ROOT or "cli" in module.split(".")


def test_every_module_sits_in_a_layer() -> None:
    loose = [m for m in MODULES if _part(m) and m != _part(m) and _rank(m) is None]
    assert not loose, f"modules outside the layers of docs/architecture.md: {loose}"


def test_no_import_cycle() -> None:
    graph = {m: {t for t, _, _ in e} for m, e in EDGES.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_library_modules_never_import_cli_modules() -> None:
    bad = [(m, t, line) for m, e in EDGES.items() if not _is_cli(m) for t, _, line in e if _is_cli(t)]
    assert not bad, f"library -> CLI imports (module, target, line): {bad}"


def test_no_private_names_across_modules() -> None:
    bad = [
        (m, t, n, line)
        for m, e in EDGES.items()
        for t, n, line in e
        if n and n.startswith("_") and not n.startswith("__")
    ]
    assert not bad, f"private names imported from another module: {bad}"


def test_layers_point_down() -> None:
    bad = []
    for m, e in EDGES.items():
        part = _part(m)
        for t, _, line in e:
            if t in SHARED_ROOT:
                continue
            if t in CLI_ROOT:
                if not _is_cli(m) or t != "rimless.cli_rules" and m != "rimless.__main__":
                    bad.append((m, t, line, "CLI root"))
                continue
            if part is None:
                if not _is_cli(m):
                    bad.append((m, t, line, "root module imports a part"))
                continue
            tpart = _part(t)
            if tpart != part:
                if not any(t == c or t.startswith(c + ".") for c in CROSS[part]):
                    bad.append((m, t, line, f"{part} may not import {tpart}"))
                continue
            rm, rt = _rank(m), _rank(t)
            if rm is not None and rt is not None and rt > rm:
                bad.append((m, t, line, "imports a higher layer"))
    assert not bad, "imports against docs/architecture.md:\n" + "\n".join(map(str, bad))


def test_firmware_imports_nothing_heavy() -> None:
    bad = []
    for m, path in MODULES.items():
        if _part(m) != "rimless.firmware":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom) and not node.level
                else []
            )
            bad += [(m, n, node.lineno) for n in names if n.split(".")[0] in HEAVY]
    assert not bad, f"firmware imports a PC-only library: {bad}"


@pytest.mark.parametrize("package", sorted(m for m, p in MODULES.items() if p.name == "__init__.py"))
def test_every_package_says_what_lives_there(package: str) -> None:
    doc = ast.get_docstring(ast.parse(MODULES[package].read_text())) or ""
    assert len(doc.split()) >= 8, f"{package}: the __init__ docstring should say what lives there"
    if _rank(package) is not None and package.count(".") == 2:
        assert re.search(r"May import", doc), f"{package}: say what it may import"


MAX_STATEMENTS = 450  # lines where a statement starts: the formatter cannot move it (about 600 lines of the old style)


def test_long_modules_are_one_concept() -> None:
    long = []
    for m, path in MODULES.items():
        if m.startswith(GENERATED):
            continue
        tree = ast.parse(path.read_text())
        n = len({node.lineno for node in ast.walk(tree) if isinstance(node, ast.stmt)})
        doc = ast.get_docstring(tree) or ""
        if n > MAX_STATEMENTS and "One concept" not in doc:
            long.append((m, n))
    assert not long, f"modules over {MAX_STATEMENTS} statements without 'One concept: ...' in their docstring: {long}"


def test_layer_names_exist() -> None:
    """The rules above name only folders that exist (a renamed folder must update them)."""
    present = defaultdict(set)
    for m in MODULES:
        part = _part(m)
        if part and m != part:
            present[part].add(m[len(part) + 1 :].split(".")[0])
    for part, layers in LAYERS.items():
        named = {s for layer in layers for s in layer.split("|")}
        assert named <= present[part], f"{part}: layers without a folder or module: {named - present[part]}"
