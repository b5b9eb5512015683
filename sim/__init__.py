"""The hybrid simulator of the rigid, viscoelastic and energy-recycling rimless wheels.

The public API (docs/api.md), imported lazily so that `import rimless.sim` stays light:

- `Wheel(params=WheelParams(), model="er", *, backend="auto", rtol=1e-10)`: `fixed_point()`, `gaits()`,
  `simulate(n_steps)`, `critical_slope()`, `branches()`,
  `basin()`, `sensitivity()`, `mfpt(terrain_sd_deg)`, `map(z)`, `jacobian(z)`, `with_params(**changes)`;
- `WheelParams` (paper Table 1 by default, SI fields) and `load_params(path)` (TOML);
- `Model` = Literal["rigid", "ve", "er"], `Backend` = Literal["auto", "fast", "reference"];
- `sweep(grid, model=..., scheduler=...)`: a pandas DataFrame of every branch of every grid point;
- the result objects `FixedPointResult`, `GaitsResult`, `CriticalSlopeResult`, `Simulation`, `BranchesResult`,
  `BasinResult`, `SensitivityResult`, `MfptResult` (`to_dict()` gives the matching command's `--json` object);
- `ClutchPower` (clutch and electronics power for the system cost of transport), `StepFailure`, `RunFailure`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rimless.lazy import lazy_exports

if TYPE_CHECKING:
    from rimless.errors import RunFailure
    from rimless.sim.api.results import (
        BasinResult,
        BranchesResult,
        CriticalSlopeResult,
        FixedPointResult,
        GaitsResult,
        MfptResult,
        SensitivityResult,
        Simulation,
    )
    from rimless.sim.api.sweep import sweep
    from rimless.sim.api.wheel import Backend, Model, Wheel
    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.model.failures import StepFailure
    from rimless.sim.model.params import WheelParams, load_params

_LAZY = {
    "Wheel": "rimless.sim.api.wheel",
    "Model": "rimless.sim.api.wheel",
    "Backend": "rimless.sim.api.wheel",
    "sweep": "rimless.sim.api.sweep",
    "FixedPointResult": "rimless.sim.api.results",
    "GaitsResult": "rimless.sim.api.results",
    "CriticalSlopeResult": "rimless.sim.api.results",
    "Simulation": "rimless.sim.api.results",
    "BranchesResult": "rimless.sim.api.results",
    "BasinResult": "rimless.sim.api.results",
    "SensitivityResult": "rimless.sim.api.results",
    "MfptResult": "rimless.sim.api.results",
    "WheelParams": "rimless.sim.model.params",
    "load_params": "rimless.sim.model.params",
    "ClutchPower": "rimless.sim.model.electrical",
    "StepFailure": "rimless.sim.model.failures",
    "RunFailure": "rimless.errors",
}

__all__ = [
    "Backend",
    "BasinResult",
    "BranchesResult",
    "ClutchPower",
    "CriticalSlopeResult",
    "FixedPointResult",
    "GaitsResult",
    "MfptResult",
    "Model",
    "RunFailure",
    "SensitivityResult",
    "Simulation",
    "StepFailure",
    "Wheel",
    "WheelParams",
    "load_params",
    "sweep",
]


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)
