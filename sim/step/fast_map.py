"""The Poincaré map on the compiled path: `FastPoincareMap`, with the interface of
rimless.sim.step.poincare.PoincareMap (`__call__`, `step`, `jacobian`, `with_params`, attributes params/model/
integrator/clutch/evaluations), usable unchanged by solve_fixed_point and the continuation code.

A map evaluation is one compiled step (rimless.sim.fast.fast_step's kernels); its `jacobian` is the exact
variational Jacobian. With guide friction a map evaluation is `friction_step` (hybrid.simulate_step with the
compiled phase integrator, phase by phase) and its `jacobian` the exact one of `friction_step(jacobian=True)`
(variational equations through the stick/slip sub-phases, saltation at their events: rimless.sim.fast.friction),
except with bilateral contact or a non-ideal clutch: central differences there (`exact_jacobian` False). `step` (the full StepResult with trajectories) and a non-ideal clutch policy go through
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
from rimless.sim.fast import FastIntegrator, check_model, mass_model_index, param_vector, raise_failure, rk, stiff
from rimless.sim.fast import friction as fj
from rimless.sim.fast import step as fs
from rimless.sim.fast.compiling import call_compiling
from rimless.sim.integrate.reference import PhaseRun, ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.guards import DIRECTION, LIFTOFF_B, TOUCHDOWN
from rimless.sim.model.guards import TABLE as GUARD_TABLE
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

    def _friction_exact(self) -> bool:
        """With guide friction: is the exact Jacobian of `friction_step(jacobian=True)` available (the ideal clutch,
        unilateral contact)?"""
        return (
            self.params.guide_friction_n > 0.0
            and not self.bilateral
            and (self.clutch is None or isinstance(self.clutch, IdealClutch))
        )

    @property
    def exact_jacobian(self) -> bool:
        """Is `jacobian` the exact variational one (else central differences of the map)?"""
        return self._compiled_ok() or self._friction_exact()

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
        if h is None and self._friction_exact():
            r = friction_step(
                self.params,
                self.model,
                z,
                rtol=float(self.integrator.rtol),
                atol=float(self.integrator.atol),
                jacobian=True,
                max_steps=int(self.integrator.max_steps),
            )
            self._count("hybrid+fast-dop853+variational")
            assert r.jacobian is not None
            return r.jacobian
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
    guide-friction work (J), the full StepResult and, with jacobian=True, dz'/dz (2 x 2, exact)."""

    z_next: np.ndarray
    period_s: float
    friction_work_J: float
    result: Any
    jacobian: np.ndarray | None = None
    #: with jacobian=True: the guards (names of rimless.sim.model.guards.TABLE) of the events the tangents went
    #: through, in order, touchdown last ("lift-off-a", "slip-end-2", "stick-end-2", "clutch-lock", ...)
    events: tuple[str, ...] = ()


class _TangentIntegrator:
    """The compiled phase integrators of FastIntegrator (DOP853; the Rosenbrock method in single support of
    near-massless legs) with the variational equations: carries the tangents V = dy/dz (10 x 2) through each (friction) sub-phase hybrid.simulate_step
    runs, and through the event between one sub-phase and the next by the saltation matrix
    (rimless.sim.fast.friction.event_tangent). The state is integrated as without V (the error is controlled on
    the state only), so the step is friction_step's to the last bit. No records, no dissipation tracking."""

    def __init__(self, mech: Mechanics, rtol: float, atol: float, max_steps: int, V: np.ndarray) -> None:
        self.rtol = rtol
        self.atol = atol
        self.max_steps = max_steps
        self.name = "fast-dop853+variational"
        self.p = np.asarray(mech.p, dtype=np.float64)
        self.mi = fast.mass_model_index(mech.params)
        self.stiff_legs = bool(stiff.leg_stiff(self.p))
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self.last: tuple[int, int, np.ndarray] | None = None  # (phase code, guard fired, end state)
        self.events: list[int] = []  # the guards of the events carried through

    def run_phase(
        self,
        mech: Mechanics,
        phase: int,
        y0: np.ndarray,
        t0: float,
        guards: tuple[int, ...],
        t_max: float,
        *,
        record_dt: float | None = None,
        track_dissipation: bool = False,
    ) -> PhaseRun:
        y0 = np.asarray(y0, dtype=np.float64)
        if self.last is not None:
            code, guard, y_end = self.last
            ok, V = call_compiling(fj.EVENT_TANGENT[self.mi], code, guard, y_end, int(phase), y0, self.p, self.V)
            if not ok:
                raise StepFailure(
                    FailureReason.INTEGRATION,
                    "the saltation matrix at a guide-friction event is undefined (guard tangent to the flow "
                    "or a singular KKT matrix; compiled map Jacobian)",
                    time_s=t0,
                )
            self.V = V
            self.events.append(guard)
        args = list(
            rk.phase_call_args(
                phase,
                self.p,
                np.concatenate((y0, self.V.T.ravel())),
                t0,
                guards,
                [DIRECTION[g] for g in guards],
                t_max,
                self.rtol,
                self.atol,
                False,
                None,
                self.max_steps,
            )
        )
        if self.stiff_legs and fast._single_support(phase):
            # near-massless legs: single support by the Rosenbrock method, as FastIntegrator; with y of 30 it
            # carries V too (rimless.sim.fast.stiff), the step of y the same as without V
            entry, args = stiff.RUN_PHASE_STIFF[self.mi], args[:10] + args[11:]
        else:
            entry = rk.RUN_PHASE[self.mi]
            args[10] = True  # with the variational equations (error control on the state's 10 components)
        st, t_end, y_end, fired, nfev, _nsteps, _nstiff, _rec_t, _rec_y = call_compiling(entry, *args)
        run = PhaseRun(
            t_end=float(t_end),
            y_end=np.array(y_end[:10]),
            guard=(guards[fired] if fired >= 0 else None),
            nfev=int(nfev),
        )
        if st != rk.STATUS_OK:
            run.failed = True
            run.message = {
                rk.STATUS_STEP_TOO_SMALL: "required step size is less than spacing between numbers",
                rk.STATUS_NOT_FINITE: "non-finite state or singular KKT matrix",
                rk.STATUS_TOO_MANY_STEPS: f"more than {self.max_steps} steps (stiff legs?)",
            }[st]
        self.V = np.array(y_end[10:30]).reshape(2, 10).T.copy()
        self.last = (int(phase), -1 if run.guard is None else int(run.guard), run.y_end.copy())
        return run


def friction_step(
    params: WheelParams,
    model: str,
    z: np.ndarray,
    *,
    rtol: float = 1e-10,
    atol: float | None = None,
    jacobian: bool = False,
    max_steps: int = fast.MAX_STEPS,
) -> FrictionStep:
    """The step map where fast_step (one compiled call) has no guide friction: hybrid.simulate_step with the
    compiled phase integrator, each stick/slip phase compiled (rimless.sim.integrate.friction). Raises
    StepFailure.

    jacobian=True: also dz'/dz (2 x 2), exact: the variational equations through every stick/slip sub-phase,
    the saltation matrices at their events (lift-off, the clutch's lock, a slip's end, a stick's end) and the
    relabel + impact reset's derivative (rimless.sim.fast.friction); the step (z_next, period, records) is the
    same to the last bit. Near-massless legs (rimless.sim.fast.stiff.leg_stiff): single support by the Rosenbrock
    method with the tangents, as the frictionless map's Jacobian."""
    check_model(model)
    mech = Mechanics.of(params)
    atol = rtol * 1e-2 if atol is None else atol
    y0 = state_from_section(mech, np.asarray(z, dtype=float))
    if not jacobian:
        res = simulate_step(mech, model, y0, FastIntegrator(rtol=rtol, atol=atol, max_steps=max_steps))
        return FrictionStep(section_from_state(res.y_plus), res.period_s, res.friction_work_J, res)
    mi = mass_model_index(params)
    _y, T = call_compiling(fj.SECTION[mi], np.asarray(z, dtype=np.float64).reshape(2), np.asarray(mech.p, float))
    integ = _TangentIntegrator(mech, float(rtol), float(atol), int(max_steps), T)
    res = simulate_step(mech, model, y0, integ)
    assert integ.last is not None and integ.last[1] == TOUCHDOWN  # simulate_step returns only at touchdown
    code, _guard, y_minus = integ.last
    ok, _yp, _impulse, J = call_compiling(fj.TOUCHDOWN_TANGENT[mi], code, y_minus, integ.p, integ.V)
    if not ok:
        raise StepFailure(
            FailureReason.INTEGRATION,
            "the touchdown's saltation or the impact's derivative is undefined (compiled map Jacobian)",
            time_s=res.period_s,
            phase="impact",
        )
    events = tuple(GUARD_TABLE[g].name for g in [*integ.events, TOUCHDOWN])
    return FrictionStep(section_from_state(res.y_plus), res.period_s, res.friction_work_J, res, np.array(J), events)
