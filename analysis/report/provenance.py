"""What a report was made from, and no path of the machine it was made on.

`Provenance`: the rimless version (`rimless.__version__`, the one version source), the command line (or the
Python function), the date (UTC), the wheel file (as given, or its name when given as an absolute path) and
every input file by name with its SHA-256 content hash, so that a report can be matched to its data without
naming a folder of the machine it was built on. `PathScrubber` rewrites the messages a report shows (refusal
reasons, warnings, the wheel file's name in a parameter's basis) so that no absolute path is left in the HTML,
the CSV or the figures: a known input becomes its name, any other absolute path its last component.
"""

from __future__ import annotations

import hashlib
import re
import shlex
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

__all__ = ["InputFile", "Provenance", "PathScrubber", "shown_file", "sha256_of", "command_text", "make_provenance"]

#: An absolute path inside a message: POSIX (``/a/b``, not ``rad/s``: no word character before the slash) or
#: Windows (``C:\\a\\b``, ``C:/a``), up to the next space, quote, bracket or separator of a message.
_ABSOLUTE = re.compile(r"(?<![\w~.\-/:])(?:[A-Za-z]:[\\/]|/)(?:[^\s:;,'\"()<>\[\]{}]+)")


def _is_absolute(text: str) -> bool:
    return PurePosixPath(text).is_absolute() or PureWindowsPath(text).is_absolute() or text.startswith("~")


def _name(text: str) -> str:
    """The last component of a POSIX or Windows path (``C:\\data\\run1.csv`` -> ``run1.csv``)."""
    return PureWindowsPath(text).name if "\\" in text else PurePosixPath(text).name


def shown_file(path: str | Path) -> str:
    """A file as the report names it: as given when relative and inside its folder (no ``..``), else its name."""
    text = str(path)
    if _is_absolute(text) or ".." in Path(text).parts:
        return _name(text)
    return text


def sha256_of(path: str | Path) -> str:
    """The SHA-256 of a file's bytes (hex), or ``""`` when it cannot be read."""
    try:
        with open(path, "rb") as fh:
            return hashlib.file_digest(fh, "sha256").hexdigest()
    except OSError:
        return ""


def command_text(argv: Sequence[str] | None, api: str) -> str:
    """The command line as shown (``rimless trials report a.csv --out rep``: absolute paths shortened to their
    names, ``--opt=/abs/path`` too), or ``Python API: <api>`` when the report was not made by a command."""
    if argv is None:
        return f"Python API: {api}"
    shown = []
    for arg in argv:
        opt, eq, value = arg.partition("=")
        if eq and opt.startswith("--"):
            shown.append(f"{opt}={shown_file(value) if _is_absolute(value) else value}")
        else:
            shown.append(shown_file(arg) if _is_absolute(arg) else arg)
    return shlex.join(shown)


@dataclass(frozen=True)
class InputFile:
    """One file the report read: its role (``trial``, ``wheel file``, ``robot log``), name and content hash."""

    role: str
    name: str
    sha256: str
    size_bytes: int

    def to_dict(self) -> dict[str, Any]:
        return {"role": self.role, "name": self.name, "sha256": self.sha256, "size_bytes": self.size_bytes}


@dataclass
class Provenance:
    """What the report was made from (see the module doc); `to_dict` is the JSON key ``provenance``."""

    version: str
    command: str
    date_utc: str
    wheel_file: str | None
    files: list[InputFile] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "rimless_version": self.version,
            "command": self.command,
            "date_utc": self.date_utc,
            "wheel_file": self.wheel_file,
            "files": [f.to_dict() for f in self.files],
        }


def _input_file(role: str, path: Path) -> InputFile:
    try:
        size = path.stat().st_size
    except OSError:
        size = -1
    return InputFile(role, shown_file(path) if role == "wheel file" else path.name, sha256_of(path), size)


def make_provenance(
    files: Sequence[Path],
    *,
    argv: Sequence[str] | None,
    api: str,
    wheel_path: Path | None,
    robot_logs: Iterable[Path] = (),
    now: datetime | None = None,
) -> Provenance:
    """The report's provenance: every trial input, the wheel file and the robot logs hashed (read once each)."""
    from rimless import __version__

    found = [_input_file("trial", Path(p)) for p in files]
    if wheel_path is not None:
        found.append(_input_file("wheel file", Path(wheel_path)))
    found += [_input_file("robot log", Path(p)) for p in robot_logs]
    date = (now or datetime.now(UTC)).strftime("%Y-%m-%d %H:%M:%S UTC")
    return Provenance(
        __version__,
        command_text(argv, api),
        date,
        None if wheel_path is None else shown_file(wheel_path),
        found,
    )


class PathScrubber:
    """Rewrite text for the report: each known path (as given and resolved) becomes its shown name, the report's
    own folder disappears (its files are named relative to the page), and any other absolute path is shortened
    to its last component."""

    def __init__(self, files: Iterable[str | Path] = (), folders: Iterable[str | Path] = ()) -> None:
        pairs: dict[str, str] = {}
        for f in files:
            for form in _forms(f):
                if _is_absolute(form) or "/" in form or "\\" in form:
                    pairs[form] = Path(f).name
        for d in folders:
            for form in _forms(d):
                pairs[form.rstrip("/") + "/"] = ""
        # longest first: a file inside a known folder is replaced whole
        self._pairs = sorted(pairs.items(), key=lambda kv: -len(kv[0]))

    def __call__(self, text: str | None) -> str:
        if not text:
            return ""
        out = str(text)
        for old, new in self._pairs:
            out = out.replace(old, new)
        return _ABSOLUTE.sub(lambda m: _name(m.group(0).rstrip(".")) + ("." if m.group(0).endswith(".") else ""), out)


def _forms(path: str | Path) -> list[str]:
    """A path as given and resolved (both may appear in a message)."""
    forms = [str(path)]
    try:
        forms.append(str(Path(path).resolve()))
    except (OSError, RuntimeError):
        pass
    return [f for f in dict.fromkeys(forms) if f and f != "."]
