"""The Poincaré map on the compiled path: `FastPoincareMap`, with the interface of
rimless.sim.step.poincare.PoincareMap (`__call__`, `step`, `jacobian`, `with_params`, attributes params/model/
integrator/clutch/evaluations), usable unchanged by solve_fixed_point and the continuation code.

A map evaluation is one compiled step (rimless.sim.fast.fast_step's kernels); its `jacobian` is the exact
variational Jacobian. `step` (the full StepResult with trajectories) and a non-ideal clutch policy go through
the reference hybrid step (rimless.sim.step.hybrid.simulate_step) with the compiled phase integrator
(rimless.sim.fast.FastIntegrator). Stiff legs: a step whose explicit DOP853 needs more than `max_steps`
steps in one phase is recomputed with scipy's implicit Radau (stiff_fallback=True), recorded in
`last_method` / `method_counts`. Units: SI; z = (theta+ rad, theta'+ rad/s).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from rimless.sim import fast
from rimless.sim.fast import FastIntegrator, check_model, mass_model_index, param_vector, raise_failure
from rimless.sim.fast import step as fs
from rimless.sim.integrate.reference import PhaseRun, ScipyIntegrator
from rimless.sim.model.guards import LIFTOFF_B
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import section_from_state, state_from_section
from rimless.sim.step.hybrid import IdealClutch, simulate_step

if TYPE_CHECKING:
    from typing_extensions import Unpack

    from rimless.sim.step.hybrid import StepOptions


class HeldStance:
    """An Integrator (any: compiled or reference) without the stance foot's lift-off guard (bilateral contact)
    for hybrid.simulate_step; its checks at the start of single support and of the impulses' signs still apply."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.name = f"{inner.name}+bilateral"

    @property
    def rtol(self) -> float:  # Integrator's
        return float(self.inner.rtol)

    def run_phase(
        self,
        mech: Mechanics,
        phase: int,
        y0: np.ndarray,
        t0: float,
        guards: tuple[int, ...],
        t_max: float,
        **options: Any,
    ) -> PhaseRun:
        return self.inner.run_phase(mech, phase, y0, t0, tuple(g for g in guards if g != LIFTOFF_B), t_max, **options)


class _VariationalJacobian:
    """Callable z -> dP/dz (exact, variational) for solve_fixed_point(..., jacobian=...)."""

    method_name = "variational"

    def __init__(self, pmap: FastPoincareMap) -> None:
        self.pmap = pmap

    def __call__(self, z: np.ndarray) -> np.ndarray:
        return self.pmap.jacobian(z)


@dataclass
class FastPoincareMap:
    """P: z -> z' on the compiled path; interface of rimless.sim.step.poincare.PoincareMap.

    integrator: a FastIntegrator whose rtol/atol the compiled map uses, and which `step` passes to
    hybrid.simulate_step. A non-ideal clutch policy makes every call go through the reference hybrid code
    (with the FastIntegrator) and the Jacobian fall back to central differences.
    """

    params: WheelParams
    model: str
    integrator: FastIntegrator = field(default_factory=FastIntegrator)
    clutch: Any = None
    evaluations: int = 0
    stiff_fallback: bool = True
    jacobian_with_map: bool = False  # compute dP/dz with every map call (cached): cheapest for Newton
    last_method: str = ""
    method_counts: dict[str, int] = field(default_factory=dict)
    bilateral: bool = False  # the stance foot held (fast_step(bilateral=True), and in `step`)

    def __post_init__(self) -> None:
        check_model(self.model)
        self.mech = Mechanics.of(self.params)
        self._p = param_vector(self.params)
        self._mi = mass_model_index(self.params)
        self._cache: tuple[tuple[float, float], np.ndarray, float, np.ndarray | None] | None = None
        self._counts = np.zeros((3, 2), dtype=np.int64)  # per-phase counters of the last compiled call

    # -- helpers -------------------------------------------------------------------------------
    def _compiled_ok(self) -> bool:
        """The whole step in one compiled call: not with guide friction (its stick/slip phases run through the
        hybrid step, each phase compiled) nor with a non-ideal clutch policy."""
        if self.params.guide_friction_n > 0.0:
            return False
        return (
            self.clutch is None
            or isinstance(self.clutch, IdealClutch)
            or (
                getattr(self.clutch, "delay_s", 0.0) <= 0.0 and getattr(self.clutch, "name", "") in ("ideal", "delayed")
            )
        )

    @property
    def exact_jacobian(self) -> bool:
        """Is `jacobian` the exact variational one (else central differences of the map)?"""
        return self._compiled_ok()

    def _count(self, method: str) -> None:
        self.last_method = method
        self.method_counts[method] = self.method_counts.get(method, 0) + 1

    def _reference_step(self, z: np.ndarray, integrator: Any) -> np.ndarray:
        return self._reference_result(z, integrator)[0]

    def _reference_result(self, z: np.ndarray, integrator: Any) -> tuple[np.ndarray, float]:
        res = simulate_step(self.mech, self.model, state_from_section(self.mech, z), integrator, clutch=self.clutch)
        return section_from_state(res.y_plus), res.period_s

    def evaluate(self, z: np.ndarray, *, jacobian: bool = False) -> tuple[np.ndarray, float, np.ndarray | None]:
        """(z_next, period_s, J or None) in one compiled call; raises StepFailure."""
        z = np.asarray(z, dtype=np.float64).reshape(2)
        key = (float(z[0]), float(z[1]))
        if self._cache is not None and self._cache[0] == key and (self._cache[3] is not None or not jacobian):
            return self._cache[1].copy(), self._cache[2], (None if self._cache[3] is None else self._cache[3].copy())
        if self.bilateral:
            st, detail, phase, t, yp, J, _times, _nfev, nsteps, _nstiff, _snap = fs.step_map_contact(
                self._mi,
                self.model == "er",
                self._p,
                z,
                float(self.integrator.rtol),
                float(self.integrator.atol),
                jacobian,
                int(self.integrator.max_steps),
                self._counts,
                True,
                np.empty(0),
            )
        else:
            st, detail, phase, t, yp, J, _times, _nfev, nsteps, _nstiff, _snap = fs.step_map(
                self._mi,
                self.model == "er",
                self._p,
                z,
                float(self.integrator.rtol),
                float(self.integrator.atol),
                jacobian,
                int(self.integrator.max_steps),
                self._counts,
            )
        if st == fs.TOO_MANY_STEPS and self.stiff_fallback and not self.bilateral:
            radau = ScipyIntegrator(
                "Radau",
                rtol=max(self.integrator.rtol, 1e-10),
                atol=max(self.integrator.atol, 1e-12),
                max_nfev=fast.RADAU_MAX_NFEV,
            )
            Jfd = None
            with np.errstate(over="ignore"):  # scipy's numerical Jacobian grows its step factors
                zn, period = self._reference_result(z, radau)
                if jacobian:
                    h = 1e-5
                    Jfd = np.empty((2, 2))
                    for i in range(2):
                        dz = np.zeros(2)
                        dz[i] = h
                        Jfd[:, i] = (self._reference_step(z + dz, radau) - self._reference_step(z - dz, radau)) / (
                            2 * h
                        )
            self._count("scipy-Radau")
            return zn, period, Jfd
        if st != fs.OK:
            raise_failure(st, detail, phase, t, nsteps)
        zn = np.array([yp[2], yp[7]])
        Jout = J.copy() if jacobian else None
        self._cache = (key, zn, float(t), Jout)
        self._count("fast-dop853")
        return zn.copy(), float(t), (None if Jout is None else Jout.copy())

    # -- PoincareMap interface -----------------------------------------------------------------
    def __call__(self, z: np.ndarray) -> np.ndarray:
        self.evaluations += 1
        z = np.asarray(z, dtype=np.float64)
        if not self._compiled_ok():
            self._count("hybrid+fast-dop853")
            return self._reference_step(z, self.integrator)
        return self.evaluate(z, jacobian=self.jacobian_with_map)[0]

    def step(self, z: np.ndarray, **options: Unpack[StepOptions]) -> Any:
        """The full StepResult (hybrid.simulate_step with the FastIntegrator; options as simulate_step)."""
        self.evaluations += 1
        integ = HeldStance(self.integrator) if self.bilateral else self.integrator
        return simulate_step(
            self.mech,
            self.model,
            state_from_section(self.mech, np.asarray(z, dtype=float)),
            integ,
            clutch=self.clutch,
            **options,
        )

    def with_params(self, params: WheelParams) -> FastPoincareMap:
        return FastPoincareMap(
            params,
            self.model,
            self.integrator,
            self.clutch,
            stiff_fallback=self.stiff_fallback,
            jacobian_with_map=self.jacobian_with_map,
            bilateral=self.bilateral,
        )

    def jacobian(self, z: np.ndarray, h: float | None = None) -> np.ndarray:
        """dP/dz: exact (variational) by default; central differences with step h if h is given."""
        z = np.asarray(z, dtype=np.float64)
        if h is None and self._compiled_ok():
            J = self.evaluate(z, jacobian=True)[2]
            if J is not None:
                return J
            h = 1e-5
        h = 1e-5 if h is None else h
        J = np.empty((2, 2))
        for i in range(2):
            dz = np.zeros(2)
            dz[i] = h
            J[:, i] = (self(z + dz) - self(z - dz)) / (2 * h)
        return J

    jacobian.method_name = "variational"  # type: ignore[attr-defined]

    @property
    def variational_jacobian(self) -> Callable[[np.ndarray], np.ndarray]:
        """A jacobian callable for solve_fixed_point (carries method_name = 'variational')."""
        return _VariationalJacobian(self)


@dataclass(frozen=True)
class FrictionStep:
    """One step with guide friction on the compiled phase integrator: next section point, period (s), the
    guide-friction work (J) and the full StepResult."""

    z_next: np.ndarray
    period_s: float
    friction_work_J: float
    result: Any


def friction_step(
    params: WheelParams, model: str, z: np.ndarray, *, rtol: float = 1e-10, atol: float | None = None
) -> FrictionStep:
    """The step map where fast_step (one compiled call) has no guide friction: hybrid.simulate_step with the
    compiled phase integrator, each stick/slip phase compiled (rimless.sim.integrate.friction). Raises
    StepFailure."""
    check_model(model)
    mech = Mechanics.of(params)
    res = simulate_step(
        mech,
        model,
        state_from_section(mech, np.asarray(z, dtype=float)),
        FastIntegrator(rtol=rtol, atol=rtol * 1e-2 if atol is None else atol),
    )
    return FrictionStep(section_from_state(res.y_plus), res.period_s, res.friction_work_J, res)
