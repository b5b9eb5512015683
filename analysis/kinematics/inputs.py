"""The inputs of the commands that take trials: a Parquet trial is read, a Vicon export imported; a refused
file becomes a row with the reason, never an exception."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rimless.analysis.io.trial import read_trial, slope_ci_deg
from rimless.analysis.kinematics.build import import_trial
from rimless.errors import UserError

__all__ = ["InputRow", "load_input", "trial_warnings"]


@dataclass
class InputRow:
    """What became of one input file."""

    file: str
    kind: str  # "parquet" or "csv"
    status: str  # "imported", "read" or "refused"
    reason: str | None = None
    trial: Any = None
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "file": self.file,
            "kind": self.kind,
            "status": self.status,
            "reason": self.reason,
            "warnings": self.warnings,
        }
        if self.trial is not None:
            m = self.trial.meta
            d.update(
                frames=m.n_frames,
                rate_hz=m.rate_hz,
                slope_deg=m.slope_deg,
                slope_source=m.slope_source,
                slope_ci_deg=slope_ci_deg(m.slope_ci_rad),
                up_axis=m.up_axis,
                parameters=None if m.parameters is None else [dict(p) for p in m.parameters],
                hub_source=m.hub_source,
                gap_frames=m.n_gap_frames,
                interpolated_frames=m.n_interpolated_frames,
                steps=int(self.trial.step_period_s.size),
            )
        return d


def trial_warnings(trial: Any) -> list[str]:
    """The notes and warnings of a trial worth showing beside it (steps refused, gaps, interpolation)."""
    m = trial.meta
    w = list(m.notes)
    if m.step_refused:
        w.append(f"steps not detected: {m.step_refused}")
    if m.n_gap_frames:
        w.append(f"{m.n_gap_frames} frame(s) without a hub (gaps)")
    if m.n_interpolated_frames:
        w.append(
            f"{m.n_interpolated_frames} frame(s) interpolated over gaps up to {m.max_gap_s * 1e3:g} ms "
            "(not used in the RMS)"
        )
    return w


def load_input(path: Path, import_kwargs: dict[str, Any] | None = None) -> InputRow:
    """Read a Parquet trial, or import a Vicon CSV; a refused file gives status ``refused`` with the reason."""
    kind = "parquet" if path.suffix.lower() == ".parquet" else "csv"
    try:
        trial = read_trial(path) if kind == "parquet" else import_trial(path, **(import_kwargs or {}))
    except UserError as err:
        msg = str(err)
        return InputRow(str(path), kind, "refused", msg if str(path) in msg else f"{path}: {msg}")
    except OSError as err:
        return InputRow(str(path), kind, "refused", f"{path}: {err}")
    return InputRow(str(path), kind, "read" if kind == "parquet" else "imported", None, trial, trial_warnings(trial))
