"""One concept: the compiled DOP853 integrator of one phase with its event location (the numba twin of
rimless.sim.integrate.events), kept in one module so the kernels inline each other.

Compiled DOP853 (Dormand-Prince 8(5,3), the same tableau, error norm, step-size control, initial step and
7th-order dense output as scipy's solve_ivp 'DOP853') for one phase of the hybrid system, with terminal
guard location on the dense output (Brent's method to 4 eps in t, the scipy semantics: a guard fires when
it crosses 0 in its direction between two accepted steps; the earliest root wins).

The integrated vector is y_aug = [y (10,), V (10x2, column-major, optional), E_diss (optional)]:
- y = [q, q'] in SI units (slope frame);
- V = dy/dz, the tangent of two section directions, integrated with the variational equations
  V' = Df(y) V (Df exact: rimless.sim.fast.model.accel_jacobian); the step size is controlled on y only
  (internal differentiation: V is the exact derivative of the discrete flow up to the step-size choice);
- E_diss = integral of the damper power, J (then included in the error norm, as in the reference).

Extra (beyond scipy): a touchdown that grazes the slope inside one step (swing height > 0 at both step
ends with a minimum below 0 in between) is detected from the sign change of the height's rate and located
on the dense output, so it is not missed. Likewise a normal-force guard (lift-off of foot a or b) that dips
below zero and recovers between two step ends: around every discrete minimum of the force over the step
ends (the previous step's stages are kept for this), the force is minimised on the dense output (samples,
then Brent's minimiser) and its first zero located. Non-finite values, NaN step sizes and more than
MAX_REJECTIONS rejected attempts end the phase with a failure status. A stiffness indicator (Hairer's
h |lambda| estimate from the last two stages, > 6.1 counts a "stiff step") is returned; a phase that needs
more than `max_steps` steps ends with STATUS_TOO_MANY_STEPS so the caller can switch to an implicit method.

The state at a guard is not read off the dense output: one DOP853 step from the start of the step holding
the event to the event time (located on the dense output) gives it with the step's accuracy (the
interpolant is an order less accurate, and its error dominated the map's error at loose tolerances).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.integrate import DOP853

from rimless.sim.fast import model as fm
from rimless.sim.fast.compiling import kernel
from rimless.sim.integrate.events import DIP_MARGIN, DIP_SAMPLES
from rimless.sim.model.clutch import SLIP_DOWN, SLIP_UP, STUCK
from rimless.sim.model.friction import FRICTION_INDEX, FRICTION_PHASE0
from rimless.sim.model.guards import SLIP_END_1, SLIP_END_2, STICK_END_1, STICK_END_2

_jit = kernel  # numba.njit(cache=True), specialised on the mass model index only (compiling.kernel)
_inner = kernel(python=False)  # the same, called from compiled code only (no wrapper for Python)

# Tableau of scipy's public DOP853 class (module-level arrays are frozen into the compiled code as constants):
# the 12 stages, the 13th (the B row, the step's end) and the 3 extra stages of the 7th-order dense output.
_NS = 12
_NSE = 16
_A = np.zeros((_NSE, _NSE), dtype=np.float64)
_A[:_NS, :_NS] = DOP853.A
_A[_NS, :_NS] = DOP853.B
_A[_NS + 1 :] = DOP853.A_EXTRA
_B = np.ascontiguousarray(DOP853.B, dtype=np.float64)
_C = np.ascontiguousarray(np.concatenate((DOP853.C, [1.0], DOP853.C_EXTRA)), dtype=np.float64)
_E3 = np.ascontiguousarray(DOP853.E3, dtype=np.float64)
_E5 = np.ascontiguousarray(DOP853.E5, dtype=np.float64)
_D = np.ascontiguousarray(DOP853.D, dtype=np.float64)
_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_ERR_EXP = -1.0 / 8.0
_EPS = np.finfo(float).eps

STATUS_OK = 0  # a guard fired or the time limit was reached (guard = -1)
STATUS_STEP_TOO_SMALL = 1
STATUS_NOT_FINITE = 2
STATUS_TOO_MANY_STEPS = 3

MAX_REJECTIONS = 100_000  # rejected step attempts per phase before giving up (bounded time)
STATE_SIZE = 10
VAR_OFFSET = 10
VAR_SIZE = 20


@_inner
def rhs_aug(mi, phase, p, y, with_var, with_diss, f, lam, ws):
    """Right-hand side of the augmented vector; lambda at y into lam. False if the KKT matrix is singular.
    ws: float64 workspace of model.WORKSPACE_SIZE + 5."""
    q = y[0:5]
    qd = y[5:10]
    qdd = ws[fm.WORKSPACE_SIZE : fm.WORKSPACE_SIZE + 5]
    if with_var:
        V = y[VAR_OFFSET : VAR_OFFSET + VAR_SIZE].reshape((2, 10)).T
        dqdd = ws[0:10].reshape((5, 2))  # no allocation per evaluation
        if phase >= FRICTION_PHASE0:
            ok = _friction_directional(mi, phase, q, qd, p, qdd, lam, V, dqdd)
        else:
            ok = fm.accel_directional(mi, phase, q, qd, p, qdd, lam, V, dqdd, ws)
        if not ok:
            return False
        for col in range(2):
            o = VAR_OFFSET + 10 * col
            for i in range(5):
                f[o + i] = y[o + 5 + i]
                f[o + 5 + i] = dqdd[i, col]
    else:
        ok = _accel_any(mi, phase, q, qd, p, qdd, lam, ws)
        if not ok:
            return False
    for i in range(5):
        f[i] = qd[i]
        f[5 + i] = qdd[i]
    if with_diss:
        f[y.shape[0] - 1] = fm.damping_power(_base_phase(phase), qd, p)
    return True


# ------------------------------------------------------------------------------------------------
# Guide friction (rimless.sim.model.friction): phase codes >= FRICTION_PHASE0 are a base phase with each
# friction leg slipping up/down (-/+ F_c on L) or stuck (L' = 0 a constraint); F_c = p[FRICTION_INDEX].
# With the variational equations too (`_friction_directional`: the map Jacobian with friction, rimless.sim.fast.
# friction). The leg states are rimless.sim.model.clutch's SLIP_UP, SLIP_DOWN and STUCK.


@_inner
def _base_phase(phase):
    if phase >= FRICTION_PHASE0:
        return (phase - FRICTION_PHASE0) // 16
    return phase


@_inner
def _leg_state(phase, leg):
    c = phase - FRICTION_PHASE0
    return (c % 16) // 4 if leg == 1 else c % 4


@_inner
def _stuck_row(phase, leg):
    """Row of leg `leg`'s holding force in lambda of a friction phase (b: 0-1, a: 2-3 in double support)."""
    base = _base_phase(phase)
    r = 4 if base == fm.DLSP else 2
    if leg == 2 and _leg_state(phase, 1) == STUCK:
        r += 1
    return r


@_inner
def _friction_kkt(mi, phase, q, qd, p, K, piv):
    """Assemble and factor the KKT matrix [[M, -A^T], [A, 0]] of a friction phase into K (11 x 11 workspace):
    A's rows foot b, [foot a], [L1' = 0 if stuck], [L2' = 0 if stuck]. Returns (ok, n, nc, h, A' q')."""
    M, h, Ja, jd = fm.terms(mi, q, qd, p)
    base = _base_phase(phase)
    A = np.zeros((6, 5))
    adot = np.zeros(6)
    A[0, 0] = 1.0
    A[1, 1] = 1.0
    nc = 2
    if base == fm.DLSP:
        for r in range(2):
            adot[2 + r] = jd[r]
            for c in range(5):
                A[2 + r, c] = Ja[r, c]
        nc = 4
    if _leg_state(phase, 1) == STUCK:
        A[nc, 3] = 1.0
        nc += 1
    if _leg_state(phase, 2) == STUCK:
        A[nc, 4] = 1.0
        nc += 1
    n = 5 + nc
    for i in range(5):
        for j in range(5):
            K[i, j] = M[i, j]
    for r in range(nc):
        for c in range(5):
            K[c, 5 + r] = -A[r, c]
            K[5 + r, c] = A[r, c]
    return fm.lu_factor(K, n, piv), n, nc, h, adot


@_inner
def _friction_accel(mi, phase, q, qd, p, qdd, lam):
    """q'' and lambda (rows: b_x, b_y, [a_x, a_y], [L1], [L2]) of a friction phase by the KKT solve of
    [[M, -A^T], [A, 0]] [q''; lambda] = [-h + f_friction; -A' q'] (rimless.sim.model.clutch.accel)."""
    s1 = _leg_state(phase, 1)
    s2 = _leg_state(phase, 2)
    F = p[FRICTION_INDEX]
    K = np.zeros((11, 11))
    piv = np.empty(11, dtype=np.int64)
    ok, n, nc, h, adot = _friction_kkt(mi, phase, q, qd, p, K, piv)
    if not ok:
        return False
    b = np.empty(n)
    for i in range(5):
        b[i] = -h[i]
    if s1 == SLIP_UP:
        b[3] -= F
    elif s1 == SLIP_DOWN:
        b[3] += F
    if s2 == SLIP_UP:
        b[4] -= F
    elif s2 == SLIP_DOWN:
        b[4] += F
    for r in range(nc):
        b[5 + r] = -adot[r]
    fm.lu_solve(K, n, piv, b)
    for i in range(5):
        qdd[i] = b[i]
    for r in range(nc):
        lam[r] = b[5 + r]
    for i in range(5):
        if not math.isfinite(qdd[i]):
            return False
    return True


@_inner
def _friction_accel_jacobian(mi, phase, p, q, qd, qdd, lam, Dqdd, Dlam):
    """q'', lambda, dq''/dy (5 x 10) and dlambda/dy (nc x 10 in Dlam, 6 x 10) of a guide-friction phase
    (rimless.sim.model.friction), exactly.

    The phase's KKT system is `_friction_kkt`'s (the constraint rows: foot b, foot a in double support, a stuck
    leg's L' = 0) with the slipping legs' constant generalised forces -+F_c on L. Those forces and the stuck rows
    do not depend on y, so differentiating M q'' + h = A^T lambda + f_c and A q'' + A' q' = 0 gives the
    frictionless right-hand side of fm.accel_jacobian on the same KKT matrix. False if singular."""
    if not _friction_accel(mi, phase, q, qd, p, qdd, lam):
        return False
    K = np.zeros((11, 11))
    piv = np.empty(11, dtype=np.int64)
    ok, n, nc, _h, _adot = _friction_kkt(mi, phase, q, qd, p, K, piv)
    if not ok:
        return False
    dM, dh_dq, dh_dqd, dJa, djd_dq, djd_dqd = fm.derivs(mi, q, qd, p)
    dlsp = _base_phase(phase) == fm.DLSP
    rhs = np.empty(n)
    for col in range(10):
        for i in range(n):
            rhs[i] = 0.0
        fm.jacobian_rhs(col, dlsp, qdd, lam, dM, dh_dq, dh_dqd, dJa, djd_dq, djd_dqd, rhs)
        fm.lu_solve(K, n, piv, rhs)
        for i in range(5):
            Dqdd[i, col] = rhs[i]
        for r in range(nc):
            Dlam[r, col] = rhs[5 + r]
    return True


@_inner
def _friction_directional(mi, phase, q, qd, p, qdd, lam, V, dqdd):
    """q'', lambda of a friction phase and dqdd[:, c] = (dq''/dy) V[:, c] (the variational equations' field)."""
    Dqdd = np.empty((5, 10))
    Dlam = np.empty((6, 10))
    if not _friction_accel_jacobian(mi, phase, p, q, qd, qdd, lam, Dqdd, Dlam):
        return False
    for i in range(5):
        for c in range(V.shape[1]):
            acc = 0.0
            for j in range(10):
                acc += Dqdd[i, j] * V[j, c]
            dqdd[i, c] = acc
    return True


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def _accel_any(mi, phase, q, qd, p, qdd, lam, ws):
    """q'' and lambda of a base phase (the generated reduced equations) or of a friction phase."""
    if phase >= FRICTION_PHASE0:
        return _friction_accel(mi, phase, q, qd, p, qdd, lam)
    return fm.accel_reduced(mi, phase, q, qd, p, qdd, lam, ws)


@_inner
def crossing(g_old, g_new, direction, strict):
    """Whether a guard fires between two step ends (the engine's rule, rimless.sim.integrate.events): it crosses 0
    in its direction, from < 0 to >= 0 (direction > 0) or from > 0 to <= 0 (direction < 0); a guard at exactly 0
    at the step's start counts as on the near side unless `strict` (the guide-friction phases: a leg that just
    stuck or just slips does not fire at once)."""
    up = (g_old < 0.0 or (g_old == 0.0 and not strict)) and g_new >= 0.0
    down = (g_old > 0.0 or (g_old == 0.0 and not strict)) and g_new <= 0.0
    return (up and direction > 0) or (down and direction < 0)


@_inner
def _needs_lambda(code):
    return fm.guard_needs_lambda(code) or code == STICK_END_1 or code == STICK_END_2


@_inner
def _guard_value(phase, code, y, lam, p):
    """Guard `code` at y with the phase's lambda (the stick/slip guards of rimless.sim.model.guards too)."""
    if code == SLIP_END_1 or code == SLIP_END_2:
        leg = 1 if code == SLIP_END_1 else 2
        rate = y[8] if leg == 1 else y[9]
        return rate if _leg_state(phase, leg) == SLIP_UP else -rate
    if code == STICK_END_1 or code == STICK_END_2:
        leg = 1 if code == STICK_END_1 else 2
        return p[FRICTION_INDEX] - abs(lam[_stuck_row(phase, leg)])
    return fm.guard_value_from(code, y, lam, p[3])


@_inner
def _rms(x, n):
    s = 0.0
    for i in range(n):
        s += x[i] * x[i]
    return math.sqrt(s / n)


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def _initial_step(mi, phase, p, t0, y0, f0, t_bound, rtol, atol, n_err, with_var, with_diss):
    """scipy.integrate._ivp.common.select_initial_step with order 7 (on the first n_err components)."""
    interval = abs(t_bound - t0)
    if interval == 0.0:
        return 0.0, 0
    N = y0.shape[0]
    a = np.empty(n_err)
    b = np.empty(n_err)
    for i in range(n_err):
        sc = atol + abs(y0[i]) * rtol
        a[i] = y0[i] / sc
        b[i] = f0[i] / sc
    d0 = _rms(a, n_err)
    d1 = _rms(b, n_err)
    if d0 < 1e-5 or d1 < 1e-5:
        h0 = 1e-6
    else:
        h0 = 0.01 * d0 / d1
    h0 = min(h0, interval)
    y1 = np.empty(N)
    for i in range(N):
        y1[i] = y0[i] + h0 * f0[i]
    f1 = np.empty(N)
    lam = np.zeros(6)
    rhs_aug(mi, phase, p, y1, with_var, with_diss, f1, lam, np.empty(fm.WORKSPACE_SIZE + 5))
    for i in range(n_err):
        sc = atol + abs(y0[i]) * rtol
        a[i] = (f1[i] - f0[i]) / sc
    d2 = _rms(a, n_err) / h0
    if not math.isfinite(d2):
        d2 = 1e300
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, interval), 1


@_inner
def _dense_eval(F, y_old, x, nout, out):
    """scipy's Dop853DenseOutput at the normalised time x in [0, 1], first nout components."""
    for i in range(nout):
        v = 0.0
        for k in range(6, -1, -1):
            v += F[k, i]
            if (6 - k) % 2 == 0:
                v *= x
            else:
                v *= 1.0 - x
        out[i] = v + y_old[i]


@_inner
def _guard_on_dense(mi, phase, p, code, t, t_old, h, F, y_old, ybuf, qdd, lam, rate):
    """Guard `code` (or, with rate=True, the swing height's rate) at time t on the dense output."""
    x = (t - t_old) / h
    _dense_eval(F, y_old, x, 10, ybuf)
    if rate:
        return fm.swing_height_rate(ybuf, p[3])
    if _needs_lambda(code):
        if phase >= FRICTION_PHASE0:
            _friction_accel(mi, phase, ybuf[0:5], ybuf[5:10], p, qdd, lam)
        else:
            fm.accel(mi, phase, ybuf[0:5], ybuf[5:10], p, qdd, lam)
    return _guard_value(phase, code, ybuf, lam, p)


@_inner
def _brent(mi, phase, p, code, rate, xa, xb, t_old, h, F, y_old):
    """scipy.optimize.brentq (xtol = rtol = 4 eps) on a guard of the dense output; returns (root, nfev)."""
    ybuf = np.empty(10)
    qdd = np.empty(5)
    lam = np.zeros(6)
    xtol = 4.0 * _EPS
    rtol = 4.0 * _EPS
    xpre = xa
    xcur = xb
    xblk = 0.0
    fblk = 0.0
    spre = 0.0
    scur = 0.0
    fpre = _guard_on_dense(mi, phase, p, code, xpre, t_old, h, F, y_old, ybuf, qdd, lam, rate)
    fcur = _guard_on_dense(mi, phase, p, code, xcur, t_old, h, F, y_old, ybuf, qdd, lam, rate)
    nf = 2
    if fpre == 0.0:
        return xpre, nf
    if fcur == 0.0:
        return xcur, nf
    for _ in range(200):
        if fpre != 0.0 and fcur != 0.0 and ((fpre < 0.0) != (fcur < 0.0)):
            xblk = xpre
            fblk = fpre
            spre = xcur - xpre
            scur = spre
        if abs(fblk) < abs(fcur):
            xpre = xcur
            xcur = xblk
            xblk = xpre
            fpre = fcur
            fcur = fblk
            fblk = fpre
        delta = (xtol + rtol * abs(xcur)) / 2.0
        sbis = (xblk - xcur) / 2.0
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur, nf
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):
                spre = scur
                scur = stry
            else:
                spre = sbis
                scur = sbis
        else:
            spre = sbis
            scur = sbis
        xpre = xcur
        fpre = fcur
        if abs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = _guard_on_dense(mi, phase, p, code, xcur, t_old, h, F, y_old, ybuf, qdd, lam, rate)
        nf += 1
    return xcur, nf


@_inner
def _build_dense(mi, phase, p, y_old, h, K, F, ytmp, lam, ws, with_var, with_diss):
    """The extra stages 13..15 of an accepted step (K rows 0..12 given) and scipy's dense-output
    coefficients F (7 x N) of that step."""
    N = y_old.shape[0]
    for s in range(_NS + 1, _NSE):
        for i in range(N):
            acc = 0.0
            for j in range(s):
                acc += _A[s, j] * K[j, i]
            ytmp[i] = y_old[i] + h * acc
        rhs_aug(mi, phase, p, ytmp, with_var, with_diss, K[s], lam, ws)
    for i in range(N):
        y_new_i = y_old[i]
        acc = 0.0
        for j in range(_NS):
            acc += _B[j] * K[j, i]
        y_new_i += h * acc
        dy = y_new_i - y_old[i]
        F[0, i] = dy
        F[1, i] = h * K[0, i] - dy
        F[2, i] = 2.0 * dy - h * (K[_NS, i] + K[0, i])
        for r in range(4):
            acc = 0.0
            for j in range(_NSE):
                acc += _D[r, j] * K[j, i]
            F[3 + r, i] = h * acc
    return _NSE - _NS - 1


# DIP_SAMPLES (dense-output samples of a normal force over a step when looking for a dip below zero) and
# DIP_MARGIN (below) are the event engine's, rimless.sim.integrate.events.
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))
DIP_XTOL = 1e-9  # relative to the step: where the minimum of a force over a step is located


# A discrete minimum of a force over three step ends is checked on the dense output unless the parabola
# through the three values stays above DIP_MARGIN times the lowest of them (the force is resolved by the
# steps, which control the error of y, so the parabola's undershoot is a safe estimate with this margin).


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def _parabola_min(t0, g0, t1, g1, t2, g2):
    """Minimum of the parabola through (t0, g0), (t1, g1), (t2, g2) with g1 below both neighbours."""
    d1 = (g1 - g0) / (t1 - t0)
    d2 = (g2 - g1) / (t2 - t1)
    a = (d2 - d1) / (t2 - t0)
    if not a > 0.0:
        return -np.inf
    ts = 0.5 * (t0 + t1) - d1 / (2.0 * a)
    return g1 + d1 * (ts - t1) + a * (ts - t0) * (ts - t1)


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def _min_on_dense(mi, phase, p, code, a, x, gx, b, t_a, h, F, y_a):
    """Brent's minimisation (golden section + parabolic interpolation) of a guard on the dense output in the
    bracket a < x < b with g(x) below both ends; returns (x_min, g_min, nfev). Stops early at g <= 0."""
    ybuf = np.empty(10)
    qdd = np.empty(5)
    lam = np.zeros(6)
    w = x
    v = x
    gw = gx
    gv = gx
    d = 0.0
    e = 0.0
    nf = 0
    tol = DIP_XTOL * h
    for _ in range(100):
        if gx <= 0.0:
            break
        m = 0.5 * (a + b)
        tol1 = tol + 4.0 * _EPS * abs(x)
        tol2 = 2.0 * tol1
        if abs(x - m) <= tol2 - 0.5 * (b - a):
            break
        golden = True
        if abs(e) > tol1:
            r = (x - w) * (gx - gv)
            q = (x - v) * (gx - gw)
            pp = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                pp = -pp
            q = abs(q)
            if abs(pp) < abs(0.5 * q * e) and pp > q * (a - x) and pp < q * (b - x):
                e = d
                d = pp / q
                u = x + d
                if u - a < tol2 or b - u < tol2:
                    d = tol1 if x < m else -tol1
                golden = False
        if golden:
            e = (b - x) if x < m else (a - x)
            d = _GOLDEN * e
        u = x + (d if abs(d) >= tol1 else (tol1 if d > 0 else -tol1))
        gu = _guard_on_dense(mi, phase, p, code, u, t_a, h, F, y_a, ybuf, qdd, lam, False)
        nf += 1
        if gu <= gx:
            if u < x:
                b = x
            else:
                a = x
            v = w
            gv = gw
            w = x
            gw = gx
            x = u
            gx = gu
        else:
            if u < x:
                a = u
            else:
                b = u
            if gu <= gw or w == x:
                v = w
                gv = gw
                w = u
                gw = gu
            elif gu <= gv or v == x or v == w:
                v = u
                gv = gu
    return x, gx, nf


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def _parabola_min_on(x0, g0, x1, g1, x2, g2):
    """Minimum over [x0, x2] of the parabola through (x0, g0), (x1, g1), (x2, g2)."""
    lo = min(g0, g1, g2)
    d1 = (g1 - g0) / (x1 - x0)
    d2 = (g2 - g1) / (x2 - x1)
    a = (d2 - d1) / (x2 - x0)
    if not a > 0.0:
        return lo
    xs = 0.5 * (x0 + x1) - d1 / (2.0 * a)
    if xs <= x0 or xs >= x2:
        return lo
    return min(lo, g1 + d1 * (xs - x1) + a * (xs - x0) * (xs - x1))


@_inner
def _first_dip(mi, phase, p, code, t_a, h, F, y_a, g_a, g_b):
    """(t, nfev): the first downward zero of a normal-force guard on one step's dense output
    [t_a, t_a + h] where it is positive at both ends (values g_a, g_b), or (inf, nfev) if it stays positive.

    The guard is sampled at DIP_SAMPLES interior points. Without a non-positive sample, the parabola through
    the lowest sample (ends included) and its neighbours decides as the step-level check does: if it stays
    above DIP_MARGIN times that sample over their span, the force is resolved and has no dip; otherwise the
    lowest interior sample is refined by Brent's minimisation. A crossing is located by Brent's root finder."""
    ybuf = np.empty(10)
    qdd = np.empty(5)
    lam = np.zeros(6)
    n = DIP_SAMPLES + 1
    gs = np.empty(n + 1)
    gs[0] = g_a
    gs[n] = g_b
    first_neg = -1
    k_low = 1
    g_low = np.inf
    nf = 0
    for k in range(1, n):
        gk = _guard_on_dense(mi, phase, p, code, t_a + h * k / n, t_a, h, F, y_a, ybuf, qdd, lam, False)
        nf += 1
        gs[k] = gk
        if gk <= 0.0:
            first_neg = k
            break
        if gk < g_low:
            g_low = gk
            k_low = k
    if first_neg > 0:
        t_low = t_a + h * first_neg / n
    else:
        k_min = 0
        for k in range(1, n + 1):
            if gs[k] < gs[k_min]:
                k_min = k
        k0 = min(max(k_min - 1, 0), n - 2)
        if _parabola_min_on(k0, gs[k0], k0 + 1, gs[k0 + 1], k0 + 2, gs[k0 + 2]) > DIP_MARGIN * gs[k_min]:
            return np.inf, nf
        x, gx, nfm = _min_on_dense(
            mi,
            phase,
            p,
            code,
            t_a + h * (k_low - 1) / n,
            t_a + h * k_low / n,
            g_low,
            t_a + h * (k_low + 1) / n,
            t_a,
            h,
            F,
            y_a,
        )
        nf += nfm
        if gx > 0.0:
            return np.inf, nf
        t_low = x
    root, nfb = _brent(mi, phase, p, code, False, t_a, t_low, t_a, h, F, y_a)
    return root, nf + nfb


@kernel(inline="always", python=False)  # one call site (two for _guards_at): no library of its own
def _guards_at(phase, p, codes, y, lam, out):
    for e in range(codes.shape[0]):
        out[e] = _guard_value(phase, codes[e], y, lam, p)


@_inner
def _rk_stages(mi, phase, p, y, f0, h, K, ytmp, y_new, lam, ws, with_var, with_diss):
    """One DOP853 step of size h from y with f0 = f(y): stages K[0..11] (K[0] = f0), y_new = y + h sum B K;
    ytmp is left holding the last stage's state. False if a right-hand side failed (singular or not finite)."""
    N = y.shape[0]
    for i in range(N):
        K[0, i] = f0[i]
    ok = True
    for s in range(1, _NS):
        for i in range(N):
            acc = 0.0
            for j in range(s):
                acc += _A[s, j] * K[j, i]
            ytmp[i] = y[i] + h * acc
        ok = rhs_aug(mi, phase, p, ytmp, with_var, with_diss, K[s], lam, ws) and ok
    for i in range(N):
        acc = 0.0
        for j in range(_NS):
            acc += _B[j] * K[j, i]
        y_new[i] = y[i] + h * acc
    return ok


@_inner
def _room(rec_t, rec_y, nrec):
    """The record buffers, doubled (contents kept) if the next record nrec would not fit."""
    cap = rec_t.shape[0]
    if nrec < cap:
        return rec_t, rec_y
    rt = np.empty(2 * cap)
    ry = np.empty((2 * cap, 10))
    for i in range(nrec):  # element loops: numba's slice assignment takes seconds to compile
        rt[i] = rec_t[i]
        for j in range(10):
            ry[i, j] = rec_y[i, j]
    return rt, ry


@_inner
def record_point(rec_t, rec_y, nrec, t, y):
    """Record (t, y[:10]) at index nrec (room already made, `_room`); returns nrec + 1."""
    rec_t[nrec] = t
    for i in range(10):
        rec_y[nrec, i] = y[i]
    return nrec + 1


@_inner
def record_grid(rec_t, rec_y, nrec, next_grid, t0, record_dt, t_stop, F, y, t, h, ybuf):
    """Record the grid times t0 + k record_dt (k from next_grid) before t_stop on the step's dense output (F, y
    at t, size h), then make room for one more record; returns (rec_t, rec_y, nrec, next_grid)."""
    while True:
        tg = t0 + next_grid * record_dt
        if tg >= t_stop:
            break
        rec_t, rec_y = _room(rec_t, rec_y, nrec)
        _dense_eval(F, y, (tg - t) / h, 10, ybuf)
        nrec = record_point(rec_t, rec_y, nrec, tg, ybuf)
        next_grid += 1
    rec_t, rec_y = _room(rec_t, rec_y, nrec)
    return rec_t, rec_y, nrec, next_grid


@_jit
def run_phase(
    mi, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
):
    """Integrate one phase from (t0, y0) until a guard in `codes` fires or t0 + t_max is reached.

    Returns (status, t_end, y_end, fired_index (-1: none), nfev, nsteps, nstiff, rec_t, rec_y).
    With record_dt > 0 the states (first 10 components) at every accepted step and on the grid
    t0 + k record_dt are returned in rec_t (n,) and rec_y (n, 10); otherwise they are empty.
    """
    N = y0.shape[0]
    ng = codes.shape[0]
    L0 = p[3]
    strict = phase >= FRICTION_PHASE0  # friction phases: a guard at exactly 0 at a step's start does not fire
    t = t0
    y = y0.copy()
    t_bound = t0 + t_max
    K = np.empty((_NSE, N))
    f = np.empty(N)
    lam = np.zeros(6)
    lam_new = np.zeros(6)
    nfev = 1
    nsteps = 0
    nstiff = 0
    recording = record_dt > 0.0
    cap = 256 if recording else 1
    rec_t = np.empty(cap)
    rec_y = np.empty((cap, 10))
    nrec = 0
    if recording:
        rec_t[0] = t0
        for i in range(10):
            rec_y[0, i] = y0[i]
        nrec = 1
    next_grid = 1
    ws = np.empty(fm.WORKSPACE_SIZE + 5)
    finite0 = rhs_aug(mi, phase, p, y, with_var, with_diss, f, lam, ws)
    for i in range(N):
        if not (math.isfinite(y[i]) and math.isfinite(f[i])):
            finite0 = False
    if not finite0:
        return STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
    g = np.empty(ng)
    g_new = np.empty(ng)
    _guards_at(phase, p, codes, y, lam, g)
    h_abs, nf0 = _initial_step(mi, phase, p, t0, y, f, t_bound, rtol, atol, n_err, with_var, with_diss)
    nfev += nf0
    for e in range(ng):
        if not math.isfinite(g[e]):
            return STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
    if not (h_abs > 0.0 and math.isfinite(h_abs)):
        return STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
    # the previous accepted step (stages, start, size, guards) for the normal-force dip check
    Kp = np.empty((_NSE, N))
    Fp = np.empty((7, N))
    yp_old = np.empty(N)
    tp_old = t0
    hp = 0.0
    have_prev = False
    g_pp = np.empty(ng)
    nreject = 0
    y_new = np.empty(N)
    ytmp = np.empty(N)
    y_last_stage = np.empty(N)
    F = np.empty((7, N))
    np.empty(n_err)
    ybuf = np.empty(N)
    while True:
        if nsteps >= max_steps:
            return STATUS_TOO_MANY_STEPS, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
        rejected = False
        h = 0.0
        t_new = t
        while True:
            if not (h_abs >= min_step) or nreject > MAX_REJECTIONS:
                return STATUS_STEP_TOO_SMALL, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
            h = h_abs
            t_new = t + h
            if t_new > t_bound:
                t_new = t_bound
            h = t_new - t
            h_abs = abs(h)
            ok = _rk_stages(mi, phase, p, y, f, h, K, ytmp, y_new, lam_new, ws, with_var, with_diss)
            for i in range(N):
                y_last_stage[i] = ytmp[i]
            fnew = K[_NS]
            ok = rhs_aug(mi, phase, p, y_new, with_var, with_diss, fnew, lam_new, ws) and ok
            nfev += _NS
            err5 = 0.0
            err3 = 0.0
            finite = ok
            for i in range(n_err):
                sc = atol + max(abs(y[i]), abs(y_new[i])) * rtol
                e5 = 0.0
                e3 = 0.0
                for j in range(_NS + 1):
                    e5 += K[j, i] * _E5[j]
                    e3 += K[j, i] * _E3[j]
                e5 /= sc
                e3 /= sc
                err5 += e5 * e5
                err3 += e3 * e3
            if not (math.isfinite(err5) and math.isfinite(err3)):
                finite = False
            if finite:
                for i in range(N):
                    if not math.isfinite(y_new[i]):
                        finite = False
                        break
            if not finite:
                h_abs *= _MIN_FACTOR
                rejected = True
                nreject += 1
                continue
            if err5 == 0.0 and err3 == 0.0:
                error_norm = 0.0
            else:
                denom = err5 + 0.01 * err3
                error_norm = h_abs * err5 / math.sqrt(denom * n_err)
            if error_norm < 1.0:
                if error_norm == 0.0:
                    factor = _MAX_FACTOR
                else:
                    factor = min(_MAX_FACTOR, _SAFETY * error_norm**_ERR_EXP)
                if rejected:
                    factor = min(1.0, factor)
                h_abs *= factor
                break
            h_abs *= max(_MIN_FACTOR, _SAFETY * error_norm**_ERR_EXP)
            rejected = True
            nreject += 1
        nsteps += 1
        # stiffness indicator h |lambda| from the last stage (c = 1) and f(y_new)
        stnum = 0.0
        stden = 0.0
        for i in range(n_err):
            d1 = K[_NS, i] - K[_NS - 1, i]
            d2 = y_new[i] - y_last_stage[i]
            stnum += d1 * d1
            stden += d2 * d2
        if stden > 0.0 and h * math.sqrt(stnum / stden) > 6.1:
            nstiff += 1
        _guards_at(phase, p, codes, y_new, lam_new, g_new)
        for e in range(ng):
            if not math.isfinite(g_new[e]):
                return STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        # which guards crossed in their direction (scipy's find_active_events), plus the graze check
        t_hi_graze = -1.0
        any_active = False
        for e in range(ng):
            if crossing(g[e], g_new[e], directions[e], strict):
                any_active = True
            elif codes[e] == fm.TOUCHDOWN and g[e] > 0.0 and g_new[e] > 0.0:
                if fm.swing_height_rate(y, L0) < 0.0 and fm.swing_height_rate(y_new, L0) > 0.0:
                    t_hi_graze = 0.0  # decide after the dense output is built
        # normal-force guards positive at both step ends may still dip below zero in between: check the
        # steps around every discrete minimum over the step ends (and the first and the last step)
        dip_prev = False
        dip_cur = False
        for e in range(ng):
            if not fm.guard_needs_lambda(codes[e]) or not (g[e] > 0.0 and g_new[e] > 0.0):
                continue
            if have_prev and g_pp[e] > g[e] and g[e] < g_new[e] and g_pp[e] > 0.0:
                if _parabola_min(tp_old, g_pp[e], t, g[e], t_new, g_new[e]) <= DIP_MARGIN * g[e]:
                    dip_prev = True
                    dip_cur = True
            elif not have_prev and g[e] < g_new[e]:
                dip_cur = True
            elif g[e] > g_new[e] and (any_active or t_hi_graze == 0.0 or t_new == t_bound):
                dip_cur = True
        need_dense = any_active or recording or t_hi_graze == 0.0 or dip_cur
        if need_dense:
            nfev += _build_dense(mi, phase, p, y, h, K, F, ytmp, lam, ws, with_var, with_diss)
        best_t = np.inf
        best_e = -1
        if t_hi_graze == 0.0:
            for e in range(ng):
                if codes[e] == fm.TOUCHDOWN:
                    tmin, nf = _brent(mi, phase, p, fm.TOUCHDOWN, True, t, t_new, t, h, F, y)
                    gmin = _guard_on_dense(mi, phase, p, fm.TOUCHDOWN, tmin, t, h, F, y, ybuf, np.empty(5), lam, False)
                    if gmin <= 0.0:
                        root, nf = _brent(mi, phase, p, fm.TOUCHDOWN, False, t, tmin, t, h, F, y)
                        if root < best_t:
                            best_t = root
                            best_e = e
        if any_active:
            for e in range(ng):
                if crossing(g[e], g_new[e], directions[e], strict):
                    root, nf = _brent(mi, phase, p, codes[e], False, t, t_new, t, h, F, y)
                    nfev += nf if _needs_lambda(codes[e]) else 0
                    if root < best_t:
                        best_t = root
                        best_e = e
        best_prev = False
        if dip_cur or dip_prev:
            if dip_prev:
                nfev += _build_dense(mi, phase, p, yp_old, hp, Kp, Fp, ytmp, lam, ws, with_var, with_diss)
            for e in range(ng):
                if not fm.guard_needs_lambda(codes[e]) or not (g[e] > 0.0 and g_new[e] > 0.0):
                    continue
                if dip_prev and g_pp[e] > 0.0:
                    root, nf = _first_dip(mi, phase, p, codes[e], tp_old, hp, Fp, yp_old, g_pp[e], g[e])
                    nfev += nf
                    if root < best_t:
                        best_t = root
                        best_e = e
                        best_prev = True
                root, nf = _first_dip(mi, phase, p, codes[e], t, h, F, y, g[e], g_new[e])
                nfev += nf
                if root < best_t:
                    best_t = root
                    best_e = e
                    best_prev = False
        t_stop = best_t if best_e >= 0 else t_new
        if recording:
            rec_t, rec_y, nrec, next_grid = record_grid(
                rec_t, rec_y, nrec, next_grid, t0, record_dt, t_stop, F, y, t, h, ybuf
            )
        if best_e >= 0:
            # the state at the event: one DOP853 step from the start of the step holding it to the event time
            # located on the dense output (the interpolant is an order less accurate than the step)
            y_end = np.empty(N)
            if best_prev:
                ok = _rk_stages(
                    mi, phase, p, yp_old, Kp[0], best_t - tp_old, K, ytmp, y_end, lam_new, ws, with_var, with_diss
                )
                while nrec > 0 and rec_t[nrec - 1] >= best_t:
                    nrec -= 1
            else:
                ok = _rk_stages(mi, phase, p, y, f, best_t - t, K, ytmp, y_end, lam_new, ws, with_var, with_diss)
            nfev += _NS - 1
            for i in range(N):
                if not math.isfinite(y_end[i]):
                    ok = False
            if not ok:  # keep the dense output's state
                if best_prev:
                    _dense_eval(Fp, yp_old, (best_t - tp_old) / hp, N, y_end)
                else:
                    _dense_eval(F, y, (best_t - t) / h, N, y_end)
            if recording:
                nrec = record_point(rec_t, rec_y, nrec, best_t, y_end)
            return STATUS_OK, best_t, y_end, best_e, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        if recording:
            nrec = record_point(rec_t, rec_y, nrec, t_new, y_new)
        for i in range(N):
            yp_old[i] = y[i]
            for j in range(_NS + 1):
                Kp[j, i] = K[j, i]
        for e in range(ng):
            g_pp[e] = g[e]
        tp_old = t
        hp = h
        have_prev = True
        t = t_new
        for i in range(N):
            y[i] = y_new[i]
            f[i] = K[_NS, i]
        for e in range(ng):
            g[e] = g_new[e]
        if t == t_bound:
            return STATUS_OK, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]


# The event engine's pieces the Rosenbrock phase (rimless.sim.fast.stiff) shares: it writes its steps' dense
# output in DOP853's form, so these read it unchanged.
needs_lambda = _needs_lambda
friction_accel = _friction_accel
friction_kkt = _friction_kkt
friction_accel_jacobian = _friction_accel_jacobian
base_phase = _base_phase
leg_state = _leg_state
stuck_row = _stuck_row
guard_value = _guard_value
guards_at = _guards_at
dense_eval = _dense_eval
guard_on_dense = _guard_on_dense
brent_on_dense = _brent
parabola_min = _parabola_min
first_dip = _first_dip


# Per-mass-model entry points (the index a compile-time constant: one mass model's generated code compiled).
@_jit
def run_phase_0(
    phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
):
    return run_phase(
        0, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
    )


@_jit
def run_phase_1(
    phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
):
    return run_phase(
        1, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
    )


@_jit
def run_phase_2(
    phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
):
    return run_phase(
        2, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_var, with_diss, record_dt, max_steps
    )


RUN_PHASE = (run_phase_0, run_phase_1, run_phase_2)


def phase_call_args(
    phase: int,
    p: np.ndarray,
    y0: np.ndarray,
    t0: float,
    guards: Sequence[int],
    directions: Sequence[int],
    t_max: float,
    rtol: float,
    atol: float,
    track_dissipation: bool,
    record_dt: float | None,
    max_steps: int,
) -> tuple[Any, ...]:
    """The arguments of `RUN_PHASE[mi]` called from Python for one phase without variational equations, each of
    the one type it is compiled for (so that every such call shares one compiled version): p the parameter
    vector, y0 the state (10,), SI; guards and directions the guard codes and their directions (read-only int64
    copies); record_dt s (None or 0: no record); with track_dissipation the dissipated energy is integrated
    as an 11th component (J)."""
    codes = np.array(guards, dtype=np.int64)
    dirs = np.array(directions, dtype=np.int64)
    codes.flags.writeable = False  # read-only, as the step kernel's own guard tables are
    dirs.flags.writeable = False
    y = np.asarray(y0, dtype=np.float64)
    if track_dissipation:
        y = np.concatenate((y, [0.0]))
    return (
        int(phase),
        np.asarray(p, dtype=np.float64),
        y,
        float(t0),
        codes,
        dirs,
        float(t_max),
        float(rtol),
        float(atol),
        11 if track_dissipation else 10,
        False,
        bool(track_dissipation),
        float(record_dt) if record_dt else -1.0,
        int(max_steps),
    )
