"""`Wheel`: one rimless wheel (parameters, model, computational path) and everything the simulator does with it.

    >>> from rimless.sim import Wheel
    >>> fp = Wheel(model="er").fixed_point()      # the period-1 gait at Table 1
    >>> fp.step_period_s, fp.max_abs_eigenvalue

Each method calls the same library function as the matching `rimless sim` command and returns a result whose
`to_dict()` is that command's `--json` object. Units are SI (rad, rad/s, s, N/m); the slope is `slope_rad`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, get_args

from rimless.errors import ParameterError
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
from rimless.sim.model.params import WheelParams, load_params
from rimless.sim.model.uncertain import WheelInput, read_wheel_input, wheel_input_for

__all__ = ["Wheel", "Model", "Backend", "MODELS"]

#: The three wheels: rigid legs (Coleman's closed form), viscoelastic legs, energy-recycling (spring-clutch) legs.
Model = Literal["rigid", "ve", "er"]
MODELS: tuple[str, ...] = get_args(Model)
#: The computational path: "fast" (compiled, numba), "reference" (scipy's DOP853), "auto" (fast where possible).
Backend = Literal["auto", "fast", "reference"]

DEFAULT_RTOL = 1e-10  # the CLI's default --rtol


def _check_model(model: str, allowed: tuple[str, ...] = MODELS) -> str:
    if model not in allowed:
        raise ParameterError(f"model must be one of {', '.join(allowed)}, got {model!r}")
    return model


class Wheel:
    """A rimless wheel: `params` (paper Table 1 by default), `model` ("er", "ve" or "rigid"), and the path.

    Parameters
    ----------
    params : WheelParams, default Table 1 (`WheelParams()`); a path to a TOML file is read with `load_params`.
    model : "er" (energy-recycling, default), "ve" (viscoelastic) or "rigid".
    backend : "auto" (compiled where possible), "fast" or "reference" (scipy).
    rtol : relative tolerance of the integrator (atol = rtol / 100).
    uncertainty : 1-sigma uncertainties of parameters (field names or the paper's symbols, e.g. ``{"I_c": 0.004}``;
        0 = exact) over those of a wheel file (``{value, sd}`` tables) or the defaults
        (`rimless.sim.model.uncertain.DEFAULT_SD`, assumed, not measured); the trial analysis carries them.
    **changes : fields of WheelParams to change, e.g. ``Wheel(stiffness_n_per_m=2500)``.
    """

    def __init__(
        self,
        params: WheelParams | str | Path | None = None,
        model: Model = "er",
        *,
        backend: Backend = "auto",
        rtol: float = DEFAULT_RTOL,
        uncertainty: Mapping[str, float] | None = None,
        **changes: Any,
    ) -> None:
        from_file = None
        if isinstance(params, (str, Path)):
            from_file = read_wheel_input(params) if Path(params).is_file() else None
            params = from_file.params if from_file is not None else load_params(params)
        base = params if params is not None else WheelParams()
        if not isinstance(base, WheelParams):
            raise ParameterError(f"params must be a WheelParams or a TOML file's path, got {type(base).__name__}")
        self.params: WheelParams = base.replace(**changes) if changes else base
        #: every parameter's value, 1-sigma uncertainty and source (what the trial analysis holds and carries)
        #: (a value given in ``changes`` is the caller's: source "wheel" even at Table 1's value)
        self.input: WheelInput = wheel_input_for(self.params, from_file, uncertainty, stated=tuple(changes))
        self.uncertainty: dict[str, float] = {n: e.sd for n, e in self.input.entries.items()}
        self.model: Model = _check_model(model)  # type: ignore[assignment]
        if backend not in get_args(Backend):
            raise ParameterError(f"backend must be one of {', '.join(get_args(Backend))}, got {backend!r}")
        if not (isinstance(rtol, float | int) and 1e-14 <= rtol <= 1e-3):
            raise ParameterError(f"rtol must be a number in [1e-14, 1e-3], got {rtol!r}")
        self.backend: Backend = backend
        self.rtol = float(rtol)
        self._map: Any = None

    # -- construction
    @classmethod
    def from_input(
        cls,
        wheel_input: WheelInput,
        model: Model = "er",
        *,
        params: WheelParams | None = None,
        backend: Backend = "auto",
        rtol: float = DEFAULT_RTOL,
    ) -> Wheel:
        """The wheel a wheel input describes (`rimless.sim.model.uncertain.WheelInput`: each parameter's value,
        1-sigma uncertainty and source, and the fields to be fitted) as the input the trial analysis holds and
        carries (`input`, `uncertainty`); simulated at ``params`` when given (e.g. a leg test's planned values),
        else at the input's values."""
        w = cls(wheel_input.params if params is None else params, model, backend=backend, rtol=rtol)
        w.input = wheel_input
        w.uncertainty = {n: e.sd for n, e in wheel_input.entries.items()}
        return w

    def with_params(self, **changes: Any) -> Wheel:
        """A copy with some parameters changed (validated), e.g. ``wheel.with_params(slope_rad=0.03)``."""
        w = Wheel(self.params.replace(**changes), self.model, backend=self.backend, rtol=self.rtol)
        # the unchanged parameters keep their uncertainty; the ones given are the caller's
        w.input = wheel_input_for(w.params, self.input, stated=tuple(changes))
        w.uncertainty = {n: e.sd for n, e in w.input.entries.items()}
        return w

    def with_model(self, model: Model) -> Wheel:
        """The same wheel and path with another model."""
        w = Wheel(self.params, model, backend=self.backend, rtol=self.rtol)
        w.input, w.uncertainty = self.input, dict(self.uncertainty)
        return w

    def __repr__(self) -> str:
        p = self.params
        extra = f", F_c={p.guide_friction_n:g} N" if p.guide_friction_n else ""
        return (
            f"Wheel(model={self.model!r}, slope={p.slope_rad:.5g} rad ({p.slope_deg:.4g} deg), "
            f"k={p.k:g} N/m, c={p.c:g} N s/m, mass_model={p.mass_model!r}{extra}, backend={self.backend!r}, "
            f"rtol={self.rtol:g})"
        )

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Wheel) and (self.params, self.model, self.backend, self.rtol) == (
            other.params,
            other.model,
            other.backend,
            other.rtol,
        )

    def __hash__(self) -> int:
        return hash((self.params, self.model, self.backend, self.rtol))

    def compliant_model(self, what: str) -> str:
        """The model, when it is a compliant one ("er" or "ve"); a ParameterError naming `what` for "rigid"."""
        if self.model == "rigid":
            raise ParameterError(
                f"{what} needs a compliant model (model='er' or 've'); the rigid wheel has the closed form of "
                "critical_slope()"
            )
        return self.model

    # -- the Poincaré map
    @property
    def poincare_map(self) -> Any:
        """The Poincaré map on the section z = (theta+ rad, theta'+ rad/s), built once (compiled or reference)."""
        if self._map is None:
            from rimless.sim.step.backend import make_map

            self._map = make_map(
                self.params, self.compliant_model("the Poincaré map"), backend=self.backend, rtol=self.rtol
            )
        return self._map

    def map(self, z: Any) -> Any:
        """P(z): the section point one step later (numpy array: theta+ rad, theta'+ rad/s).

        Raises `rimless.sim.model.failures.StepFailure` (with a `reason`) when the step fails (stall, ...)."""
        import numpy as np

        return np.asarray(self.poincare_map(np.asarray(z, dtype=float)), dtype=float)

    def jacobian(self, z: Any) -> Any:
        """dP/dz at z (2x2): exact (variational equations) on the compiled path, else central differences."""
        import numpy as np

        from rimless.sim.step.backend import jacobian_factory

        jf = jacobian_factory(self.backend)
        jac = jf(self.poincare_map) if jf else self.poincare_map.jacobian
        return np.asarray(jac(np.asarray(z, dtype=float)), dtype=float)

    # -- studies (each is a `rimless sim` command)
    def fixed_point(
        self,
        *,
        theta_dot_guess: float | None = None,
        theta_plus_guess: float | None = None,
        gait: int | None = None,
        strict_contact: bool = False,
        power: Any = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> FixedPointResult:
        """The period-1 gait (`rimless sim fixed-point`): Newton from the default guess (or the gaits search when
        that fails), or from the guess given (rad, rad/s), or gait number `gait` of `gaits()`.

        power: a `rimless.sim.model.electrical.ClutchPower` for the system cost of transport (default: none).
        Raises `RunFailure` when no gait is found."""
        from rimless.sim.studies.gaits import fixed_point_study

        out = fixed_point_study(
            self.params,
            self.compliant_model("fixed_point()"),
            theta_dot_guess=theta_dot_guess,
            theta_plus_guess=theta_plus_guess,
            gait=gait,
            strict_contact=strict_contact,
            backend=self.backend,
            rtol=self.rtol,
            progress=progress,
            power=power,
        )
        return FixedPointResult(out)

    def gaits(
        self,
        *,
        theta_dot_min: float = 0.8,
        theta_dot_max: float = 6.0,
        guesses: int = 14,
        progress: Callable[[int, int], None] | None = None,
    ) -> GaitsResult:
        """Every period-1 gait at the wheel's slope (`rimless sim gaits`): theta'+ guesses in [min, max] rad/s."""
        from rimless.sim.studies.gaits import gait_scan

        out = gait_scan(
            self.params,
            self.compliant_model("gaits()"),
            theta_dot_min=theta_dot_min,
            theta_dot_max=theta_dot_max,
            guesses=guesses,
            backend=self.backend,
            rtol=self.rtol,
            progress=progress,
        )
        return GaitsResult(out)

    def simulate(
        self,
        n_steps: int = 6,
        *,
        theta_dot: float | None = None,
        theta_plus_rad: float | None = None,
        forces: bool = False,
        sample_dt_s: float = 1e-3,
        progress: Callable[[int], None] | None = None,
    ) -> Simulation:
        """`n_steps` steps (`rimless sim gait`) from the fixed point, or from theta'+ = `theta_dot` rad/s (and
        theta+ = `theta_plus_rad`, default -alpha/2) just after an impact; samples every `sample_dt_s` s.

        A walk that fails early is a result: `failure` says why, `steps_done` how far it got."""
        from rimless.sim.studies.walk import simulate_walk

        traj, out = simulate_walk(
            self.params,
            self.compliant_model("simulate()"),
            steps=n_steps,
            theta_dot=theta_dot,
            theta_plus_rad=theta_plus_rad,
            forces=forces,
            sample_dt_s=sample_dt_s,
            backend=self.backend,
            rtol=self.rtol,
            progress=progress,
        )
        return Simulation(out, traj)

    def critical_slope(
        self,
        *,
        step_rad: float = 0.001,
        start_slope_rad: float | None = None,
        theta_dot_guess: float | None = None,
        theta_plus_guess: float | None = None,
        gait: int | None = None,
        strict_contact: bool = False,
        power: Any = None,
        progress: Callable[[float], None] | None = None,
        gaits_progress: Callable[[int, int], None] | None = None,
    ) -> CriticalSlopeResult:
        """The critical slope (`rimless sim critical-slope`): the paper's Algorithm 1 from `start_slope_rad` (the
        wheel's slope by default) down in steps of `step_rad`, following the branch of the gait Newton finds from
        the default guess (or the guess given, or gait number `gait` at the start slope), and the refined end of
        the branch with its reason; for model "rigid", Coleman's closed form (paper convention M = m_H, and the
        eight-leg-consistent one). progress(slope_rad): the continuation's current slope."""
        from rimless.sim.studies.gaits import critical_slope_study

        if self.model == "rigid":
            return CriticalSlopeResult(critical_slope_study(self.params, "rigid", power=power))
        out = critical_slope_study(
            self.params,
            self.model,
            step_rad=step_rad,
            start_slope_rad=self.params.slope_rad if start_slope_rad is None else start_slope_rad,
            theta_dot_guess=theta_dot_guess,
            theta_plus_guess=theta_plus_guess,
            gait=gait,
            strict_contact=strict_contact,
            backend=self.backend,
            rtol=self.rtol,
            gaits_progress=gaits_progress,
            progress=progress,
            power=power,
        )
        return CriticalSlopeResult(out)

    def branches(
        self,
        *,
        start_slope_rad: float | None = None,
        guesses: int = 14,
        to_end: bool = False,
        progress: Callable[[str], None] | None = None,
    ) -> BranchesResult:
        """Every period-1 gait at `start_slope_rad` (the wheel's slope by default) followed down in slope by
        pseudo-arclength continuation to its first special point (`to_end`: to the end of the branch); one row
        per branch with the keys of `rimless sim sweep`'s table."""
        from rimless.sim.continuation.branches import trace_gait_branches

        start = self.params.slope_rad if start_slope_rad is None else float(start_slope_rad)
        found = trace_gait_branches(
            self.params,
            self.compliant_model("branches()"),
            backend=self.backend,
            rtol=self.rtol,
            start_slope_rad=start,
            n_guesses=guesses,
            to_end=to_end,
            progress=progress,
        )
        return BranchesResult({"model": self.model, "start_slope_rad": start, "branches": [b.row() for b in found]})

    # -- robustness beyond local stability (docs/simulator.md "Robustness")
    def basin(
        self,
        *,
        grid: int = 50,
        steps: int = 100,
        box: Any = None,
        tol: float = 1e-4,
        out: str | Path | None = None,
        progress: Callable[[int, int], None] | None = None,
        scheduler: str = "auto",
        workers: int | None = None,
    ) -> BasinResult:
        """The basin of attraction of the period-1 gait (`rimless sim basin`): the fate of each of grid x grid
        section points (cell centres) over `box` = ((theta+ lo, hi) rad, (theta'+ lo, hi) rad/s) (default: the
        gait's theta+ +- 0.15 rad, theta'+ in [0.02, 2.5] x the gait's) after at most `steps` map steps.

        `out`: a folder for basin.png and basin.csv. progress(i, n): points done. `scheduler`: where the grid's
        rows run, as `sweep()`'s: "sync" (this process), "local" (a Dask LocalCluster of `workers` processes,
        default one per core), "tcp://HOST:PORT", or "auto" (local from 64 x 64 points on a machine with a
        second core, else sync); the fates do not depend on it."""
        from rimless.sim.studies.basin import basin_study, write_basin

        if out is not None:
            from rimless.output import check_output_folder

            check_output_folder(out, option="--out")
        data, points = basin_study(
            self.params,
            self.compliant_model("basin()"),
            grid=grid,
            steps=steps,
            box=box,
            tol=tol,
            backend=self.backend,
            rtol=self.rtol,
            progress=progress,
            scheduler=scheduler,
            workers=workers,
        )
        if out is not None:
            data["files"] = write_basin(data, points, out)
        return BasinResult(data, points)

    def sensitivity(self, *, push_rad_s: float = 0.02, slope_step_deg: float = 0.05) -> SensitivityResult:
        """The gait sensitivity norm (`rimless sim sensitivity`) for a one-step slope change and a push (a change
        of theta'+), from the exact map Jacobian, checked against simulated disturbances of these sizes."""
        from rimless.sim.studies.sensitivity import sensitivity_study

        return SensitivityResult(
            sensitivity_study(
                self.params,
                self.compliant_model("sensitivity()"),
                push_rad_s=push_rad_s,
                slope_step_deg=slope_step_deg,
                backend=self.backend,
                rtol=self.rtol,
            )
        )

    def mfpt(
        self,
        terrain_sd_deg: float,
        *,
        method: Literal["mesh", "monte-carlo"] = "mesh",
        walks: int = 200,
        cap: int = 10_000,
        seed: int = 0,
        nodes: tuple[int, int] = (15, 60),
        slopes: int = 48,
        progress: Callable[[int, int], None] | None = None,
    ) -> MfptResult:
        """The mean first-passage time (`rimless sim mfpt`): the mean number of steps before a failure when each
        step's slope is drawn from a normal of standard deviation `terrain_sd_deg` about the wheel's slope.

        method "mesh": a Markov chain on nodes = (n_theta, n_theta_dot) section nodes and `slopes` slope values,
        with a coarser mesh for its discretisation error; "monte-carlo": `walks` walks of at most `cap` steps
        (seeded), with a 95 % interval."""
        import math

        from rimless.sim.studies.mfpt import mfpt_study

        if not (isinstance(terrain_sd_deg, float | int) and math.isfinite(terrain_sd_deg) and terrain_sd_deg > 0):
            raise ParameterError(f"terrain_sd_deg must be a number > 0, got {terrain_sd_deg!r}")
        return MfptResult(
            mfpt_study(
                self.params,
                self.compliant_model("mfpt()"),
                math.radians(terrain_sd_deg),
                method=method,
                walks=walks,
                cap=cap,
                seed=seed,
                nodes=nodes,
                slopes=slopes,
                backend=self.backend,
                rtol=self.rtol,
                progress=progress,
            )
        )
