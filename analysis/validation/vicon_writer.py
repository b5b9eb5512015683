"""A small Vicon CSV writer for the truth models: Tracker ``Objects`` and ``Trajectories`` (markers) sections.

Written apart from the reader in `rimless.analysis.io` (it imports nothing from `rimless.analysis`), so that a truth
recording does not share the reader's assumptions. Values are given in SI (m, rad) and written in the units the
section's units row names (mm for positions, rad for angles). Each section: the kind line, the rate, the names
row, the components row, the units row, then ``Frame, Sub Frame`` and the values (a non-finite value is an empty
cell: an occlusion).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["section_text", "objects_section", "markers_section", "write"]


def _cell(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.6f}"


def section_text(
    kind: str,
    rate: str,
    groups: list[tuple[str, np.ndarray]],
    *,
    comps: tuple[str, ...],
    units: tuple[str, ...],
    scale: tuple[float, ...],
    first_frame: int = 1,
) -> list[str]:
    """Lines of one section; ``groups`` = (name-row text, (n, len(comps)) values in SI)."""
    names = ["", ""]
    comp = ["Frame", "Sub Frame"]
    unit = ["", ""]
    cols = []
    for name, arr in groups:
        names += [name] + [""] * (len(comps) - 1)
        comp += list(comps)
        unit += list(units)
        cols.append(np.asarray(arr, float) / np.asarray(scale))
    data = np.concatenate(cols, axis=1)
    lines = [kind, rate, ",".join(names), ",".join(comp), ",".join(unit)]
    for i in range(data.shape[0]):
        lines.append(",".join([str(first_frame + i), "0", *(_cell(v) for v in data[i])]))
    return lines


def objects_section(objects: dict[str, np.ndarray], rate: str = "100") -> list[str]:
    """A Tracker ``Objects`` section: per object (n, 6) = helical rotation vector (rad), origin (m)."""
    return section_text(
        "Objects",
        rate,
        [(f"Global Angle {k}:{k}", v) for k, v in objects.items()],
        comps=("RX", "RY", "RZ", "TX", "TY", "TZ"),
        units=("rad",) * 3 + ("mm",) * 3,
        scale=(1.0,) * 3 + (1e-3,) * 3,
    )


def markers_section(markers: dict[str, np.ndarray], rate: str = "100") -> list[str]:
    """A ``Trajectories`` section: per marker (n, 3) positions (m), written in mm."""
    return section_text(
        "Trajectories",
        rate,
        list(markers.items()),
        comps=("X", "Y", "Z"),
        units=("mm",) * 3,
        scale=(1e-3,) * 3,
    )


def write(path: str | Path, *sections: list[str]) -> str:
    """Write the sections (a blank line between them) to ``path``; returns the path."""
    text = "\n".join("\n".join(s) + "\n" for s in sections)
    with open(path, "w", newline="") as f:
        f.write(text)
    return str(path)
