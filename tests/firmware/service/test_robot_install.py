"""No pydantic on the robot. typer 0.29 depends on pydantic and coerces every non-flag option through it, so the
robot install (`pip install -e ".[robot]"`) carried pydantic and its compiled core (9.6 MB) and `rimless robot run`
imported them (issue 32, item 7). The robot extra pins typer 0.28 (the same vendored click, no pydantic); the PC
install keeps 0.29. Fails on today's main: the robot extra leaves typer at 0.29.

Checked from the installed packages' own metadata (importlib.metadata): whatever typer is installed here, if it
requires pydantic, the robot extra must exclude it; the command path is checked in a subprocess with
an import spy that names, for each pydantic module imported, the module that asked for it."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).parents[3]
RIMLESS = str(Path(sys.executable).with_name("rimless"))
PYDANTIC_FAMILY = {"pydantic", "pydantic_core", "annotated_types", "typing_inspection"}


def _typer_requires_pydantic() -> bool:
    return any(Requirement(r).name == "pydantic" for r in metadata.requires("typer") or [])


def _extra(name: str) -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["optional-dependencies"][name]]


# Runs `rimless robot run --fake --duration-s 0` in this process with a finder in front of the import system that
# notes, for every pydantic-family import, the first module on the stack outside that family and importlib: who
# asked for it (at import time or at run time, as typer does when it coerces an option).
_SPY = r"""
import json, sys
FAMILY = set(sys.argv[1].split(","))
out, cfg = sys.argv[2], sys.argv[3]
importers = set()
class Spy:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in FAMILY:
            f, who = sys._getframe(1), ""
            while f is not None:
                mod = f.f_globals.get("__name__", "")
                if mod.split(".")[0] not in FAMILY and not mod.startswith(("importlib", "_frozen_importlib")):
                    who = mod
                    break
                f = f.f_back
            importers.add(who)
        return None
sys.meta_path.insert(0, Spy())
sys.argv = ["rimless", "robot", "run", "--fake", "--duration-s", "0", "--config", cfg]
from rimless.__main__ import main
code = 0
try:
    main()
except SystemExit as e:
    code = e.code or 0
loaded = sorted(m for m in sys.modules if m.split(".")[0] in FAMILY)
runner = "rimless.firmware.service.runner" in sys.modules
with open(out, "w") as f:
    json.dump({"code": code, "importers": sorted(importers), "loaded": loaded, "runner": runner}, f)
"""


def _robot_run_imports(tmp_path: Path) -> dict:
    """What `rimless robot run --fake --duration-s 0` imported of the pydantic family, and who asked for it."""
    cfg = tmp_path / "robot.toml"
    cfg.write_text(f'[commands]\nenabled = false\n[log]\ndir = "{tmp_path}"\n')
    out = tmp_path / "imports.json"
    r = subprocess.run(
        [sys.executable, "-c", _SPY, ",".join(sorted(PYDANTIC_FAMILY)), str(out), str(cfg)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0 and out.exists(), r.stderr[-2000:]
    seen = json.loads(out.read_text())
    assert seen["code"] == 0 and seen["runner"]  # the command ran, through the firmware's runner
    return seen


def test_the_robot_extra_excludes_a_typer_that_needs_pydantic() -> None:
    typer_pins = [r for r in _extra("robot") if r.name == "typer"]
    assert typer_pins, "the robot extra does not choose its typer: the base range allows one that needs pydantic"
    installed = metadata.version("typer")
    if _typer_requires_pydantic():
        assert not typer_pins[0].specifier.contains(installed), f"typer {installed} requires pydantic"
    else:
        assert typer_pins[0].specifier.contains(installed)
    assert all(r.name not in PYDANTIC_FAMILY for r in _extra("robot"))


def test_the_robot_command_path_imports_pydantic_only_through_typer(tmp_path: Path) -> None:
    """Whatever typer is installed: no rimless module (nor gpiozero, spidev, zxcvbn) asks for pydantic, so with the
    robot's typer nothing does."""
    seen = _robot_run_imports(tmp_path)
    assert all(who.startswith("typer.") for who in seen["importers"]), seen["importers"]
    if _typer_requires_pydantic():
        assert "pydantic" in seen["loaded"]  # the spy sees what it looks for: typer 0.29's coercion
    else:
        assert not seen["loaded"] and not seen["importers"]


def test_on_the_robot_install_the_command_path_loads_no_pydantic(tmp_path: Path) -> None:
    if _typer_requires_pydantic():
        pytest.skip(f"typer {metadata.version('typer')} requires pydantic: this is the PC install, not the robot's")
    assert _robot_run_imports(tmp_path)["loaded"] == []
