"""One concept: the compiled linearly implicit (Rosenbrock) integrator of one phase, for stiff legs.

Why: a leg of mass m, stiffness k and damping c has the eigenvalues of m s^2 + c s + k = 0. At Table 1 they are
about -110 +- 250j 1/s; with near-massless legs (0.1 g, what a user describing a rigid-legged wheel writes) the
free leg is overdamped with a fast root near -c/m = -8e4 1/s. The explicit DOP853 (rimless.sim.fast.rk) is then
held by its stability limit (h |lambda| < ~6: steps of ~7e-5 s, some 60 000 right-hand sides per step) while the
motion itself is as smooth as at Table 1. `leg_stiff` says when a phase is stiff in that sense; the step kernel
and the FastIntegrator then integrate single support with `run_phase_stiff` instead.

Method: the 4th-order Kaps-Rentrop Rosenbrock method with Shampine's A-stable parameters (gamma = 1/2, the
embedded 3rd-order solution for the error; Hairer & Wanner, Solving ODEs II, section IV.7; Numerical Recipes'
`stiff`), on the exact Jacobian of the phase's field (rimless.sim.fast.model.accel_jacobian), one LU per step
attempt. Error norm, tolerances and step-size control as scipy's solvers (RMS of err / (atol + rtol max|y|)),
exponent -1/4.

Events follow the engine's rules (rimless.sim.integrate.events, as rimless.sim.fast.rk does): a guard fires
when it crosses 0 in its direction between two accepted steps; the touchdown graze and the normal-force dips
between step ends are searched on the step's dense output (the cubic Hermite interpolant, written in DOP853's
dense-output form so that rk's Brent and dip search read it unchanged). The crossing is then refined on the
integrator itself: Brent's method (4 eps in t) on the guard of one Rosenbrock step from the step's start to t,
so the event time and state carry the step's accuracy, not the interpolant's.

Guide friction's stick/slip phases (codes >= FRICTION_PHASE0, rimless.sim.model.friction) are integrated the
same way: their field is rk's, their exact Jacobian `rk.friction_accel_jacobian` (the slipping legs' forces -+F_c
and the stuck legs' rows L' = 0 do not depend on y), and their guards cross strictly as on DOP853 (a guard at
exactly 0 at a step's start, a leg that just stuck or just slips, does not fire at once).

With the variational equations (the map's exact Jacobian; y of 30: the state and the tangents V, 10 x 2) the
integrated vector's Jacobian is block lower triangular, [[J, 0], [B, J]] with B g = d/dy (J(y) V) g; the stage
solves take B g by central differences of the variational field (`_stage_solve`). The step of y is the same as
without V; that of V is then the derivative of the Rosenbrock step of y (up to those differences), as DOP853's V
is of its own step. The step size is controlled on y only.

Units: SI; y = [q, q'] (10,) plus the dissipated energy (J) as an 11th component when asked, or the tangents.
"""

from __future__ import annotations

import math

import numpy as np

from rimless.sim.fast import model as fm
from rimless.sim.fast import rk
from rimless.sim.fast.compiling import kernel
from rimless.sim.integrate.events import DIP_MARGIN
from rimless.sim.model.friction import FRICTION_PHASE0

_jit = kernel
_inner = kernel(python=False)

# the switch (rimless.sim.fast.model: single support by this method, double support's field by the pivoted KKT)
STIFF_LEG_RATE = fm.STIFF_LEG_RATE

# Kaps-Rentrop with Shampine's parameters (gamma = 1/2): stages g_i solve (I / (gamma h) - J) g_i = ...
_GAM = 0.5
_A21 = 2.0
_A31 = 48.0 / 25.0
_A32 = 6.0 / 25.0
_C21 = -8.0
_C31 = 372.0 / 25.0
_C32 = 12.0 / 5.0
_C41 = -112.0 / 125.0
_C42 = -54.0 / 125.0
_C43 = -2.0 / 5.0
_B1 = 19.0 / 9.0
_B2 = 1.0 / 2.0
_B3 = 25.0 / 108.0
_B4 = 125.0 / 108.0
_E1 = 17.0 / 54.0
_E2 = 7.0 / 36.0
_E3 = 0.0
_E4 = 125.0 / 108.0
_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 5.0
_ERR_EXP = -0.25
_EPS = np.finfo(float).eps
MAX_REJECTIONS = 10_000
_FD_STEP = 6e-6  # central differences of the variational field (B g): about eps^(1/3) relative to the state


leg_rate = fm.leg_rate  # max(c / m, sqrt(k / m)), 1/s
leg_stiff = fm.leg_stiff  # leg_rate(p) > STIFF_LEG_RATE


@_inner
def _jacobian(mi, phase, p, y, with_diss, Jm):
    """Jm = df/dy (N x N) of the phase's field (a guide-friction phase's too); False if the KKT matrix is
    singular. With the variational equations (y of 30) Jm is the state's block (10 x 10)."""
    N = Jm.shape[0]
    qdd = np.empty(5)
    lam = np.zeros(6)
    Dqdd = np.empty((5, 10))
    if phase >= FRICTION_PHASE0:
        ok = rk.friction_accel_jacobian(mi, phase, p, y[0:5], y[5:10], qdd, lam, Dqdd, np.empty((6, 10)))
    else:
        Dlam = np.empty((4, 10))
        ok = fm.accel_jacobian(mi, phase, y[0:5], y[5:10], p, qdd, lam, Dqdd, Dlam)
    for i in range(N):
        for j in range(N):
            Jm[i, j] = 0.0
    for i in range(5):
        Jm[i, 5 + i] = 1.0
        for j in range(10):
            Jm[5 + i, j] = Dqdd[i, j]
    if with_diss:  # d/dy of c (L1'^2 + L2'^2) (L1' locked in the clutched phase)
        if rk.base_phase(phase) != fm.SLSP_CLUTCHED:
            Jm[10, 8] = 2.0 * p[5] * y[8]
        Jm[10, 9] = 2.0 * p[5] * y[9]
    return ok


@_inner
def _lu(A, piv):
    """In-place LU with partial pivoting; False if singular."""
    n = A.shape[0]
    for k in range(n):
        r = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                r = i
        piv[k] = r
        if big == 0.0 or not math.isfinite(big):
            return False
        if r != k:
            for j in range(n):
                tmp = A[k, j]
                A[k, j] = A[r, j]
                A[r, j] = tmp
        for i in range(k + 1, n):
            A[i, k] /= A[k, k]
            f = A[i, k]
            if f != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= f * A[k, j]
    return True


@_inner
def _solve(A, piv, b):
    """b <- A^-1 b with the LU of `_lu`."""
    n = A.shape[0]
    for k in range(n):
        r = piv[k]
        if r != k:
            tmp = b[k]
            b[k] = b[r]
            b[r] = tmp
    for i in range(n):
        acc = b[i]
        for j in range(i):
            acc -= A[i, j] * b[j]
        b[i] = acc
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, n):
            acc -= A[i, j] * b[j]
        b[i] = acc / A[i, i]


@_inner
def n_var(N):
    """The tangent columns V carried in an integrated vector of N components: 2 with the variational equations
    (y (10), V (10 x 2); without the dissipated energy), else 0."""
    return 2 if N == rk.VAR_OFFSET + rk.VAR_SIZE else 0


@_inner
def _stage_solve(mi, phase, p, A, piv, y, g, nv, ytmp, fplus, fminus, lam, ws):
    """g <- (I / (gamma h) - J_aug)^-1 g for the integrated vector's Jacobian J_aug at y. Without tangents
    (nv = 0) J_aug = Jm (A its LU). With them J_aug = [[J, 0], [B, J]] (block lower triangular; B g =
    d/dy (J(y) V) g, the field's second derivative in the directions V and g): the state's block is solved
    first, then each tangent's with B g_y added, B g_y by central differences of the variational field (step
    _FD_STEP relative to the state). Then the Rosenbrock step of y and V is the derivative of the Rosenbrock
    step of y (the two second derivatives are the same symmetric form), as DOP853's is of its own."""
    _solve(A, piv, g)
    if nv == 0:
        return True
    N = y.shape[0]
    gn = 0.0
    yn = 0.0
    for i in range(10):
        gn = max(gn, abs(g[i]))
        yn = max(yn, abs(y[i]))
    ok = True
    if gn > 0.0:
        e = _FD_STEP * (1.0 + yn) / gn
        for i in range(N):
            ytmp[i] = y[i]
        for i in range(10):
            ytmp[i] = y[i] + e * g[i]
        ok = rk.rhs_aug(mi, phase, p, ytmp, True, False, fplus, lam, ws)
        for i in range(10):
            ytmp[i] = y[i] - e * g[i]
        ok = rk.rhs_aug(mi, phase, p, ytmp, True, False, fminus, lam, ws) and ok
        for i in range(10, N):
            g[i] += (fplus[i] - fminus[i]) / (2.0 * e)
    for c in range(nv):
        _solve(A, piv, g[10 + 10 * c : 20 + 10 * c])
    return ok


@_inner
def ros_step(mi, phase, p, y, f0, Jm, h, with_diss, y_new, err, G, lam, ws):
    """One Rosenbrock step of size h from y (f0 = f(y), Jm = df/dy at y of the state's block): y_new, err (the
    embedded estimate). G (4 x N) receives the stages. False if a right-hand side or the linear system failed.
    2 field evaluations (and 8 more of the variational field when y carries tangents, `_stage_solve`)."""
    N = y.shape[0]
    Ny = Jm.shape[0]
    nv = n_var(N)
    wv = nv > 0
    A = np.empty((Ny, Ny))
    piv = np.empty(Ny, dtype=np.int64)
    d = 1.0 / (_GAM * h)
    for i in range(Ny):
        for j in range(Ny):
            A[i, j] = -Jm[i, j]
        A[i, i] += d
    if not _lu(A, piv):
        return False
    ytmp = np.empty(N)
    ftmp = np.empty(N)
    yb = np.empty(N if wv else 0)
    fp = np.empty(N if wv else 0)
    fq = np.empty(N if wv else 0)
    for i in range(N):
        G[0, i] = f0[i]
    ok = _stage_solve(mi, phase, p, A, piv, y, G[0], nv, yb, fp, fq, lam, ws)
    for i in range(N):
        ytmp[i] = y[i] + _A21 * G[0, i]
    ok = rk.rhs_aug(mi, phase, p, ytmp, wv, with_diss, ftmp, lam, ws) and ok
    for i in range(N):
        G[1, i] = ftmp[i] + _C21 * G[0, i] / h
    ok = _stage_solve(mi, phase, p, A, piv, y, G[1], nv, yb, fp, fq, lam, ws) and ok
    for i in range(N):
        ytmp[i] = y[i] + _A31 * G[0, i] + _A32 * G[1, i]
    ok = rk.rhs_aug(mi, phase, p, ytmp, wv, with_diss, ftmp, lam, ws) and ok
    for i in range(N):
        G[2, i] = ftmp[i] + (_C31 * G[0, i] + _C32 * G[1, i]) / h
    ok = _stage_solve(mi, phase, p, A, piv, y, G[2], nv, yb, fp, fq, lam, ws) and ok
    for i in range(N):
        G[3, i] = ftmp[i] + (_C41 * G[0, i] + _C42 * G[1, i] + _C43 * G[2, i]) / h
    ok = _stage_solve(mi, phase, p, A, piv, y, G[3], nv, yb, fp, fq, lam, ws) and ok
    for i in range(N):
        y_new[i] = y[i] + _B1 * G[0, i] + _B2 * G[1, i] + _B3 * G[2, i] + _B4 * G[3, i]
        err[i] = _E1 * G[0, i] + _E2 * G[1, i] + _E3 * G[2, i] + _E4 * G[3, i]
        if not math.isfinite(y_new[i]):
            ok = False
    return ok


@_inner
def _hermite(y, f0, y_new, f1, h, F):
    """The cubic Hermite interpolant of a step in DOP853's dense form (rk.dense_eval reads it)."""
    N = y.shape[0]
    for i in range(N):
        dy = y_new[i] - y[i]
        F[0, i] = dy
        F[1, i] = h * f0[i] - dy
        F[2, i] = 2.0 * dy - h * (f0[i] + f1[i])
        for k in range(3, 7):
            F[k, i] = 0.0


@_inner
def _guard_by_step(mi, phase, p, code, s, y, f0, Jm, with_diss, y_out, lam, ws):
    """Guard `code` at the state one Rosenbrock step of size s from y (y_out receives that state)."""
    N = y.shape[0]
    if s == 0.0:
        for i in range(N):
            y_out[i] = y[i]
    else:
        G = np.empty((4, N))
        err = np.empty(N)
        ros_step(mi, phase, p, y, f0, Jm, s, with_diss, y_out, err, G, lam, ws)
    qdd = np.empty(5)
    if rk.needs_lambda(code):
        if phase >= FRICTION_PHASE0:
            rk.friction_accel(mi, phase, y_out[0:5], y_out[5:10], p, qdd, lam)
        else:
            fm.accel(mi, phase, y_out[0:5], y_out[5:10], p, qdd, lam)
    return rk.guard_value(phase, code, y_out, lam, p)


@_inner
def _refine(mi, phase, p, code, t, t_root, t_hi, y, f0, Jm, with_diss, y_end, lam, ws):
    """The guard's crossing on the integrator itself near the dense output's root t_root: Brent's method (4 eps
    in t) on g(t) = guard of one step from (t, y) to t, bracketed by the root and the nearer end of [t, t_hi]
    where the signs differ; (t_event, nfev), y_end the state there. Without a bracket: the dense root kept."""
    N = y.shape[0]
    ybuf = np.empty(N)
    g_root = _guard_by_step(mi, phase, p, code, t_root - t, y, f0, Jm, with_diss, y_end, lam, ws)
    nf = 2
    if g_root == 0.0:
        return t_root, nf
    g_lo = _guard_by_step(mi, phase, p, code, 0.0, y, f0, Jm, with_diss, ybuf, lam, ws)
    if (g_lo < 0.0) != (g_root < 0.0) and g_lo != 0.0:
        a, fa, b, fb = t, g_lo, t_root, g_root
    else:
        g_hi = _guard_by_step(mi, phase, p, code, t_hi - t, y, f0, Jm, with_diss, ybuf, lam, ws)
        nf += 2
        if not ((g_hi < 0.0) != (g_root < 0.0)):
            return t_root, nf
        a, fa, b, fb = t_root, g_root, t_hi, g_hi
    # Brent's method (scipy.optimize.brentq's algorithm) on [a, b]
    xpre, fpre, xcur, fcur = a, fa, b, fb
    xblk, fblk, spre, scur = 0.0, 0.0, 0.0, 0.0
    tol = 4.0 * _EPS
    for _ in range(100):
        if fpre != 0.0 and fcur != 0.0 and ((fpre < 0.0) != (fcur < 0.0)):
            xblk, fblk = xpre, fpre
            spre = xcur - xpre
            scur = spre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (tol + tol * abs(xcur)) / 2.0
        sbis = (xblk - xcur) / 2.0
        if fcur == 0.0 or abs(sbis) < delta:
            break
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):
                spre, scur = scur, stry
            else:
                spre, scur = sbis, sbis
        else:
            spre, scur = sbis, sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = _guard_by_step(mi, phase, p, code, xcur - t, y, f0, Jm, with_diss, ybuf, lam, ws)
        nf += 2
    _guard_by_step(mi, phase, p, code, xcur - t, y, f0, Jm, with_diss, y_end, lam, ws)
    return xcur, nf + 2


@_jit
def run_phase_stiff(mi, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps):
    """Integrate one phase from (t0, y0) until a guard in `codes` fires or t0 + t_max is reached, with the
    Rosenbrock method. Arguments and returns as rimless.sim.fast.rk.run_phase (the variational equations carried
    when y0 has their 30 components): (status, t_end, y_end, fired_index (-1: none), nfev, nsteps, nstiff, rec_t,
    rec_y); nfev counts field evaluations, one per Jacobian and the stage solves' 8 differences included; nstiff the steps with h |lambda_leg| > 6.1 (`leg_rate`),
    those DOP853 could not have taken (its stiffness indicator's threshold)."""
    N = y0.shape[0]
    nv = n_var(N)
    wv = nv > 0
    ng = codes.shape[0]
    L0 = p[3]
    t = t0
    y = y0.copy()
    t_bound = t0 + t_max
    ws = np.empty(fm.WORKSPACE_SIZE + 5)
    f = np.empty(N)
    f_new = np.empty(N)
    lam = np.zeros(6)
    lam_new = np.zeros(6)
    Jm = np.empty((N - 10 * nv, N - 10 * nv))
    G = np.empty((4, N))
    err = np.empty(N)
    y_new = np.empty(N)
    F = np.zeros((7, N))
    Fp = np.zeros((7, N))
    yp_old = np.empty(N)
    g = np.empty(ng)
    g_new = np.empty(ng)
    g_pp = np.empty(ng)
    recording = record_dt > 0.0
    rec_t = np.empty(256 if recording else 1)
    rec_y = np.empty((256 if recording else 1, 10))
    nrec = 0
    if recording:
        rec_t[0] = t0
        for i in range(10):
            rec_y[0, i] = y0[i]
        nrec = 1
    next_grid = 1
    nfev = 1
    nsteps = 0
    nstiff = 0
    rate = leg_rate(p)
    strict = phase >= FRICTION_PHASE0  # friction phases: a guard at exactly 0 at a step's start does not fire
    ok = rk.rhs_aug(mi, phase, p, y, wv, with_diss, f, lam, ws)
    for i in range(N):
        if not (math.isfinite(y[i]) and math.isfinite(f[i])):
            ok = False
    if not ok:
        return rk.STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
    rk.guards_at(phase, p, codes, y, lam, g)
    for e in range(ng):
        if not math.isfinite(g[e]):
            return rk.STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
    h_abs = min(1e-4, t_max)  # the controller grows it by up to 5x a step
    tp_old = t0
    hp = 0.0
    have_prev = False
    nreject = 0
    while True:
        if nsteps >= max_steps:
            return rk.STATUS_TOO_MANY_STEPS, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        if not _jacobian(mi, phase, p, y, with_diss, Jm):
            return rk.STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        nfev += 1
        min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
        rejected = False
        h = 0.0
        t_new = t
        while True:
            if not (h_abs >= min_step) or nreject > MAX_REJECTIONS:
                return rk.STATUS_STEP_TOO_SMALL, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
            t_new = min(t + h_abs, t_bound)
            h = t_new - t
            h_abs = h
            good = ros_step(mi, phase, p, y, f, Jm, h, with_diss, y_new, err, G, lam_new, ws)
            good = rk.rhs_aug(mi, phase, p, y_new, wv, with_diss, f_new, lam_new, ws) and good
            nfev += 11 if wv else 3
            e2 = 0.0
            for i in range(n_err):
                sc = atol + max(abs(y[i]), abs(y_new[i])) * rtol
                e2 += (err[i] / sc) ** 2
            error_norm = math.sqrt(e2 / n_err)
            if not (good and math.isfinite(error_norm)):
                h_abs *= _MIN_FACTOR
                rejected = True
                nreject += 1
                continue
            if error_norm < 1.0:
                factor = _MAX_FACTOR if error_norm == 0.0 else min(_MAX_FACTOR, _SAFETY * error_norm**_ERR_EXP)
                if rejected:
                    factor = min(1.0, factor)
                h_abs *= factor
                break
            h_abs *= max(_MIN_FACTOR, _SAFETY * error_norm**_ERR_EXP)
            rejected = True
            nreject += 1
        nsteps += 1
        if h * rate > 6.1:  # a step the explicit method could not take (its stiffness indicator's threshold)
            nstiff += 1
        rk.guards_at(phase, p, codes, y_new, lam_new, g_new)
        for e in range(ng):
            if not math.isfinite(g_new[e]):
                return rk.STATUS_NOT_FINITE, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        _hermite(y, f, y_new, f_new, h, F)
        best_t = np.inf
        best_e = -1
        best_prev = False
        any_active = False
        for e in range(ng):
            if rk.crossing(g[e], g_new[e], directions[e], strict):
                any_active = True
        for e in range(ng):
            root = np.inf
            if rk.crossing(g[e], g_new[e], directions[e], strict):
                root, nf = rk.brent_on_dense(mi, phase, p, codes[e], False, t, t_new, t, h, F, y)
                nfev += nf if rk.needs_lambda(codes[e]) else 0
            elif codes[e] == fm.TOUCHDOWN and g[e] > 0.0 and g_new[e] > 0.0:
                if fm.swing_height_rate(y, L0) < 0.0 and fm.swing_height_rate(y_new, L0) > 0.0:  # a graze
                    tmin, nf = rk.brent_on_dense(mi, phase, p, fm.TOUCHDOWN, True, t, t_new, t, h, F, y)
                    ybuf = np.empty(N)
                    gmin = rk.guard_on_dense(
                        mi, phase, p, fm.TOUCHDOWN, tmin, t, h, F, y, ybuf, np.empty(5), lam, False
                    )
                    if gmin <= 0.0:
                        root, nf = rk.brent_on_dense(mi, phase, p, fm.TOUCHDOWN, False, t, tmin, t, h, F, y)
            elif fm.guard_needs_lambda(codes[e]) and g[e] > 0.0 and g_new[e] > 0.0:
                # a normal force that may dip below zero between step ends (the engine's dip rule)
                if have_prev and g_pp[e] > g[e] and g[e] < g_new[e] and g_pp[e] > 0.0:
                    if rk.parabola_min(tp_old, g_pp[e], t, g[e], t_new, g_new[e]) <= DIP_MARGIN * g[e]:
                        r_prev, nf = rk.first_dip(mi, phase, p, codes[e], tp_old, hp, Fp, yp_old, g_pp[e], g[e])
                        nfev += nf
                        if r_prev < best_t:
                            best_t = r_prev
                            best_e = e
                            best_prev = True
                        root, nf = rk.first_dip(mi, phase, p, codes[e], t, h, F, y, g[e], g_new[e])
                        nfev += nf
                elif (not have_prev and g[e] < g_new[e]) or (g[e] > g_new[e] and (any_active or t_new == t_bound)):
                    root, nf = rk.first_dip(mi, phase, p, codes[e], t, h, F, y, g[e], g_new[e])
                    nfev += nf
            if root < best_t:
                best_t = root
                best_e = e
                best_prev = False
        t_stop = best_t if best_e >= 0 else t_new
        if recording:
            rec_t, rec_y, nrec, next_grid = rk.record_grid(
                rec_t, rec_y, nrec, next_grid, t0, record_dt, t_stop, F, y, t, h, np.empty(N)
            )
        if best_e >= 0:
            y_end = np.empty(N)
            if best_prev:  # the dip was in the previous step: refine there (its Jacobian again)
                fp = np.empty(N)
                rk.rhs_aug(mi, phase, p, yp_old, wv, with_diss, fp, lam, ws)
                _jacobian(mi, phase, p, yp_old, with_diss, Jm)
                t_ev, nf = _refine(
                    mi, phase, p, codes[best_e], tp_old, best_t, t, yp_old, fp, Jm, with_diss, y_end, lam, ws
                )
                nfev += nf + 2
                while nrec > 0 and rec_t[nrec - 1] >= t_ev:
                    nrec -= 1
            else:
                t_ev, nf = _refine(mi, phase, p, codes[best_e], t, best_t, t_new, y, f, Jm, with_diss, y_end, lam, ws)
                nfev += nf
            if recording:
                nrec = rk.record_point(rec_t, rec_y, nrec, t_ev, y_end)
            return rk.STATUS_OK, t_ev, y_end, best_e, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]
        if recording:
            nrec = rk.record_point(rec_t, rec_y, nrec, t_new, y_new)
        for i in range(N):
            yp_old[i] = y[i]
            for k in range(7):
                Fp[k, i] = F[k, i]
        for e in range(ng):
            g_pp[e] = g[e]
        tp_old = t
        hp = h
        have_prev = True
        t = t_new
        for i in range(N):
            y[i] = y_new[i]
            f[i] = f_new[i]
        for i in range(6):
            lam[i] = lam_new[i]
        for e in range(ng):
            g[e] = g_new[e]
        if t == t_bound:
            return rk.STATUS_OK, t, y, -1, nfev, nsteps, nstiff, rec_t[:nrec], rec_y[:nrec]


# Per-mass-model entry points from Python (the index a compile-time constant, as rk.RUN_PHASE).
@_jit
def run_phase_stiff_0(phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps):
    return run_phase_stiff(
        0, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps
    )


@_jit
def run_phase_stiff_1(phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps):
    return run_phase_stiff(
        1, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps
    )


@_jit
def run_phase_stiff_2(phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps):
    return run_phase_stiff(
        2, phase, p, y0, t0, codes, directions, t_max, rtol, atol, n_err, with_diss, record_dt, max_steps
    )


RUN_PHASE_STIFF = (run_phase_stiff_0, run_phase_stiff_1, run_phase_stiff_2)
