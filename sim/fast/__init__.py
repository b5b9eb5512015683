"""The compiled fast path: a numba DOP853 backend for the hybrid simulation and a lean compiled step with the
exact (variational) map Jacobian, and their Python faces.

It is the second implementation of the model whose reference implementation is rimless.sim.step.hybrid,
integrate.reference, model.dynamics and model.mechanics (scipy, Python right-hand side); both give the same
steps, failure classes and guards (codes and directions of the one table rimless.sim.model.guards, the dip
rules of the event engine rimless.sim.integrate.events). Modules:
- rimless.sim.fast.model: compiled mechanics (phase dynamics, their exact derivatives, guards, impact);
- rimless.sim.fast.rk: compiled DOP853 for one phase with guard location on the dense output (the engine's twin);
- rimless.sim.fast.friction: the tangent maps at guide friction's events (the friction map's exact Jacobian);
- rimless.sim.fast.stiff: a compiled Rosenbrock method for single support of near-massless legs (`leg_stiff`);
- rimless.sim.fast.step: one whole step (phase sequence, pre-checks, saltation, impact) compiled;
- rimless.sim.fast.compiling: calling a kernel on first use with a notice on stderr while it compiles;
- rimless.sim.fast.ahead: on a cold cache, the step kernel's late callees compiled in a second process;
- rimless.sim.fast (this file): the Python face below. Import fast-path names from here.

- `FastIntegrator(rtol, atol)`: implements rimless.sim.integrate.reference.Integrator (`run_phase`), so
  rimless.sim.step.hybrid.simulate_step can use it when trajectories, forces or energies are recorded.
- `fast_step(params, model, z, ...)` / `fast_map(params, model, z, rtol)`: one whole step compiled
  (phases, guards, pre-checks, failure classes and impact identical to hybrid.simulate_step with the ideal
  clutch); nothing is recorded. Failures raise StepFailure with the same FailureReason as the reference.
- `exact_jacobian(pmap_or_params, model, z)`: dP/dz (2x2) from the variational equations, saltation
  matrices at lift-off and clutch lock, and the exact derivative of the relabel + impact reset. With guide
  friction the step runs phase by phase (rimless.sim.step.fast_map.friction_step) and its exact Jacobian adds
  the stick/slip sub-phases' variational equations and saltation matrices (rimless.sim.fast.friction).
The Poincaré map on this path, `FastPoincareMap`, is a step-level object: rimless.sim.step.fast_map.

Units: SI; z = (theta+ rad, theta'+ rad/s) on the post-impact section (rimless.sim.model.section).

Stiff legs: DOP853 is explicit. Single support of legs whose fastest root max(c/m, sqrt(k/m)) exceeds
stiff.STIFF_LEG_RATE (near-massless legs; not Table 1's) is integrated by the compiled Rosenbrock method of
rimless.sim.fast.stiff, on the step map (with its exact Jacobian too) and in FastIntegrator walks (stiff_legs=True), the
stick/slip phases of guide friction included (so friction_step and every walk with friction). A phase
still needing more than `max_steps` steps is reported as such (StepFailure INTEGRATION with "too many steps",
StiffnessLimit); FastPoincareMap(stiff_fallback=True) then recomputes that map with scipy's implicit Radau.

May import: rimless.sim.model, rimless.sim.integrate (the Integrator protocol, the event engine's constants),
numpy, scipy, numba, rimless.errors. Never step/, continuation/, studies/, in_the_loop/ or cli/.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np


def _use_rimless_cache_dir() -> None:
    """RIMLESS_CACHE_DIR moves every cache the project keeps; numba's compiled kernels go to its `numba/`
    subfolder. Set before the kernels below are decorated (numba picks a kernel's cache folder then) and in the
    environment, so that subprocesses (Dask workers, benchmarks) use the same folder."""
    root = os.environ.get("RIMLESS_CACHE_DIR")
    if not root:
        return
    folder = os.path.join(os.path.abspath(os.path.expanduser(root)), "numba")
    os.environ["NUMBA_CACHE_DIR"] = folder
    import numba

    numba.config.CACHE_DIR = folder  # type: ignore[attr-defined]  # config names are set at run time


_use_rimless_cache_dir()


def _compile_settings() -> None:
    """LLVM's loop vectoriser off (NUMBA_LOOP_VECTORIZE=0) unless the environment sets it: about 5 % less
    compile time on first use, the same run time (docs/performance.md, "First use"), the same results (without
    fast-math it only vectorises element-wise loops, the same operation on every element). Set in the
    environment, which numba re-reads when it compiles (and subprocesses inherit)."""
    if "NUMBA_LOOP_VECTORIZE" in os.environ:
        return
    os.environ["NUMBA_LOOP_VECTORIZE"] = "0"
    import numba

    numba.config.LOOP_VECTORIZE = 0  # type: ignore[attr-defined]  # (as CACHE_DIR)


_compile_settings()

from rimless.sim.fast import friction as fj  # noqa: E402
from rimless.sim.fast import model as fm  # noqa: E402 (after the cache folder is chosen)
from rimless.sim.fast import rk, stiff  # noqa: E402
from rimless.sim.fast import step as fs  # noqa: E402
from rimless.sim.fast.ahead import compiling_ahead  # noqa: E402
from rimless.sim.fast.compiling import cache_folder as _cache_folder  # noqa: E402
from rimless.sim.fast.compiling import call_compiling as _call_compiling  # noqa: E402
from rimless.sim.integrate.reference import PhaseRun  # noqa: E402
from rimless.sim.model.failures import FailureReason, StepFailure  # noqa: E402
from rimless.sim.model.friction import FRICTION_PHASE0  # noqa: E402
from rimless.sim.model.guards import DIRECTION  # noqa: E402
from rimless.sim.model.mechanics import Mechanics  # noqa: E402
from rimless.sim.model.params import WheelParams  # noqa: E402


def _invalidate_stale_cache() -> None:
    """numba's on-disk cache (cache=True) is keyed on each function's own source file only: a kernel that
    inlines code from another module (the generated mechanics, model.py, rk.py) would be loaded stale
    after that module changed (e.g. a re-derivation). Stamp the cache with a hash of every source the
    kernels depend on and drop our cached kernels when it differs."""
    import hashlib
    from pathlib import Path

    from rimless.sim.fast import compiling
    from rimless.sim.integrate import events
    from rimless.sim.model import dynamics, guards
    from rimless.sim.model.generated import active_feet, eight_leg, sliding_leg

    digest = hashlib.sha256()
    for mod in (fm, rk, fs, stiff, fj, compiling, eight_leg, sliding_leg, active_feet, guards, dynamics, events):
        assert mod.__file__ is not None  # modules loaded from source files
        digest.update(Path(mod.__file__).read_bytes())
    stamp_value = digest.hexdigest()
    try:
        cache_dir = Path(fs.step_kernel._cache._cache_path)
        stamp = cache_dir / "rimless_fast_kernels.stamp"
        if stamp.exists() and stamp.read_text() == stamp_value:
            return
        for pattern in ("model.*.nb[ic]", "rk.*.nb[ic]", "step.*.nb[ic]", "stiff.*.nb[ic]", "friction.*.nb[ic]"):
            for f in cache_dir.glob(pattern):
                f.unlink(missing_ok=True)
        gen_dir = Path(fm._M0._cache._cache_path)
        if gen_dir != cache_dir:
            for f in gen_dir.glob("*.nb[ic]"):
                f.unlink(missing_ok=True)
        cache_dir.mkdir(parents=True, exist_ok=True)
        stamp.write_text(stamp_value)
    except (OSError, AttributeError):  # read-only install or another numba: the cache is merely not reused
        pass


_invalidate_stale_cache()


def cache_folder() -> str:
    """Where the compiled kernels are cached on disk (numba's cache folder of the step kernel)."""
    return _cache_folder(fs.step_kernel)


MAX_STEPS = 200_000  # accepted steps per phase before the explicit method gives up
# right-hand-side evaluations per phase of the implicit fallback (scipy Radau, Python right-hand side):
# some 10-20 s per phase on a busy 2-core machine; beyond it the step fails as an integration failure
RADAU_MAX_NFEV = 50_000
MODELS = ("er", "ve")

_REASON = {
    fs.STALL: FailureReason.STALL,
    fs.STANCE_LIFT_OFF: FailureReason.STANCE_LIFT_OFF,
    fs.TOUCHDOWN_BEFORE_CLUTCH: FailureReason.TOUCHDOWN_BEFORE_CLUTCH,
    fs.CLUTCH_MISSED: FailureReason.CLUTCH_MISSED,
    fs.DLSP_NEVER_ENDS: FailureReason.DLSP_NEVER_ENDS,
    fs.NEGATIVE_IMPULSE: FailureReason.NEGATIVE_IMPULSE,
    fs.INTEGRATION: FailureReason.INTEGRATION,
    fs.TOO_MANY_STEPS: FailureReason.INTEGRATION,
    fs.NOT_FINITE: FailureReason.INTEGRATION,
}
_PHASE = {0: "dlsp", 1: "slsp_free", 2: "slsp_clutched", 3: "impact"}
_DETAIL = {
    fs.D_PRECHECK: "failed the check at the start of the phase",
    fs.D_GUARD: "the guard fired",
    fs.D_TIME_LIMIT: f"no event within {fs.PHASE_TIME_LIMIT_S} s",
    fs.D_SOLVER: "the compiled integrator failed (step size too small or non-finite state)",
    fs.D_NOT_FINITE: "non-finite forces or state (speeds or parameters too large to represent)",
}


class StiffnessLimit(StepFailure):
    """The explicit method needed more than `max_steps` steps in one phase (stiff or very oscillatory legs)."""


def _single_support(phase: int) -> bool:
    """Whether phase code `phase` (a base phase, or a guide-friction phase of rimless.sim.model.friction) is one
    of single support, the phases the Rosenbrock method takes with near-massless legs."""
    base = phase if phase < FRICTION_PHASE0 else (phase - FRICTION_PHASE0) // 16
    return base in (fm.SLSP_FREE, fm.SLSP_CLUTCHED)


def mass_model_index(params: WheelParams) -> int:
    return fm.MASS_MODEL_INDEX[params.mass_model]


def param_vector(params: WheelParams) -> np.ndarray:
    """(m_H, m, I_c, L0, k, c, g, phi) as float64, SI."""
    return np.array(params.as_vector(), dtype=np.float64)


def compiled(params: WheelParams) -> bool:
    """Whether the step kernel and the phase integrator of ``params``' mass model are compiled in this process
    or in numba's on-disk cache (a process started now loads them instead of compiling them)."""
    from rimless.sim.fast.compiling import is_cached

    mi = mass_model_index(params)
    return is_cached(fs.STEP_MAP_CONTACT[mi]) and is_cached(rk.RUN_PHASE[mi])


def check_model(model: str) -> bool:
    """True for ER, False for VE; ValueError for another model."""
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}")
    return model == "er"


@dataclass(frozen=True)
class FastStep:
    """Result of one compiled step: next section point, period (s), post-impact state (new labels, foot b
    not moved to the origin), dz'/dz (if asked), phase end times (s), counters."""

    z_next: np.ndarray
    period_s: float
    y_plus: np.ndarray
    jacobian: np.ndarray | None
    phase_end_s: np.ndarray  # end of dlsp, end of free compression (VE: = touchdown), touchdown
    nfev: int
    nsteps: int
    nstiff: int  # accepted steps flagged stiff by the h |lambda| > 6.1 test
    relabel_snap_J: float = 0.0  # energy the relabelling snap of the old trailing leg adds (J; < 0 removes)
    # "fast-dop853", or "fast-dop853+rosenbrock": single support of near-massless legs by rimless.sim.fast.stiff
    method: str = "fast-dop853"
    contact: BilateralContact | None = None  # with bilateral=True only
    # per phase (dlsp, slsp_free, slsp_clutched): right-hand-side evaluations and accepted steps
    phase_nfev: tuple[int, int, int] = (0, 0, 0)
    phase_steps: tuple[int, int, int] = (0, 0, 0)


@dataclass(frozen=True)
class BilateralContact:
    """What a step under bilateral contact (the stance foot held, impulses of either sign) did that unilateral
    contact forbids: the smallest single-support stance normal force (N) and its time from the step's start
    (s), how long that force is negative (s), and the smallest normal impact impulse (N s)."""

    min_stance_force_N: float
    min_stance_force_time_s: float
    negative_force_s: float
    min_impulse_N_s: float

    @classmethod
    def of(cls, c: np.ndarray) -> BilateralContact:
        return cls(
            float(c[fs.C_MIN_FORCE]), float(c[fs.C_MIN_FORCE_T]), float(c[fs.C_NEGATIVE_S]), float(c[fs.C_MIN_IMPULSE])
        )

    @property
    def unilateral_valid(self) -> bool:
        return self.min_stance_force_N >= 0.0 and self.min_impulse_N_s > 0.0


def raise_failure(status: int, detail: int, phase: int, t: float, nsteps: int) -> None:
    """Raise the StepFailure (FailureReason of the reference) for a compiled step's status and detail codes."""
    reason = _REASON[status]
    msg = _DETAIL.get(detail, "")
    if status == fs.TOO_MANY_STEPS:
        raise StiffnessLimit(
            reason,
            f"the explicit DOP853 needed more than the step limit in one phase "
            f"({nsteps} steps in the step): stiff legs, use an implicit method",
            time_s=t,
            phase=_PHASE[phase],
        )
    if status == fs.STALL and detail == fs.D_PRECHECK:
        msg = "theta' <= 0 at the start of the step"
    elif status == fs.CLUTCH_MISSED:
        msg = "L1' >= 0 at lift-off: the stance leg's maximum compression happened in double support"
    elif status == fs.STANCE_LIFT_OFF and detail == fs.D_PRECHECK:
        msg = "the stance foot is unloaded at the start of single support"
    elif status == fs.NEGATIVE_IMPULSE:
        msg = "a normal impact impulse is <= 0"
    elif status == fs.NOT_FINITE:
        msg = "non-finite state or forces during integration (speeds too large to represent)"
    raise StepFailure(reason, f"{msg} (compiled map)", time_s=t, phase=_PHASE[phase])


def fast_step(
    params: WheelParams,
    model: str,
    z: np.ndarray,
    *,
    rtol: float = 1e-10,
    atol: float | None = None,
    jacobian: bool = False,
    max_steps: int = MAX_STEPS,
    bilateral: bool = False,
    record_contact: bool = True,
) -> FastStep:
    """One compiled step from z = (theta+, theta'+); raises StepFailure with the reference's reason.

    atol defaults to rtol / 100 (the reference ScipyIntegrator pairs rtol 1e-10 with atol 1e-12).
    bilateral: hold the stance foot (no stance lift-off, impulses of either sign accepted) and report what
    unilateral contact would forbid in `contact` (BilateralContact; record_contact=False skips that record,
    which costs about as much as the step): for finding and characterising gaits that are not contact-valid.

    Guide friction is not in this one-call step: params with guide_friction_n > 0 raise ValueError (they were
    stepped without their friction until session 22); `rimless.sim.step.fast_map.friction_step` steps them.
    """
    if params.guide_friction_n > 0.0:
        raise ValueError(
            f"fast_step has no guide friction (guide_friction_n = {params.guide_friction_n} N): "
            "use rimless.sim.step.fast_map.friction_step or FastPoincareMap"
        )
    er = check_model(model)
    atol = rtol * 1e-2 if atol is None else atol
    zz = np.asarray(z, dtype=np.float64).reshape(2)
    counts = np.zeros((3, 2), dtype=np.int64)
    c = np.empty(fs.CONTACT_SIZE if bilateral and record_contact else 0)
    # the mass model's own entry point: only its generated code is compiled (rimless.sim.fast.model)
    mi = mass_model_index(params)
    st, detail, phase, t, yp, J, times, nfev, nsteps, nstiff, snap = _call_compiling(
        fs.STEP_MAP_CONTACT[mi],
        er,
        param_vector(params),
        zz,
        float(rtol),
        float(atol),
        bool(jacobian),
        int(max_steps),
        counts,
        bool(bilateral),
        c,
        ahead=lambda: compiling_ahead(mi),
    )
    if st != fs.OK:
        raise_failure(st, detail, phase, t, nsteps)
    return FastStep(
        z_next=np.array([yp[2], yp[7]]),
        period_s=float(t),
        y_plus=yp,
        jacobian=J if jacobian else None,
        phase_end_s=times,
        nfev=int(nfev),
        nsteps=int(nsteps),
        nstiff=int(nstiff),
        relabel_snap_J=float(snap),
        method="fast-dop853+rosenbrock" if stiff.leg_stiff(param_vector(params)) else "fast-dop853",
        contact=BilateralContact.of(c) if bilateral and len(c) else None,
        phase_nfev=(int(counts[0, 0]), int(counts[1, 0]), int(counts[2, 0])),
        phase_steps=(int(counts[0, 1]), int(counts[1, 1]), int(counts[2, 1])),
    )


def fast_map(
    params: WheelParams, model: str, z: np.ndarray, rtol: float = 1e-10, atol: float | None = None
) -> tuple[np.ndarray, float]:
    """(z_next, period_s) of the compiled Poincaré map; raises StepFailure (ValueError with guide friction:
    `fast_step`)."""
    r = fast_step(params, model, z, rtol=rtol, atol=atol)
    return r.z_next, r.period_s


def exact_jacobian(
    pmap_or_params: Any,
    model: str | None = None,
    z: np.ndarray | None = None,
    *,
    rtol: float = 1e-10,
    atol: float | None = None,
) -> np.ndarray:
    """dP/dz (2x2) by the variational equations with saltation and the exact impact reset Jacobian.

    Call as exact_jacobian(params, model, z) or exact_jacobian(pmap, z=z) / exact_jacobian(pmap, z)
    where pmap is a (Fast)PoincareMap (its params and model are used, and its integrator's tolerances
    if it has them).

    Guide friction (params.guide_friction_n > 0): the one-call step has none, so a FastPoincareMap with an exact
    friction Jacobian (its `exact_jacobian`) answers with its own (rimless.sim.step.fast_map.friction_step(
    jacobian=True)); params with friction, or a map without that Jacobian, raise ValueError (never the
    frictionless map's Jacobian).
    """
    if isinstance(pmap_or_params, WheelParams):
        if model is None or z is None:
            raise TypeError("exact_jacobian(params, model, z)")
        params = pmap_or_params
        if params.guide_friction_n > 0.0:
            raise ValueError(
                "exact_jacobian(params, ...) with guide friction: use FastPoincareMap(params, model).jacobian(z) "
                "or rimless.sim.step.fast_map.friction_step(params, model, z, jacobian=True)"
            )
    else:
        pm = pmap_or_params
        if z is None and model is not None and not isinstance(model, str):
            z, model = model, None
        params, model = pm.params, pm.model
        if params.guide_friction_n > 0.0:
            if not getattr(pm, "exact_jacobian", False):
                raise ValueError("exact_jacobian: this map with guide friction has no exact Jacobian")
            assert z is not None
            return np.asarray(pm.jacobian(np.asarray(z, dtype=np.float64)))
        integ = getattr(pm, "integrator", None)
        if isinstance(integ, FastIntegrator):
            rtol, atol = integ.rtol, integ.atol
    assert z is not None and model is not None
    r = fast_step(params, model, z, rtol=rtol, atol=atol, jacobian=True)
    assert r.jacobian is not None
    return r.jacobian


@dataclass
class FastIntegrator:
    """Compiled DOP853 backend for rimless.sim.step.hybrid (Integrator protocol); same defaults as the reference."""

    rtol: float = 1e-10
    atol: float = 1e-12
    max_steps: int = MAX_STEPS
    #: single support with near-massless legs (rimless.sim.fast.stiff.leg_stiff) by the compiled Rosenbrock
    #: method; False keeps DOP853 everywhere (the reference the benchmark compares with)
    stiff_legs: bool = True
    name: str = field(init=False)

    def __post_init__(self) -> None:
        self.name = "fast-dop853"

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
        args = rk.phase_call_args(
            phase,
            mech.p,
            y0,
            t0,
            guards,
            [DIRECTION[g] for g in guards],
            t_max,
            self.rtol,
            self.atol,
            track_dissipation,
            record_dt,
            self.max_steps,
        )
        mi = fm.MASS_MODEL_INDEX[mech.params.mass_model]
        if self.stiff_legs and _single_support(phase) and stiff.leg_stiff(mech.p):
            # near-massless legs: single support (with guide friction too: its slip and stick phases) by the
            # Rosenbrock method (rimless.sim.fast.stiff)
            args = args[:10] + args[11:]  # no variational equations
            entry = stiff.RUN_PHASE_STIFF[mi]
        else:
            entry = rk.RUN_PHASE[mi]
        st, t_end, y_end, fired, nfev, nsteps, _nstiff, rec_t, rec_y = _call_compiling(entry, *args)
        run = PhaseRun(
            t_end=float(t_end),
            y_end=np.array(y_end[:10]),
            guard=(guards[fired] if fired >= 0 else None),
            nfev=int(nfev),
            dissipated_J=float(y_end[10]) if track_dissipation else 0.0,
        )
        if st != rk.STATUS_OK:
            run.failed = True
            run.message = {
                rk.STATUS_STEP_TOO_SMALL: "required step size is less than spacing between numbers",
                rk.STATUS_NOT_FINITE: "non-finite state or singular KKT matrix",
                rk.STATUS_TOO_MANY_STEPS: f"more than {self.max_steps} steps (stiff legs?)",
            }[st]
        if record_dt:
            run.t = np.array(rec_t)
            run.y = np.array(rec_y)
        return run


def warm_up(models: tuple[str, ...] = MODELS, params: WheelParams | None = None) -> float:
    """Compile (or load from the on-disk cache) every kernel of ``params``' mass model (Table 1 by default):
    the step kernel with and without its Jacobian, the phase integrator's entry from Python (recorded steps and
    guide friction's phases) and the exact friction Jacobian's entry points (`ahead.friction_tangent_calls`);
    returns the seconds it took."""
    import time

    t0 = time.perf_counter()
    p = params or WheelParams()
    z = np.array([-0.465155, 2.604441])
    for model in models:
        for jacobian in (False, True):
            try:
                fast_step(p, model, z, jacobian=jacobian)
            except StepFailure:  # a step from Table 1's gait that fails at other parameters: compiled all the same
                pass
    from rimless.sim.fast.ahead import friction_tangent_calls, recorded_phase_call

    entry, args = recorded_phase_call(p)  # the integrator's entry from Python (recorded steps)
    _call_compiling(entry, *args)
    for entry, args in friction_tangent_calls(p):  # friction_step(jacobian=True)'s own kernels
        try:
            _call_compiling(entry, *args)
        except ZeroDivisionError:  # a tangent at a degenerate event: compiled all the same
            pass
    return time.perf_counter() - t0
