"""One step of the hybrid system: the phase sequence of the ER or VE wheel, then the impact.

ER (model.md section 4): DLSP -> SLSP free compression -> SLSP clutched -> impact.
VE: DLSP -> SLSP (free) -> impact.
The integrator is a backend (rimless.sim.integrate.reference); the clutch decision is a policy object.
A step either returns a valid StepResult or raises StepFailure with a classified reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, TypedDict

import numpy as np

from rimless.sim.integrate.friction import run_with_friction
from rimless.sim.integrate.reference import Integrator, PhaseRun
from rimless.sim.model import friction as fr
from rimless.sim.model import guards as ev
from rimless.sim.model.dynamics import DLSP, PHASE_NAMES, SLSP_CLUTCHED, SLSP_FREE, accel
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.impact import ImpactResult, impact
from rimless.sim.model.mechanics import Mechanics, foot_a

MODELS = ("er", "ve")
PHASE_TIME_LIMIT_S = 5.0


@dataclass(frozen=True)
class PhaseRecord:
    """One phase of a step: its name and start/end times in s."""

    name: str
    t_start_s: float
    t_end_s: float

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


@dataclass
class Segment:
    """Recorded samples of one phase: times (n,) in s and states (n, 10)."""

    phase: int
    t: np.ndarray
    y: np.ndarray


@dataclass
class StepResult:
    """A valid step from one post-impact state to the next."""

    y_start: np.ndarray
    y_minus: np.ndarray  # pre-impact state, pre-impact labels
    y_plus: np.ndarray  # post-impact state, new labels (foot b not moved to the origin)
    t_start_s: float
    period_s: float
    phases: list[PhaseRecord]
    impact: ImpactResult
    nfev: int
    dissipated_J: float = 0.0  # damper loss over the step (only with track_dissipation)
    clutch_loss_J: float = 0.0  # energy removed by a late clutch lock (0 for the ideal clutch)
    # energy the relabelling adds by snapping the old trailing leg to L0 with zero rate, J (signed: < 0
    # removes energy). Table 1, eight-leg, at the fixed points: about +1.2e-5 J for VE, -2e-6 J for ER.
    relabel_snap_J: float = 0.0
    friction_work_J: float = 0.0  # guide-friction work over the step, J (0 without guide friction)
    stick_s: tuple[float, float] = (0.0, 0.0)  # time the stance and trailing legs were stuck by guide friction, s
    segments: list[Segment] | None = None
    diagnostics: dict[str, float] | None = None

    @property
    def phase_durations_s(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for rec in self.phases:
            out[rec.name] = out.get(rec.name, 0.0) + rec.duration_s
        return out


class ClutchPolicy(Protocol):
    """Decides when free compression ends and the stance leg locks (ER only)."""

    @property
    def name(self) -> str: ...  # read-only: the policies are frozen dataclasses

    def lock(
        self,
        mech: Mechanics,
        integrator: Integrator,
        y: np.ndarray,
        t: float,
        *,
        record_dt: float | None,
        track_dissipation: bool,
    ) -> tuple[np.ndarray, float, list[PhaseRun]]:
        """Given the state at L1' = 0 (ideal lock instant), return (state after lock, time, extra free runs)."""
        ...


@dataclass(frozen=True)
class IdealClutch:
    """Locks exactly at maximum compression (the event L1' = 0), as in the paper."""

    name: str = "ideal"

    def lock(
        self,
        mech: Mechanics,
        integrator: Integrator,
        y: np.ndarray,
        t: float,
        *,
        record_dt: float | None,
        track_dissipation: bool,
    ) -> tuple[np.ndarray, float, list[PhaseRun]]:
        y = y.copy()
        y[8] = 0.0  # L1' is zero to the event tolerance; make the clutch constraint exact
        return y, t, []


@dataclass(frozen=True)
class DelayedClutch:
    """Locks `delay_s` after maximum compression (sensing + actuation latency); the late lock is an
    inelastic leg impact that stops L1' and removes energy (reported as clutch loss)."""

    delay_s: float
    name: str = field(default="delayed")

    def lock(
        self,
        mech: Mechanics,
        integrator: Integrator,
        y: np.ndarray,
        t: float,
        *,
        record_dt: float | None,
        track_dissipation: bool,
    ) -> tuple[np.ndarray, float, list[PhaseRun]]:
        if self.delay_s <= 0.0:
            return IdealClutch().lock(mech, integrator, y, t, record_dt=record_dt, track_dissipation=track_dissipation)
        run = run_phase(
            integrator,
            mech,
            SLSP_FREE,
            y,
            t,
            (ev.TOUCHDOWN, ev.STALL, ev.LIFTOFF_B),
            self.delay_s,
            record_dt=record_dt,
            track_dissipation=track_dissipation,
        )
        _check_failed(run, "slsp_free")
        if run.guard == ev.TOUCHDOWN:
            raise StepFailure(
                FailureReason.TOUCHDOWN_BEFORE_CLUTCH,
                "the swing foot landed before the delayed lock",
                time_s=run.t_end,
                phase="slsp_free",
            )
        _raise_single_support_failure(run, "slsp_free")
        q, qd = run.y_end[:5], run.y_end[5:]
        M = mech.mass_matrix(q)
        A = np.zeros((3, 5))
        A[0, 0] = A[1, 1] = A[2, 3] = 1.0
        minv_at = np.linalg.solve(M, A.T)
        qd_new = qd - minv_at @ np.linalg.solve(A @ minv_at, A @ qd)
        qd_new[[0, 1, 3]] = 0.0
        return np.concatenate((q, qd_new)), run.t_end, [run]


def run_phase(
    integrator: Integrator,
    mech: Mechanics,
    phase: int,
    y: np.ndarray,
    t: float,
    guards: tuple[int, ...],
    t_max: float,
    *,
    record_dt: float | None,
    track_dissipation: bool,
) -> PhaseRun:
    """One base phase on `integrator`: as it is without guide friction, else its stick/slip sub-phases
    (rimless.sim.integrate.friction)."""
    if mech.params.guide_friction_n > 0.0:
        return run_with_friction(
            integrator, mech, phase, y, t, guards, t_max, record_dt=record_dt, track_dissipation=track_dissipation
        )
    return integrator.run_phase(
        mech, phase, y, t, guards, t_max, record_dt=record_dt, track_dissipation=track_dissipation
    )


def start_guard_value(mech: Mechanics, phase: int, code: int, y: np.ndarray) -> float:
    """Guard `code` at the start y of base phase `phase` (with guide friction: in the friction phase it starts in)."""
    if mech.params.guide_friction_n > 0.0:
        fcode, y = fr.initial_phase(mech, phase, y)
        return fr.guard_value(mech, fcode, code, y)
    return ev.guard_value(mech, phase, code, y)


def _check_failed(run: PhaseRun, phase: str) -> None:
    if run.failed:
        raise StepFailure(
            FailureReason.INTEGRATION, run.message or "the integrator failed", time_s=run.t_end, phase=phase
        )


def _raise_single_support_failure(run: PhaseRun, phase: str) -> None:
    failure = ev.failure_of(run.guard, run.t_end, phase)  # stall or stance lift-off
    if failure is not None:
        raise failure


class StepOptions(TypedDict, total=False):
    """simulate_step's keyword options that the Poincare maps' `step(z, **options)` pass through."""

    t0: float
    record_dt: float | None
    track_dissipation: bool
    diagnostics: bool
    strict_contact: bool


def simulate_step(
    mech: Mechanics,
    model: str,
    y0: np.ndarray,
    integrator: Integrator,
    *,
    t0: float = 0.0,
    clutch: ClutchPolicy | None = None,
    record_dt: float | None = None,
    track_dissipation: bool = False,
    diagnostics: bool = False,
    strict_contact: bool = False,
) -> StepResult:
    """Integrate one step from a post-impact state y0 (10,) through the impact.

    record_dt: sample the trajectory (dense output) at this spacing in s, plus every solver step.
    diagnostics: also compute minimum normal forces and the trailing foot's lowest point (needs samples).
    strict_contact: a leading-foot tension in double support or a trailing foot below the slope fails.
    """
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}")
    clutch = clutch or IdealClutch()
    if (diagnostics or strict_contact) and record_dt is None:
        record_dt = 2e-4
    runs: list[tuple[int, PhaseRun, float]] = []
    phases: list[PhaseRecord] = []
    nfev = 0
    dissipated = 0.0
    friction_work = 0.0
    stick = np.zeros(2)
    y = np.asarray(y0, dtype=float)
    t = t0

    def run(phase: int, guards: tuple[int, ...]) -> PhaseRun:
        nonlocal nfev, dissipated, friction_work
        r = run_phase(
            integrator,
            mech,
            phase,
            y,
            t,
            guards,
            PHASE_TIME_LIMIT_S,
            record_dt=record_dt,
            track_dissipation=track_dissipation,
        )
        nfev += r.nfev
        dissipated += r.dissipated_J
        friction_work += r.friction_J
        stick[:] += r.stick_s
        _check_failed(r, PHASE_NAMES[phase])
        runs.append((phase, r, t))
        phases.append(PhaseRecord(PHASE_NAMES[phase], t, r.t_end))
        return r

    if not np.all(np.isfinite(y)):
        raise StepFailure(FailureReason.INTEGRATION, "non-finite start state", time_s=t, phase="dlsp")

    def force(phase: int, code: int, state: np.ndarray, name: str) -> float:
        with np.errstate(over="ignore", invalid="ignore"):
            value = start_guard_value(mech, phase, code, state)
        if not np.isfinite(value):
            raise StepFailure(
                FailureReason.INTEGRATION,
                "non-finite contact forces (speeds or parameters too large to represent)",
                time_s=t,
                phase=name,
            )
        return value

    # 1. Double support. It may end at once if the trailing foot is unloaded right after impact.
    if not y[7] > 0.0:
        raise StepFailure(FailureReason.STALL, "theta' <= 0 at the start of the step", time_s=t, phase="dlsp")
    if force(DLSP, ev.LIFTOFF_A, y, "dlsp") > 0.0:
        r = run(DLSP, (ev.LIFTOFF_A, ev.STALL, ev.TOUCHDOWN))
        if r.guard == ev.STALL:
            raise StepFailure(FailureReason.STALL, "theta' reached 0 in double support", time_s=r.t_end, phase="dlsp")
        if r.guard == ev.TOUCHDOWN:
            raise StepFailure(
                FailureReason.DLSP_NEVER_ENDS,
                "the swing foot landed before the trailing foot lifted off",
                time_s=r.t_end,
                phase="dlsp",
            )
        if r.guard is None:
            raise StepFailure(
                FailureReason.DLSP_NEVER_ENDS,
                f"no lift-off within {PHASE_TIME_LIMIT_S} s",
                time_s=r.t_end,
                phase="dlsp",
            )
        y, t = r.y_end, r.t_end
    else:
        phases.append(PhaseRecord("dlsp", t, t))

    # 2. Single support.
    if not force(SLSP_FREE, ev.LIFTOFF_B, y, "slsp_free") > 0.0:
        raise StepFailure(
            FailureReason.STANCE_LIFT_OFF,
            "the stance foot is unloaded at the start of single support",
            time_s=t,
            phase="slsp_free",
        )
    clutch_loss = 0.0
    if model == "er":
        if y[8] >= 0.0:
            raise StepFailure(
                FailureReason.CLUTCH_MISSED,
                f"L1' = {y[8]:.3g} m/s >= 0 at lift-off: the stance leg's maximum compression "
                "happened in double support, before the clutch could lock",
                time_s=t,
                phase="slsp_free",
            )
        r = run(SLSP_FREE, (ev.CLUTCH_LOCK, ev.TOUCHDOWN, ev.STALL, ev.LIFTOFF_B))
        if r.guard == ev.TOUCHDOWN:
            raise StepFailure(
                FailureReason.TOUCHDOWN_BEFORE_CLUTCH,
                "the swing foot landed during free compression",
                time_s=r.t_end,
                phase="slsp_free",
            )
        _raise_single_support_failure(r, "slsp_free")
        if r.guard is None:
            raise StepFailure(
                FailureReason.INTEGRATION,
                f"free compression lasted over {PHASE_TIME_LIMIT_S} s",
                time_s=r.t_end,
                phase="slsp_free",
            )
        y, t, extra = clutch.lock(
            mech, integrator, r.y_end, r.t_end, record_dt=record_dt, track_dissipation=track_dissipation
        )
        for er in extra:
            nfev += er.nfev
            dissipated += er.dissipated_J
            friction_work += er.friction_J
            stick[:] += er.stick_s
            runs.append((SLSP_FREE, er, phases[-1].t_end_s))
            phases.append(PhaseRecord("slsp_free", phases[-1].t_end_s, er.t_end))
        if extra:
            clutch_loss = mech.energy(extra[-1].y_end[:5], extra[-1].y_end[5:]) - mech.energy(y[:5], y[5:])
        final_phase = SLSP_CLUTCHED
    else:
        final_phase = SLSP_FREE
    r = run(final_phase, (ev.TOUCHDOWN, ev.STALL, ev.LIFTOFF_B))
    _raise_single_support_failure(r, PHASE_NAMES[final_phase])
    if r.guard is None:
        raise StepFailure(
            FailureReason.STALL,
            f"no touchdown within {PHASE_TIME_LIMIT_S} s",
            time_s=r.t_end,
            phase=PHASE_NAMES[final_phase],
        )
    y_minus, t = r.y_end, r.t_end

    # 3. Impact.
    with np.errstate(over="ignore", invalid="ignore"):
        imp = impact(mech, y_minus[:5], y_minus[5:])
    if not (np.all(np.isfinite(imp.impulse)) and np.all(np.isfinite(imp.qd_plus)) and np.isfinite(t)):
        raise StepFailure(
            FailureReason.INTEGRATION, "non-finite impact (speeds too large to represent)", time_s=t, phase="impact"
        )
    if not (imp.impulse[1] > 0.0 and imp.impulse[3] > 0.0):
        raise StepFailure(
            FailureReason.NEGATIVE_IMPULSE,
            f"normal impulses b = {imp.impulse[1]:.4g} N s, a = {imp.impulse[3]:.4g} N s must be > 0",
            time_s=t,
            phase="impact",
        )
    result = StepResult(
        y_start=np.asarray(y0, dtype=float),
        y_minus=y_minus,
        y_plus=np.concatenate((imp.q_plus, imp.qd_plus)),
        t_start_s=t0,
        period_s=t - t0,
        phases=phases,
        impact=imp,
        nfev=nfev,
        dissipated_J=dissipated,
        clutch_loss_J=clutch_loss,
        relabel_snap_J=imp.relabel_snap_J,
        friction_work_J=friction_work,
        stick_s=(float(stick[0]), float(stick[1])),
    )
    if record_dt is not None:
        result.segments = [Segment(ph, r.t, r.y) for ph, r, _ in runs if r.t is not None and r.y is not None]
    if diagnostics or strict_contact:
        result.diagnostics = contact_diagnostics(mech, result.segments or [])
        if strict_contact:
            d = result.diagnostics
            if d["min_normal_force_b_dlsp_N"] < 0.0:
                raise StepFailure(
                    FailureReason.LEADING_FOOT_TENSION,
                    f"lambda_b,y reaches {d['min_normal_force_b_dlsp_N']:.3g} N in double support (--strict-contact)",
                    phase="dlsp",
                )
            if d["trailing_foot_min_height_m"] < 0.0:
                raise StepFailure(
                    FailureReason.TRAILING_FOOT_BELOW,
                    f"the lifted trailing foot dips {-d['trailing_foot_min_height_m'] * 1e3:.3g} mm "
                    "below the slope (--strict-contact)",
                    phase="slsp",
                )
    return result


def contact_diagnostics(mech: Mechanics, segments: list[Segment]) -> dict[str, float]:
    """Minimum normal forces per phase (N), how long the leading foot pulls in double support (s),
    and the lowest point of the lifted trailing foot (m, negative = below the slope), from samples."""
    inf = float("inf")
    out = {
        "min_normal_force_b_dlsp_N": inf,
        "min_normal_force_a_dlsp_N": inf,
        "min_normal_force_b_slsp_free_N": inf,
        "min_normal_force_b_slsp_clutched_N": inf,
        "leading_foot_tension_s": 0.0,
        "trailing_foot_min_height_m": inf,
    }
    for seg in segments:
        lam_b = np.empty(len(seg.t))
        for i, yi in enumerate(seg.y):
            _, lam = (
                fr.sample_accel(mech, seg.phase, yi)
                if mech.params.guide_friction_n > 0.0
                else accel(mech, seg.phase, yi[:5], yi[5:])
            )
            lam_b[i] = lam[1]
            if seg.phase == DLSP:
                out["min_normal_force_a_dlsp_N"] = min(out["min_normal_force_a_dlsp_N"], lam[3])
            else:
                out["trailing_foot_min_height_m"] = min(out["trailing_foot_min_height_m"], float(foot_a(yi[:5])[1]))
        key = f"min_normal_force_b_{PHASE_NAMES[seg.phase]}_N"
        if len(lam_b):
            out[key] = min(out[key], float(lam_b.min()))
        if seg.phase == DLSP and len(seg.t) > 1:
            neg = lam_b < 0.0
            dt = np.diff(seg.t)
            out["leading_foot_tension_s"] += float(np.sum(dt * (neg[:-1] & neg[1:])))
    return {k: (v if v != inf else float("nan")) for k, v in out.items()}
