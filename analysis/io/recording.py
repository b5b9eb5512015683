"""A Vicon export of either format: C3D (`rimless.analysis.io.c3d`) or CSV (`rimless.analysis.io.vicon_csv`)."""

from __future__ import annotations

from pathlib import Path

from rimless.analysis.io.c3d import read_c3d
from rimless.analysis.io.vicon_csv import read_vicon_csv
from rimless.analysis.io.vicon_file import ViconFile

__all__ = ["read_recording"]


def read_recording(path: str | Path) -> ViconFile:
    """A Vicon export: ``.c3d`` by `read_c3d`, anything else as Vicon CSV."""
    if str(path).lower().endswith(".c3d"):
        return read_c3d(path)
    return read_vicon_csv(path)
