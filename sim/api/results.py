"""Result objects of the public API: the command's `--json` object with attribute access, a short repr and a
notebook view.

Every result holds `data`, the same plain dict the matching command prints with `--json` (its keys are the
contract: add, never rename), and `to_dict()` returns a deep copy of it. Attribute access reads the keys
(`res.step_period_s`); `repr` is a few lines; `_repr_html_` a small table in a notebook.
"""

from __future__ import annotations

import copy
import html
import math
from collections.abc import Iterator, Mapping
from typing import Any

__all__ = [
    "Result",
    "FixedPointResult",
    "GaitsResult",
    "CriticalSlopeResult",
    "Simulation",
    "BranchesResult",
    "BasinResult",
    "SensitivityResult",
    "MfptResult",
]


def _fmt(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)


class Result(Mapping[str, Any]):
    """A command's JSON object as a read-only mapping with attribute access."""

    #: keys shown by repr and the notebook table, in order (those present)
    headline: tuple[str, ...] = ()

    def __init__(self, data: dict[str, Any]) -> None:
        self.data = data

    @property
    def title(self) -> str:
        """What the result is about, in a few words."""
        return "result"

    def to_dict(self) -> dict[str, Any]:
        """The same keys and values as the command's `--json` object (a deep copy)."""
        return copy.deepcopy(self.data)

    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.data)

    def __len__(self) -> int:
        return len(self.data)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name == "data":
            raise AttributeError(name)
        try:
            return self.data[name]
        except KeyError:
            raise AttributeError(f"{type(self).__name__} has no key or attribute {name!r}") from None

    def __dir__(self) -> list[str]:
        return sorted(set(super().__dir__()) | set(self.data))

    def _rows(self) -> list[tuple[str, str]]:
        return [(k, _fmt(self.data[k])) for k in self.headline if k in self.data]

    def __repr__(self) -> str:
        body = ", ".join(f"{k}={v}" for k, v in self._rows())
        return f"{type(self).__name__}({self.title}: {body}; {len(self.data)} keys, .to_dict())"

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in self._rows())
        return f"<table><caption>{html.escape(type(self).__name__)}: {html.escape(self.title)}</caption>{rows}</table>"


class FixedPointResult(Result):
    """A period-1 gait (`rimless sim fixed-point --json`)."""

    headline = (
        "theta_plus_rad",
        "theta_dot_plus_rad_s",
        "step_period_s",
        "max_abs_eigenvalue",
        "stable",
        "contact_valid",
        "found_by",
    )

    @property
    def title(self) -> str:
        return f"{self.data['model']} wheel at {self.data['slope_deg']:.4f} deg"

    @property
    def z(self) -> Any:
        """The section point (theta+ rad, theta'+ rad/s) as a numpy array."""
        import numpy as np

        return np.array([self.data["theta_plus_rad"], self.data["theta_dot_plus_rad_s"]])


class GaitsResult(Result):
    """Every period-1 gait at one slope (`rimless sim gaits --json`); `gaits` lists them."""

    @property
    def title(self) -> str:
        return (
            f"{len(self.data['gaits'])} gait(s) of the {self.data['model']} wheel at {self.data['slope_rad']:.5f} rad"
        )

    def _rows(self) -> list[tuple[str, str]]:
        return [
            (
                f"gait {i + 1}",
                f"theta'+ {g['theta_dot_plus_rad_s']:.5f} rad/s, period {g['step_period_s']:.4f} s, "
                f"max|eig| {g['max_abs_eigenvalue']:.4f}, {'stable' if g['stable'] else 'unstable'}, "
                f"{'valid' if g['contact_valid'] else 'contact NOT valid'}",
            )
            for i, g in enumerate(self.data["gaits"])
        ]

    def __repr__(self) -> str:
        lines = [f"GaitsResult({self.title})"] + [f"  {k}: {v}" for k, v in self._rows()]
        return "\n".join(lines)

    def to_frame(self) -> Any:
        """One row per gait (pandas DataFrame; nested keys left out)."""
        import pandas as pd

        flat = [{k: v for k, v in g.items() if not isinstance(v, (dict, list))} for g in self.data["gaits"]]
        return pd.DataFrame(flat)


class CriticalSlopeResult(Result):
    """A critical slope (`rimless sim critical-slope --json`): compliant models or the rigid closed form."""

    headline = ("critical_slope_deg", "critical_slope_rad", "cot", "reason", "method", "located_to_rad")

    @property
    def title(self) -> str:
        return f"{self.data['model']} wheel"


class Simulation(Result):
    """N steps of a walk (`rimless sim gait --json`) and the sampled trajectory (`trajectory`, SI columns)."""

    headline = ("start", "theta_dot_plus_rad_s", "steps_done", "steps_requested", "failure")

    def __init__(self, data: dict[str, Any], trajectory: Any) -> None:
        super().__init__(data)
        self.trajectory = trajectory

    @property
    def title(self) -> str:
        return f"{self.data['model']} wheel at {math.degrees(self.data['slope_rad']):.4f} deg"

    def to_frame(self) -> Any:
        """The samples as a pandas DataFrame (t_s, step, phase, coordinates, CoM height, ...)."""
        return self.trajectory.to_frame()

    def plot(self, path: Any = None, *, forces: bool = False) -> Any:
        """The gait figure (matplotlib Figure); written to `path` (.png, .pdf, .svg) when given."""
        from rimless.sim.studies.figures import plot_gait, save_figure

        fig = plot_gait(self.trajectory, None, forces=forces)
        if path is not None:
            save_figure(fig, path)
        return fig


class BranchesResult(Result):
    """Every gait at the start slope followed down in slope (`rimless sim sweep`'s rows for one wheel)."""

    @property
    def title(self) -> str:
        return f"{len(self.data['branches'])} branch(es) of the {self.data['model']} wheel"

    def __repr__(self) -> str:
        lines = [f"BranchesResult({self.title})"]
        for b in self.data["branches"]:
            crit = b.get("critical_slope_deg")
            lines.append(
                f"  {b['branch']}: ends by {b.get('reason')}"
                + (f" at {crit:.4f} deg" if isinstance(crit, float) and crit == crit else "")
            )
        return "\n".join(lines)

    def to_frame(self) -> Any:
        """One row per branch (pandas DataFrame)."""
        import pandas as pd

        return pd.DataFrame(self.data["branches"])


class BasinResult(Result):
    """The basin of attraction (`rimless sim basin --json`) and every grid point (`points`, `to_frame()`)."""

    headline = (
        "basin_area_rad2_per_s",
        "basin_area_fraction",
        "nearest_failure_distance",
        "grid",
        "steps",
    )

    def __init__(self, data: dict[str, Any], points: Any) -> None:
        super().__init__(data)
        self.points = points

    @property
    def title(self) -> str:
        return f"{self.data['model']} wheel at {self.data['slope_deg']:.4f} deg"

    def to_frame(self) -> Any:
        """One row per grid point: theta_plus_rad, theta_dot_plus_rad_s, fate, steps, distance_scaled."""
        import pandas as pd

        return pd.DataFrame(self.points)


class SensitivityResult(Result):
    """The gait sensitivity norm (`rimless sim sensitivity --json`): `slope` and `push` blocks."""

    @property
    def title(self) -> str:
        return f"{self.data['model']} wheel at {self.data['slope_deg']:.4f} deg"

    def _rows(self) -> list[tuple[str, str]]:
        return [
            (
                f"GSN {name} (per {self.data[name]['unit']})",
                f"{self.data[name]['gsn']:.6g}, simulated {self.data[name]['simulated']['gsn']:.6g} "
                f"(relative difference {self.data[name]['relative_difference']:.2g})",
            )
            for name in ("slope", "push")
        ]


class MfptResult(Result):
    """The mean first-passage time on rough terrain (`rimless sim mfpt --json`)."""

    headline = ("mfpt_steps", "mfpt_ci_steps", "mfpt_discretisation_error_steps", "method", "terrain_sd_deg")

    @property
    def title(self) -> str:
        return f"{self.data['model']} wheel at {self.data['slope_deg']:.4f} deg"
