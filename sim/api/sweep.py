"""`sweep`: every branch of every grid point, as a pandas DataFrame (`rimless sim sweep` without the files)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from rimless.errors import ParameterError, RunFailure
from rimless.sim.api.wheel import MODELS, Wheel

__all__ = ["sweep"]


def _grid_names() -> dict[str, tuple[str, str]]:
    from rimless.sim.studies.sweep import GRID_PARAMETERS

    return GRID_PARAMETERS


def sweep(
    grid: Mapping[str, Sequence[float]],
    *,
    wheel: Wheel | None = None,
    model: str | Sequence[str] = ("er", "ve"),
    scheduler: str = "sync",
    workers: int | None = None,
    cache_dir: str | Path | None = None,
    start_slope_rad: float | None = None,
    guesses: int = 14,
    to_end: bool = False,
    power: Any = None,
    progress: Callable[[int, int], None] | None = None,
) -> Any:
    """Every period-1 gait at the start slope of each grid point, followed down in slope; one row per branch.

    grid : {name: values}, names among k (N/m), c (N s/m), hub_mass_kg, leg_mass_kg, inertia_kg_m2; every
        combination is a point (the other parameters are the wheel's).
    wheel : the base wheel (parameters, backend, rtol); default `Wheel()` (Table 1, compiled path).
    model : "er", "ve" or a list of them.
    scheduler : "sync" (this process, the default here), "local" (a local Dask cluster) or "tcp://HOST:PORT".
    cache_dir : where finished points are cached (keyed by parameters, options and the code's hash); None: none.
    start_slope_rad : where the gaits are searched (default: the wheel's slope).

    Returns a pandas DataFrame with the columns of `rimless sim sweep`'s table (critical_slope_rad, reason,
    system CoT columns, ...); `df.attrs` holds the sweep's facts (points computed and cached, seconds, workers).
    Raises RunFailure when no grid point has a gait."""
    import pandas as pd

    from rimless.sim.model.electrical import ClutchPower
    from rimless.sim.studies.sweep import SweepOptions, grid_points, run_sweep
    from rimless.sim.studies.system_cot import sweep_system_cot

    wheel = wheel or Wheel()
    models = [model] if isinstance(model, str) else list(model)
    for m in models:
        if m not in MODELS or m == "rigid":
            raise ParameterError(f"model must be er or ve (or a list of them), got {m!r}")
    known = _grid_names()
    unknown = [n for n in grid if n not in known]
    if unknown:
        raise ParameterError(f"grid: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(known)}")
    values = {n: [float(v) for v in vs] for n, vs in grid.items()} or {"k": [wheel.params.k]}
    options = SweepOptions(
        backend=wheel.backend,
        rtol=wheel.rtol,
        start_slope_rad=wheel.params.slope_rad if start_slope_rad is None else float(start_slope_rad),
        n_guesses=guesses,
        to_end=to_end,
    )
    points = grid_points(wheel.params, models, values, [wheel.params.mass_model])
    res = run_sweep(
        points,
        options,
        scheduler=scheduler,
        workers=workers,
        cache_dir=Path(cache_dir) if cache_dir is not None else None,
        progress=progress,
    )
    rows = sweep_system_cot(res.rows, res.points, power or ClutchPower(), backend=wheel.backend, rtol=wheel.rtol)
    if not any(r.get("branch") for r in rows):
        raise RunFailure(f"no grid point has a period-1 gait at {options.start_slope_rad:.5f} rad")
    frame = pd.DataFrame(rows)
    frame.attrs.update(
        {
            "grid": values,
            "models": models,
            "options": dict(options.__dict__),
            "computed": res.computed,
            "cached": res.cached,
            "seconds": res.seconds,
            "scheduler": scheduler,
            "workers": res.workers,
        }
    )
    return frame
