"""Where the analysis tests find the public Vicon exports: ``../shared/data/vicon-public`` beside the repo."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PUBLIC = REPO.parent / "shared" / "data" / "vicon-public"


def public(name: str) -> Path:
    """The public export ``name``; the test is skipped when the exports are not there."""
    p = PUBLIC / name
    if not p.exists():
        pytest.skip(f"public Vicon exports not found at {PUBLIC} (they live in ../shared beside the repo)")
    return p
