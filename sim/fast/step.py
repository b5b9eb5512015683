"""The compiled step map: one step of the hybrid system from the section point z to the next post-impact
state, with the same phase sequence, pre-checks and failure classes as rimless.sim.step.hybrid.simulate_step
for the ideal clutch, and optionally the exact map Jacobian dP/dz.

Jacobian: the section tangent dy0/dz (10x2) is carried through each phase by the variational equations,
through each intermediate guard by the saltation matrix
    S = dR/dy + (f+ - dR/dy f-) (dg/dy) / (dg/dy f-)
(lift-off: R = identity; clutch lock: R sets L1' = 0, dR/dy = identity with row L1' zeroed), and through
touchdown by dR/dy (I - f- (dg/dy) / (dg/dy f-)) with R the exact relabel + impact reset: the map's
output is taken at the event, so no f+ term appears there. Then dz'/dz = rows (theta, theta') of the result.

Status codes are mapped to FailureReason by rimless.sim.fast.
"""

from __future__ import annotations

import math

import numpy as np

from rimless.sim.fast import model as fm
from rimless.sim.fast import rk, stiff
from rimless.sim.fast.ahead import compiling_ahead
from rimless.sim.fast.compiling import call_compiling, kernel
from rimless.sim.model.guards import DIRECTION

_jit = kernel  # numba.njit(cache=True), specialised on the mass model index only (compiling.kernel)
_inner = kernel(python=False)  # the same, called from compiled code only (no wrapper for Python)

OK = 0
STALL = 1
STANCE_LIFT_OFF = 2
TOUCHDOWN_BEFORE_CLUTCH = 3
CLUTCH_MISSED = 4
DLSP_NEVER_ENDS = 5
NEGATIVE_IMPULSE = 6
INTEGRATION = 7
TOO_MANY_STEPS = 8
NOT_FINITE = 9  # reported as an integration failure with its own message
# detail codes (which check failed), for the messages
D_NONE = 0
D_PRECHECK = 1  # failed a check at the start of a phase
D_GUARD = 2  # a guard fired
D_TIME_LIMIT = 3  # the phase time limit was reached
D_SOLVER = 4  # the integrator failed (step too small / not finite)
D_NOT_FINITE = 5  # non-finite forces or state (e.g. an overflowing speed)

PHASE_TIME_LIMIT_S = 5.0
IMPACT_PHASE = 3

# Double support lasts some 30 ms and DOP853 crosses it in one to three steps; the error made there dominates
# the map's error (it is carried through the whole step), while single support's errors at the same rtol are
# some hundred times smaller (measured at the Table 1 fixed points). The map therefore integrates double
# support at rtol * DLSP_RTOL_SCALE (not below DLSP_RTOL_FLOOR): a few more steps, for a given map error at
# a much looser rtol.
DLSP_RTOL_SCALE = 1e-4
DLSP_RTOL_FLOOR = 1e-13
# ... and, with near-massless legs (rimless.sim.fast.stiff.leg_stiff), not below DLSP_STIFF_FLOOR. Set when the
# double-support field came from the generated reduced equations, whose rounding error grows as eps (m_H / m)^2
# (measured at m = 0.1 g, Table 1's k and c, 12 post-impact states: at most 5 steps at rtol 1e-8; 1-4 at 1e-10
# except where double support ends in a stall, 580-6 600; at 1e-12 up to 57 000 or the step limit; at m = 1 mg
# no end within the step limit). That field now comes from the pivoted KKT solve (rimless.sim.fast.model.
# kkt_in_double_support, 1e-14 at 1e-4 to 1e-8 kg); the floor is kept as it was (not re-measured without it).
DLSP_STIFF_FLOOR = 1e-10

# the guards of each phase, with their directions from the one guard table (rimless.sim.model.guards)
PHASE_DLSP_CODES = np.array([fm.LIFTOFF_A, fm.STALL, fm.TOUCHDOWN], dtype=np.int64)
PHASE_FREE_ER_CODES = np.array([fm.CLUTCH_LOCK, fm.TOUCHDOWN, fm.STALL, fm.LIFTOFF_B], dtype=np.int64)
PHASE_SS_CODES = np.array([fm.TOUCHDOWN, fm.STALL, fm.LIFTOFF_B], dtype=np.int64)
PHASE_DLSP_DIRS = np.array([DIRECTION[int(c)] for c in PHASE_DLSP_CODES], dtype=np.int64)
PHASE_FREE_ER_DIRS = np.array([DIRECTION[int(c)] for c in PHASE_FREE_ER_CODES], dtype=np.int64)
PHASE_SS_DIRS = np.array([DIRECTION[int(c)] for c in PHASE_SS_CODES], dtype=np.int64)
# bilateral contact: the same guards without the stance foot's lift-off (LIFTOFF_B is last in both lists)
PHASE_FREE_ER_CODES_BI = PHASE_FREE_ER_CODES[:-1].copy()
PHASE_FREE_ER_DIRS_BI = PHASE_FREE_ER_DIRS[:-1].copy()
PHASE_SS_CODES_BI = PHASE_SS_CODES[:-1].copy()
PHASE_SS_DIRS_BI = PHASE_SS_DIRS[:-1].copy()
# step_map_contact's `contact` record (bilateral contact)
C_MIN_FORCE = 0  # smallest stance normal force lambda_b,y in single support, N
C_MIN_FORCE_T = 1  # its time, s
C_NEGATIVE_S = 2  # how long that force is < 0 in single support, s
C_MIN_IMPULSE = 3  # smallest normal impact impulse, N s
CONTACT_SIZE = 4
BILATERAL_RECORD_DT = 2e-4  # s: force samples between the solver's steps (bilateral mode only)


@_inner
def _get_V(ya):
    V = np.empty((10, 2))
    for c in range(2):
        for i in range(10):
            V[i, c] = ya[rk.VAR_OFFSET + 10 * c + i]
    return V


@_inner
def _set_V(ya, V):
    for c in range(2):
        for i in range(10):
            ya[rk.VAR_OFFSET + 10 * c + i] = V[i, c]


@_inner
def _saltation(V, f_minus, f_plus, dg, reset_index):
    """S V with S = dR + (f+ - dR f-) dg^T / (dg . f-); dR = identity, with row reset_index zeroed if >= 0."""
    den = 0.0
    for i in range(10):
        den += dg[i] * f_minus[i]
    out = np.empty((10, 2))
    for c in range(2):
        gv = 0.0
        for i in range(10):
            gv += dg[i] * V[i, c]
        for i in range(10):
            rv = V[i, c]
            rf = f_minus[i]
            if i == reset_index:
                rv = 0.0
                rf = 0.0
            out[i, c] = rv + (f_plus[i] - rf) * gv / den
    return out


@_inner
def _finite(a, b):
    for i in range(a.shape[0]):
        if not math.isfinite(a[i]):
            return False
    for i in range(b.shape[0]):
        if not math.isfinite(b[i]):
            return False
    return True


@_inner
def _map_status(st, fired_ok):
    if st == rk.STATUS_NOT_FINITE:
        return NOT_FINITE
    if st == rk.STATUS_TOO_MANY_STEPS:
        return TOO_MANY_STEPS
    return INTEGRATION


@_jit
def single_support_force(mi, phase, rec_t, rec_y, p, contact):
    """Fold foot b's normal force lambda_b,y (N) at the recorded states (rec_t s, rec_y) of one phase into
    `contact`: its minimum (refined by a parabola through its neighbours), the minimum's time and the time spent
    below zero. In single support foot b is the stance foot; in double support (as rimless.sim.continuation.arclength also
    uses it) the leading foot, whose time below zero is its tensile transient."""
    n = rec_t.shape[0]
    if n == 0:
        return
    qdd = np.empty(5)
    lam = np.zeros(4)
    f = np.empty(n)
    for i in range(n):
        fm.accel(mi, phase, rec_y[i, :5], rec_y[i, 5:10], p, qdd, lam)
        f[i] = lam[1]
    for i in range(n - 1):  # time below zero, zero crossings interpolated linearly
        a, b, dt = f[i], f[i + 1], rec_t[i + 1] - rec_t[i]
        if a < 0.0 and b < 0.0:
            contact[C_NEGATIVE_S] += dt
        elif a < 0.0 <= b:
            contact[C_NEGATIVE_S] += dt * a / (a - b)
        elif b < 0.0 <= a:
            contact[C_NEGATIVE_S] += dt * b / (b - a)
    j = 0
    for i in range(1, n):
        if f[i] < f[j]:
            j = i
    fmin, tmin = f[j], rec_t[j]
    if 0 < j < n - 1:
        t0, t1, t2 = rec_t[j - 1], rec_t[j], rec_t[j + 1]
        d1 = (f[j] - f[j - 1]) / (t1 - t0)
        d2 = (f[j + 1] - f[j]) / (t2 - t1)
        curv = (d2 - d1) / (t2 - t0)  # half the second derivative
        if curv > 0.0:
            tv = 0.5 * (t0 + t1) - d1 / (2.0 * curv)
            if t0 <= tv <= t2:
                fv = f[j] + (tv - t1) * (d1 + curv * (tv - t0))
                if fv <= fmin:
                    fmin, tmin = fv, tv
    if fmin < contact[C_MIN_FORCE]:
        contact[C_MIN_FORCE] = fmin
        contact[C_MIN_FORCE_T] = tmin


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def dlsp_tolerances(rtol, atol, p):
    """(rtol, atol) of the double-support phase for the map's (rtol, atol); p the parameter vector."""
    floor = DLSP_STIFF_FLOOR if stiff.leg_stiff(p) else DLSP_RTOL_FLOOR
    scale = min(1.0, max(rtol * DLSP_RTOL_SCALE, floor) / rtol) if rtol > 0.0 else 1.0
    return rtol * scale, atol * scale


@_jit(inline="always")  # three call sites in step_kernel: no library level of its own
def _run_phase(
    mi,
    phase,
    p,
    ya,
    t,
    codes,
    dirs,
    rtol,
    atol,
    want_jac,
    max_steps,
    ending,
    touchdown_status,
    time_limit_status,
    counts,
    rec_dt,
    contact,
):
    """One phase of the map from (t, ya) until a guard of `codes` fires, counted into counts[phase].

    Returns (status, detail, t_end, y_end, nfev, nsteps, nstiff): status OK when the phase ended at its guard
    `ending`; else the failure: the integrator's (D_SOLVER), time_limit_status at the phase time limit,
    STALL / STANCE_LIFT_OFF at the stall / stance lift-off guards, touchdown_status at an early touchdown.
    rec_dt > 0 (bilateral contact with a record): the states every rec_dt s go into `contact`'s stance force."""
    if phase != fm.DLSP and stiff.leg_stiff(p):  # near-massless legs: Rosenbrock (stiff.py), with V if want_jac
        st, t_end, y_end, fired, nf, ns, nst, rec_t, rec_y = stiff.run_phase_stiff(
            mi, phase, p, ya, t, codes, dirs, PHASE_TIME_LIMIT_S, rtol, atol, 10, False, rec_dt, max_steps
        )
    else:
        st, t_end, y_end, fired, nf, ns, nst, rec_t, rec_y = rk.run_phase(
            mi, phase, p, ya, t, codes, dirs, PHASE_TIME_LIMIT_S, rtol, atol, 10, want_jac, False, rec_dt, max_steps
        )
    if rec_dt > 0.0:
        single_support_force(mi, phase, rec_t, rec_y, p, contact)
    counts[phase, 0] = nf
    counts[phase, 1] = ns
    if st != rk.STATUS_OK:
        return _map_status(st, fired), D_SOLVER, t_end, y_end, nf, ns, nst
    if fired < 0:
        return time_limit_status, D_TIME_LIMIT, t_end, y_end, nf, ns, nst
    code = codes[fired]
    if code == ending:
        return OK, D_NONE, t_end, y_end, nf, ns, nst
    if code == fm.STALL:
        return STALL, D_GUARD, t_end, y_end, nf, ns, nst
    if code == fm.TOUCHDOWN:
        return touchdown_status, D_GUARD, t_end, y_end, nf, ns, nst
    return STANCE_LIFT_OFF, D_GUARD, t_end, y_end, nf, ns, nst


def step_map(mi, er, p, z, rtol, atol, want_jac, max_steps, counts):
    """One step from z = (theta+ rad, theta'+ rad/s) (foot b at the origin); unilateral contact (see
    step_map_contact)."""
    return step_map_contact(mi, er, p, z, rtol, atol, want_jac, max_steps, counts, False, np.empty(0))


def step_map_contact(mi, er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact):
    """step_kernel for mass model index mi through its own entry point (STEP_MAP_CONTACT[mi]), so that only
    that mass model's generated code is compiled."""
    return call_compiling(
        STEP_MAP_CONTACT[mi],
        er,
        p,
        z,
        rtol,
        atol,
        want_jac,
        max_steps,
        counts,
        bilateral,
        contact,
        ahead=lambda: compiling_ahead(mi),
    )


@_jit(inline="always")  # one call site per mass model entry point below
def step_kernel(mi, er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact):
    """One step from z = (theta+ rad, theta'+ rad/s) (foot b at the origin).

    bilateral=False: unilateral contact, the step fails with STANCE_LIFT_OFF / NEGATIVE_IMPULSE. bilateral=True:
    the stance foot is held (no lift-off guard, no pre-check) and a non-positive impulse is accepted, so a fixed
    point that violates unilateral contact can be found and characterised. With bilateral=True and `contact`
    of size CONTACT_SIZE, it receives the smallest single-support stance force (N, from the states every
    BILATERAL_RECORD_DT s and every solver step, which about doubles the step's cost), its time (s), the time
    that force is negative (s) and the smallest normal impulse (N s); with `contact` of size 0 nothing is
    recorded.


    Returns (status, detail, phase, t_s, y_plus (10,), J (2x2), times (3,), nfev, nsteps, nstiff, snap_J):
    status OK or a failure code; phase 0/1/2 (dlsp/slsp_free/slsp_clutched) or 3 (impact) where it ended;
    t_s the step period (or the failure time), s; times = end of dlsp, end of free compression (ER; else
    the touchdown time), touchdown, s; J = dz'/dz when want_jac (else zeros); snap_J the mechanical
    energy the relabelling adds by snapping the old trailing leg to L0 with zero rate (J, signed: > 0 adds
    energy, < 0 removes it; 0 unless the step ends in a valid impact). counts (3x2 int64, zeroed here)
    receives each phase's right-hand-side evaluations and accepted steps (rows dlsp, slsp_free, slsp_clutched).
    """
    y0, T = fm.state_from_section(mi, z, p)
    N = 30 if want_jac else 10
    ya = np.zeros(N)
    for i in range(10):  # not ya[:10] = y0: numba's slice copy compiles its shape-mismatch message, ~2.5 s cold
        ya[i] = y0[i]
    if want_jac:
        _set_V(ya, T)
    J = np.zeros((2, 2))
    times = np.zeros(3)
    yp = np.zeros(10)
    nfev = 0
    nsteps = 0
    nstiff = 0
    snap = 0.0
    t = 0.0
    counts[:, :] = 0
    qdd = np.empty(5)
    lam = np.zeros(4)
    record = bilateral and contact.shape[0] >= CONTACT_SIZE
    if record:
        contact[C_MIN_FORCE] = np.inf
        contact[C_MIN_FORCE_T] = -1.0
        contact[C_NEGATIVE_S] = 0.0
        contact[C_MIN_IMPULSE] = np.nan
    rec_dt = BILATERAL_RECORD_DT if record else -1.0
    for i in range(10):
        if not np.isfinite(y0[i]):
            return INTEGRATION, D_PRECHECK, 0, t, yp, J, times, nfev, nsteps, nstiff, snap
    # 1. double support
    if y0[7] <= 0.0:
        return STALL, D_PRECHECK, 0, t, yp, J, times, nfev, nsteps, nstiff, snap
    if not fm.accel(mi, fm.DLSP, y0[:5], y0[5:10], p, qdd, lam):
        return INTEGRATION, D_SOLVER, 0, t, yp, J, times, nfev, nsteps, nstiff, snap
    if not _finite(qdd, lam):
        return INTEGRATION, D_NOT_FINITE, 0, t, yp, J, times, nfev, nsteps, nstiff, snap
    if lam[3] > 0.0:
        rtol_d, atol_d = dlsp_tolerances(rtol, atol, p)
        st, detail, t_end, y_end, nf, ns, nst = _run_phase(
            mi,
            fm.DLSP,
            p,
            ya,
            t,
            PHASE_DLSP_CODES,
            PHASE_DLSP_DIRS,
            rtol_d,
            atol_d,
            want_jac,
            max_steps,
            fm.LIFTOFF_A,
            DLSP_NEVER_ENDS,
            DLSP_NEVER_ENDS,
            counts,
            -1.0,
            contact,
        )
        nfev += nf
        nsteps += ns
        nstiff += nst
        if st != OK:
            return st, detail, 0, t_end, yp, J, times, nfev, nsteps, nstiff, snap
        ya = y_end
        t = t_end
        if want_jac:
            ys = ya[:10].copy()
            fmin = fm.phase_field(mi, fm.DLSP, ys, p)
            fplus = fm.phase_field(mi, fm.SLSP_FREE, ys, p)
            dg = fm.guard_gradient(mi, fm.DLSP, fm.LIFTOFF_A, ys, p)
            _set_V(ya, _saltation(_get_V(ya), fmin, fplus, dg, -1))
    times[0] = t
    # 2. single support
    ys = ya[:10].copy()
    if not fm.accel(mi, fm.SLSP_FREE, ys[:5], ys[5:10], p, qdd, lam):
        return INTEGRATION, D_SOLVER, 1, t, yp, J, times, nfev, nsteps, nstiff, snap
    if not _finite(qdd, lam):
        return INTEGRATION, D_NOT_FINITE, 1, t, yp, J, times, nfev, nsteps, nstiff, snap
    if not (lam[1] > 0.0) and not bilateral:
        return STANCE_LIFT_OFF, D_PRECHECK, 1, t, yp, J, times, nfev, nsteps, nstiff, snap
    if er:
        if ys[8] >= 0.0:
            return CLUTCH_MISSED, D_PRECHECK, 1, t, yp, J, times, nfev, nsteps, nstiff, snap
        codes = PHASE_FREE_ER_CODES_BI if bilateral else PHASE_FREE_ER_CODES
        dirs = PHASE_FREE_ER_DIRS_BI if bilateral else PHASE_FREE_ER_DIRS
        st, detail, t_end, y_end, nf, ns, nst = _run_phase(
            mi,
            fm.SLSP_FREE,
            p,
            ya,
            t,
            codes,
            dirs,
            rtol,
            atol,
            want_jac,
            max_steps,
            fm.CLUTCH_LOCK,
            TOUCHDOWN_BEFORE_CLUTCH,
            INTEGRATION,
            counts,
            rec_dt,
            contact,
        )
        nfev += nf
        nsteps += ns
        nstiff += nst
        if st != OK:
            return st, detail, 1, t_end, yp, J, times, nfev, nsteps, nstiff, snap
        ya = y_end
        t = t_end
        if want_jac:
            ys = ya[:10].copy()
            fmin = fm.phase_field(mi, fm.SLSP_FREE, ys, p)
            ys[8] = 0.0
            fplus = fm.phase_field(mi, fm.SLSP_CLUTCHED, ys, p)
            dg = fm.guard_gradient(mi, fm.SLSP_FREE, fm.CLUTCH_LOCK, ys, p)
            _set_V(ya, _saltation(_get_V(ya), fmin, fplus, dg, 8))
        ya[8] = 0.0  # the ideal clutch makes L1' = 0 exact
        final = fm.SLSP_CLUTCHED
    else:
        final = fm.SLSP_FREE
    times[1] = t
    codes = PHASE_SS_CODES_BI if bilateral else PHASE_SS_CODES
    dirs = PHASE_SS_DIRS_BI if bilateral else PHASE_SS_DIRS
    st, detail, t_end, y_end, nf, ns, nst = _run_phase(
        mi,
        final,
        p,
        ya,
        t,
        codes,
        dirs,
        rtol,
        atol,
        want_jac,
        max_steps,
        fm.TOUCHDOWN,
        STALL,
        STALL,
        counts,
        rec_dt,
        contact,
    )
    nfev += nf
    nsteps += ns
    nstiff += nst
    if st != OK:
        return st, detail, final, t_end, yp, J, times, nfev, nsteps, nstiff, snap
    ya = y_end
    t = t_end
    times[2] = t
    # 3. impact
    ym = ya[:10].copy()
    if want_jac:
        V = _get_V(ya)
        fmin = fm.phase_field(mi, final, ym, p)
        dg = fm.guard_gradient(mi, final, fm.TOUCHDOWN, ym, p)
        # project out the touchdown-time variation: (I - f- dg^T / (dg . f-)) V
        # _saltation with f+ = 0 and dR = I gives V - f- (dg V)/(dg f-): exactly this projection
        V = _saltation(V, fmin, np.zeros(10), dg, -1)
    else:
        V = np.zeros((10, 2))
    ok, yp, impulse, Vp = fm.impact(mi, ym, p, V, want_jac)
    if not ok:
        return INTEGRATION, D_SOLVER, IMPACT_PHASE, t, yp, J, times, nfev, nsteps, nstiff, snap
    if not (_finite(yp, impulse) and math.isfinite(t)):
        return INTEGRATION, D_NOT_FINITE, IMPACT_PHASE, t, yp, J, times, nfev, nsteps, nstiff, snap
    if record:
        contact[C_MIN_IMPULSE] = min(impulse[1], impulse[3])
    if not (impulse[1] > 0.0 and impulse[3] > 0.0) and not bilateral:
        return NEGATIVE_IMPULSE, D_GUARD, IMPACT_PHASE, t, yp, J, times, nfev, nsteps, nstiff, snap
    yt, _D = fm.relabel_with_jacobian(ym, p[3])
    snap = fm.energy(mi, yt[:5], yt[5:10], p) - fm.energy(mi, ym[:5], ym[5:10], p)
    if want_jac:
        J[0, 0] = Vp[2, 0]
        J[0, 1] = Vp[2, 1]
        J[1, 0] = Vp[7, 0]
        J[1, 1] = Vp[7, 1]
    return OK, D_NONE, IMPACT_PHASE, t, yp, J, times, nfev, nsteps, nstiff, snap


# Per-mass-model entry points: the index is a compile-time constant in each, so a command compiles the
# generated code of its own mass model only (rimless.sim.fast.model's overloads); index them by MASS_MODEL_INDEX.
@_jit
def step_map_contact_0(er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact):
    return step_kernel(0, er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact)


@_jit
def step_map_contact_1(er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact):
    return step_kernel(1, er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact)


@_jit
def step_map_contact_2(er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact):
    return step_kernel(2, er, p, z, rtol, atol, want_jac, max_steps, counts, bilateral, contact)


STEP_MAP_CONTACT = (step_map_contact_0, step_map_contact_1, step_map_contact_2)
