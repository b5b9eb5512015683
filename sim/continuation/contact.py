"""Contact and stall facts of one step, measured on its recorded trajectory: the smallest stance normal force
in single support (N), the smallest normal impact impulse (N s), the leading foot's tension in double support,
the lifted foot's lowest point (m), the friction the impact needs; under unilateral or bilateral contact."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from rimless.sim.model.failures import StepFailure


@dataclass
class ContactFacts:
    """Contact and stall facts of one step from its recorded trajectory (N, N s, rad/s, s, m)."""

    min_stance_force_single_support_N: float
    min_impulse_N_s: float
    min_theta_dot_single_support_rad_s: float
    leading_foot_tension_N: float  # most negative leading-foot normal force in double support (0 if none)
    leading_foot_tension_s: float
    trailing_foot_min_height_m: float
    friction_required: float  # max over both feet of |tangential| / normal impact impulse
    period_s: float
    energy_ratio: float
    relabel_energy_J: float  # energy added by the relabelling snap of the old trailing leg (+ adds)
    # under bilateral contact (the stance foot held; a gait that unilateral contact forbids):
    bilateral: bool = False
    min_stance_force_time_s: float = math.nan  # when the smallest single-support stance force occurs, s
    negative_stance_force_s: float = 0.0  # how long that force is below 0, s
    unilateral_failure: str = ""  # the unilateral map's failure at this point ('' when it accepts the step)

    @property
    def contact_valid(self) -> bool:
        """Unilateral contact in single support and at the impact (the double-support transient is reported,
        not rejected: it is the rigid-contact artefact the paper discusses)."""
        return (
            self.min_stance_force_single_support_N >= 0.0 and self.min_impulse_N_s > 0.0 and not self.unilateral_failure
        )

    @property
    def violation(self) -> str:
        """What unilateral contact forbids here: 'stance-lift-off', 'negative-impulse' (both: joined by ', '),
        or '' when the gait is contact-valid."""
        kinds = []
        if not self.min_stance_force_single_support_N >= 0.0 or "stance-lift-off" in self.unilateral_failure:
            kinds.append("stance-lift-off")
        if not self.min_impulse_N_s > 0.0 or "negative-impulse" in self.unilateral_failure:
            kinds.append("negative-impulse")
        if not kinds and self.unilateral_failure:
            kinds.append("unilateral-map-fails")
        return ", ".join(kinds)

    @property
    def strict_contact_valid(self) -> bool:
        return self.contact_valid and self.leading_foot_tension_N >= 0.0 and self.trailing_foot_min_height_m >= 0.0

    def as_dict(self) -> dict[str, float | bool | str]:
        d: dict[str, float | bool | str] = dict(self.__dict__)
        d["contact_valid"] = self.contact_valid
        d["strict_contact_valid"] = self.strict_contact_valid
        d["violation"] = self.violation
        return d


def contact_facts(pmap: Any, z: np.ndarray, record_dt: float = 2e-4) -> ContactFacts:
    """Record the step from z (samples every record_dt s plus every solver step) and measure its contact
    and stall facts.

    A bilateral map (`bilateral` true: the stance foot held) records the step under bilateral contact and adds
    the compiled map's own record of the stance force (rimless.sim.fast.BilateralContact: its minimum, when, how
    long it is negative) and the unilateral map's failure at z, if any."""
    from rimless.sim.model.dynamics import DLSP

    z = np.asarray(z, dtype=float)
    if getattr(pmap, "bilateral", False):
        return _bilateral_facts(pmap, z, record_dt)
    return _facts_of_step(_recorded_step(pmap, z, record_dt), DLSP)


def _recorded_step(pmap: Any, z: np.ndarray, record_dt: float) -> Any:
    """The step from z with its samples and contact diagnostics (hybrid.contact_diagnostics' keys); the
    normal forces' minima and the leading foot's tension time come from the compiled kernel
    (rimless.sim.fast.step) on the same samples, the minimum refined by a parabola, the tension time with its
    zero crossings interpolated."""
    try:
        from rimless.sim.fast import mass_model_index, param_vector
        from rimless.sim.fast import step as fs
    except ImportError:  # no compiled path: the reference diagnostics
        return pmap.step(z, diagnostics=True, record_dt=record_dt)
    from rimless.sim.model.dynamics import DLSP
    from rimless.sim.model.mechanics import ALPHA
    from rimless.sim.step.hybrid import PHASE_NAMES

    step = pmap.step(z, record_dt=record_dt)
    mi, p = mass_model_index(pmap.params), param_vector(pmap.params)
    inf = math.inf
    d = {
        "min_normal_force_b_dlsp_N": inf,
        "min_normal_force_b_slsp_free_N": inf,
        "min_normal_force_b_slsp_clutched_N": inf,
        "leading_foot_tension_s": 0.0,
        "trailing_foot_min_height_m": inf,
    }
    for seg in step.segments or []:
        if not len(seg.t):
            continue
        y = np.ascontiguousarray(seg.y, dtype=np.float64)
        c = np.array([inf, -1.0, 0.0, math.nan])
        fs.single_support_force(mi, int(seg.phase), np.ascontiguousarray(seg.t, dtype=np.float64), y, p, c)
        key = f"min_normal_force_b_{PHASE_NAMES[seg.phase]}_N"
        d[key] = min(d[key], float(c[fs.C_MIN_FORCE]))
        if seg.phase == DLSP:
            d["leading_foot_tension_s"] += float(c[fs.C_NEGATIVE_S])
        else:  # the lifted trailing foot's height above the slope; when the stance force is smallest
            if c[fs.C_MIN_FORCE] <= min(d["min_normal_force_b_slsp_free_N"], d["min_normal_force_b_slsp_clutched_N"]):
                d["min_normal_force_b_single_support_time_s"] = float(c[fs.C_MIN_FORCE_T]) - step.t_start_s
            q2 = y[:, 2]
            h = y[:, 1] + y[:, 3] * np.cos(q2) - y[:, 4] * np.cos(q2 + ALPHA)
            d["trailing_foot_min_height_m"] = min(d["trailing_foot_min_height_m"], float(np.min(h)))
    step.diagnostics = {k: (v if v != inf else math.nan) for k, v in d.items()}
    return step


def _bilateral_facts(pmap: Any, z: np.ndarray, record_dt: float) -> ContactFacts:
    from dataclasses import replace

    from rimless.sim import fast
    from rimless.sim.model.dynamics import DLSP

    integ = pmap.integrator
    rec = fast.fast_step(pmap.params, pmap.model, z, rtol=integ.rtol, atol=integ.atol, bilateral=True)
    c = rec.contact
    assert c is not None  # bilateral=True records it
    try:
        fast.fast_step(pmap.params, pmap.model, z, rtol=integ.rtol, atol=integ.atol)
        uni = ""
    except StepFailure as err:
        uni = f"{err.reason.value}: {err}"
    try:
        facts = _facts_of_step(_recorded_step(pmap, z, record_dt), DLSP)
    except StepFailure:  # the recorded step's own checks (stance force or impulses at a phase start): the
        # compiled record alone
        facts = ContactFacts(
            c.min_stance_force_N,
            c.min_impulse_N_s,
            math.nan,
            math.nan,
            math.nan,
            math.nan,
            math.nan,
            rec.period_s,
            math.nan,
            rec.relabel_snap_J,
        )
    # the stance force from the compiled record (finer samples, parabola at the minimum): the same number the
    # continuation's test function uses between recorded points
    return replace(
        facts,
        bilateral=True,
        min_stance_force_single_support_N=c.min_stance_force_N,
        min_stance_force_time_s=c.min_stance_force_time_s,
        negative_stance_force_s=c.negative_force_s,
        unilateral_failure=uni,
    )


def _facts_of_step(step: Any, DLSP: int) -> ContactFacts:
    d = step.diagnostics or {}
    single = [d.get("min_normal_force_b_slsp_free_N", math.nan), d.get("min_normal_force_b_slsp_clutched_N", math.nan)]
    single = [v for v in single if v == v]
    th_min = math.inf
    for seg in step.segments or []:
        if seg.phase != DLSP and len(seg.t):
            th_min = min(th_min, float(np.min(seg.y[:, 7])))
    imp = step.impact
    lead = d.get("min_normal_force_b_dlsp_N", math.nan)
    return ContactFacts(
        min_stance_force_time_s=float(d.get("min_normal_force_b_single_support_time_s", math.nan)),
        min_stance_force_single_support_N=min(single) if single else math.nan,
        min_impulse_N_s=float(min(imp.impulse[1], imp.impulse[3])),
        min_theta_dot_single_support_rad_s=th_min,
        leading_foot_tension_N=min(0.0, lead) if lead == lead else 0.0,
        leading_foot_tension_s=float(d.get("leading_foot_tension_s", 0.0)),
        trailing_foot_min_height_m=float(d.get("trailing_foot_min_height_m", math.nan)),
        friction_required=float(max(imp.friction_required)),
        period_s=step.period_s,
        energy_ratio=imp.energy_ratio,
        relabel_energy_J=-float(imp.relabel_loss),
    )
