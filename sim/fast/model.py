"""Compiled (numba) mechanics of the three mass models: the KKT phase dynamics and their exact derivatives,
the guards, the impact (relabel + inelastic projection) with its exact Jacobian, and the section map.

One concept: the compiled mechanics of a wheel (one mass model's generated equations and what is built on them).

Same equations and conventions as rimless.sim.model.dynamics / events / impact / section (model.md sections 2-6):
slope frame (x down the slope, y the outward normal), q = [x_b, y_b, theta, L1, L2] (m, m, rad, m, m),
y = [q, q'] (10,), parameter vector p = WheelParams.as_vector() = (m_H, m, I_c, L0, k, c, g, phi), SI units.

The generated functions (rimless.sim.model.generated.*) are compiled as they are; a mass model is selected by an
integer index (MASS_MODEL_INDEX): a compile-time constant in the per-model entry points (one model's generated
code compiled, see below), a run-time switch over the three when a kernel is called from Python with it.
"""

from __future__ import annotations

import math

import numpy as np
from numba.core import types as _nbt
from numba.extending import overload

from rimless.sim.fast.compiling import kernel
from rimless.sim.model.dynamics import DLSP, SLSP_CLUTCHED, SLSP_FREE
from rimless.sim.model.generated import active_feet as _af
from rimless.sim.model.generated import eight_leg as _el
from rimless.sim.model.generated import sliding_leg as _sl
from rimless.sim.model.guards import CLUTCH_LOCK, LIFTOFF_A, LIFTOFF_B, STALL, TOUCHDOWN
from rimless.sim.model.params import SPOKE_ANGLE_RAD

ALPHA = SPOKE_ANGLE_RAD
MASS_MODEL_INDEX = {"eight-leg": 0, "sliding-leg": 1, "active-feet": 2}

# Phase codes and guard codes: the module-level ints of rimless.sim.model.dynamics and of the one guard
# table rimless.sim.model.guards (numba freezes them into the compiled code as constants).

_jit = kernel  # numba.njit(cache=True), specialised on the mass model index only (compiling.kernel)
_inner = kernel(python=False)  # the same, called from compiled code only (no wrapper for Python)


def _compile(name: str) -> tuple:
    return tuple(_inner(getattr(mod, name)) for mod in (_el, _sl, _af))


_M0, _M1, _M2 = _compile("mass_matrix")
_H0, _H1, _H2 = _compile("bias")
_JA0, _JA1, _JA2 = _compile("jac_a")
_JDOT0, _JDOT1, _JDOT2 = _compile("jdot_qd_a")
_DM0, _DM1, _DM2 = _compile("dmass_dq")
_DHQ0, _DHQ1, _DHQ2 = _compile("dbias_dq")
_DHD0, _DHD1, _DHD2 = _compile("dbias_dqd")
_DJA0, _DJA1, _DJA2 = _compile("djac_a_dq")
_DJQ0, _DJQ1, _DJQ2 = _compile("djdot_qd_a_dq")
_DJD0, _DJD1, _DJD2 = _compile("djdot_qd_a_dqd")
_T0, _T1, _T2 = _compile("kinetic")
_V0, _V1, _V2 = _compile("potential")
# the generated reduced phase equations (rimless.sim.model.derive.REDUCED_PHASES), [phase][mass model]
_DL0, _DL1, _DL2 = _compile("dlsp_accel")
_SSF0, _SSF1, _SSF2 = _compile("slsp_free_accel")
_SSC0, _SSC1, _SSC2 = _compile("slsp_clutched_accel")
_DLD0, _DLD1, _DLD2 = _compile("dlsp_dir")
_SSFD0, _SSFD1, _SSFD2 = _compile("slsp_free_dir")
_SSCD0, _SSCD1, _SSCD2 = _compile("slsp_clutched_dir")


# One mass model compiled, not three: the kernels pass the mass model index `mi` down to the five places below
# that pick a model's generated functions. When `mi` is a compile-time constant (the per-model entry points
# rimless.sim.fast.step.STEP_MAP / rk.RUN_PHASE call the kernels with a literal 0, 1 or 2, which numba types as
# Literal[int]), the overloads return the implementation of that model only, so the other two models' generated
# code is never compiled; called with a run-time int (from Python, e.g. tests and benchmarks), they return the
# run-time switch over all three (prefer_literal=True: numba would otherwise try, and take, the run-time switch
# first). The same generated functions run either way: results are identical.


def _literal(mi):
    return mi.literal_value if isinstance(mi, _nbt.IntegerLiteral) else None


def _terms_of(mi, q, qd, p):
    raise NotImplementedError("compiled code only")


@overload(_terms_of, prefer_literal=True)  # the literal first: one mass model
def _ov_terms_of(mi, q, qd, p):
    v = _literal(mi)
    if v is not None:
        M, H, JA, JD = ((_M0, _H0, _JA0, _JDOT0), (_M1, _H1, _JA1, _JDOT1), (_M2, _H2, _JA2, _JDOT2))[v]
        return lambda mi, q, qd, p: (M(q, p), H(q, qd, p), JA(q, p), JD(q, qd, p))

    def generic(mi, q, qd, p):
        if mi == 0:
            return _M0(q, p), _H0(q, qd, p), _JA0(q, p), _JDOT0(q, qd, p)
        if mi == 1:
            return _M1(q, p), _H1(q, qd, p), _JA1(q, p), _JDOT1(q, qd, p)
        return _M2(q, p), _H2(q, qd, p), _JA2(q, p), _JDOT2(q, qd, p)

    return generic


def _energy_of(mi, q, qd, p):
    raise NotImplementedError("compiled code only")


@overload(_energy_of, prefer_literal=True)  # the literal first: one mass model
def _ov_energy_of(mi, q, qd, p):
    v = _literal(mi)
    if v is not None:
        T, V = ((_T0, _V0), (_T1, _V1), (_T2, _V2))[v]
        return lambda mi, q, qd, p: T(q, qd, p) + V(q, p)

    def generic(mi, q, qd, p):
        if mi == 0:
            return _T0(q, qd, p) + _V0(q, p)
        if mi == 1:
            return _T1(q, qd, p) + _V1(q, p)
        return _T2(q, qd, p) + _V2(q, p)

    return generic


def _derivs_of(mi, q, qd, p):
    raise NotImplementedError("compiled code only")


@overload(_derivs_of, prefer_literal=True)  # the literal first: one mass model
def _ov_derivs_of(mi, q, qd, p):
    v = _literal(mi)
    if v is not None:
        DM, DHQ, DHD, DJA, DJQ, DJD = (
            (_DM0, _DHQ0, _DHD0, _DJA0, _DJQ0, _DJD0),
            (_DM1, _DHQ1, _DHD1, _DJA1, _DJQ1, _DJD1),
            (_DM2, _DHQ2, _DHD2, _DJA2, _DJQ2, _DJD2),
        )[v]
        return lambda mi, q, qd, p: (DM(q, p), DHQ(q, qd, p), DHD(q, qd, p), DJA(q, p), DJQ(q, qd, p), DJD(q, qd, p))

    def generic(mi, q, qd, p):
        if mi == 0:
            return _DM0(q, p), _DHQ0(q, qd, p), _DHD0(q, qd, p), _DJA0(q, p), _DJQ0(q, qd, p), _DJD0(q, qd, p)
        if mi == 1:
            return _DM1(q, p), _DHQ1(q, qd, p), _DHD1(q, qd, p), _DJA1(q, p), _DJQ1(q, qd, p), _DJD1(q, qd, p)
        return _DM2(q, p), _DHQ2(q, qd, p), _DHD2(q, qd, p), _DJA2(q, p), _DJQ2(q, qd, p), _DJD2(q, qd, p)

    return generic


def _reduced_of(mi, phase, q, qd, p, qdd, lam):
    raise NotImplementedError("compiled code only")


@overload(_reduced_of, prefer_literal=True)  # the literal first: one mass model
def _ov_reduced_of(mi, phase, q, qd, p, qdd, lam):
    v = _literal(mi)
    if v is not None:
        DL, SSF, SSC = ((_DL0, _SSF0, _SSC0), (_DL1, _SSF1, _SSC1), (_DL2, _SSF2, _SSC2))[v]

        def one(mi, phase, q, qd, p, qdd, lam):
            if phase == DLSP:
                return DL(q, qd, p, qdd, lam)
            if phase == SLSP_FREE:
                return SSF(q, qd, p, qdd, lam)
            return SSC(q, qd, p, qdd, lam)

        return one

    def generic(mi, phase, q, qd, p, qdd, lam):
        if phase == DLSP:
            if mi == 0:
                return _DL0(q, qd, p, qdd, lam)
            if mi == 1:
                return _DL1(q, qd, p, qdd, lam)
            return _DL2(q, qd, p, qdd, lam)
        if phase == SLSP_FREE:
            if mi == 0:
                return _SSF0(q, qd, p, qdd, lam)
            if mi == 1:
                return _SSF1(q, qd, p, qdd, lam)
            return _SSF2(q, qd, p, qdd, lam)
        if mi == 0:
            return _SSC0(q, qd, p, qdd, lam)
        if mi == 1:
            return _SSC1(q, qd, p, qdd, lam)
        return _SSC2(q, qd, p, qdd, lam)

    return generic


def _directional_of(mi, phase, q, qd, p, qdd, lam, V, dqdd):
    raise NotImplementedError("compiled code only")


@overload(_directional_of, prefer_literal=True)  # the literal first: one mass model
def _ov_directional_of(mi, phase, q, qd, p, qdd, lam, V, dqdd):
    v = _literal(mi)
    if v is not None:
        DLD, SSFD, SSCD = ((_DLD0, _SSFD0, _SSCD0), (_DLD1, _SSFD1, _SSCD1), (_DLD2, _SSFD2, _SSCD2))[v]

        def one(mi, phase, q, qd, p, qdd, lam, V, dqdd):
            if phase == DLSP:
                return DLD(q, qd, p, qdd, lam, V, dqdd)
            if phase == SLSP_FREE:
                return SSFD(q, qd, p, qdd, lam, V, dqdd)
            return SSCD(q, qd, p, qdd, lam, V, dqdd)

        return one

    def generic(mi, phase, q, qd, p, qdd, lam, V, dqdd):
        if phase == DLSP:
            if mi == 0:
                return _DLD0(q, qd, p, qdd, lam, V, dqdd)
            if mi == 1:
                return _DLD1(q, qd, p, qdd, lam, V, dqdd)
            return _DLD2(q, qd, p, qdd, lam, V, dqdd)
        if phase == SLSP_FREE:
            if mi == 0:
                return _SSFD0(q, qd, p, qdd, lam, V, dqdd)
            if mi == 1:
                return _SSFD1(q, qd, p, qdd, lam, V, dqdd)
            return _SSFD2(q, qd, p, qdd, lam, V, dqdd)
        if mi == 0:
            return _SSCD0(q, qd, p, qdd, lam, V, dqdd)
        if mi == 1:
            return _SSCD1(q, qd, p, qdd, lam, V, dqdd)
        return _SSCD2(q, qd, p, qdd, lam, V, dqdd)

    return generic


@_jit
def terms(mi, q, qd, p):
    """(M (5x5), h (5,), J_a (2x5), J_a' q' (2,)) of mass model index mi: the mass matrix (kg, kg m), the
    bias (Coriolis + dV/dq + damping, generalized forces), foot a's position Jacobian and its rate term."""
    return _terms_of(mi, q, qd, p)


@_jit
def energy(mi, q, qd, p):
    """Total mechanical energy T + V (J) of mass model index mi."""
    return _energy_of(mi, q, qd, p)


@_inner
def _derivs(mi, q, qd, p):
    """(dM/dq [k,i,j], dh/dq [i,k], dh/dqd [i,k], dJ_a/dq [k,r,j], d(J_a'q')/dq [r,k], d(J_a'q')/dqd [r,k])."""
    return _derivs_of(mi, q, qd, p)


derivs = _derivs  # the generated derivatives, for the friction phases' exact Jacobian (rimless.sim.fast.stiff)


# ------------------------------------------------------------------------------------------------
# Small dense LU with partial pivoting (the KKT systems are at most 9x9).


@_inner
def lu_factor(K, n, piv):
    """In-place LU of K[:n, :n] with row pivots; False if singular or not finite."""
    for j in range(n):
        best = j
        vmax = abs(K[j, j])
        for i in range(j + 1, n):
            v = abs(K[i, j])
            if v > vmax:
                vmax = v
                best = i
        if not (vmax > 0.0) or not math.isfinite(vmax):
            return False
        piv[j] = best
        if best != j:
            for c in range(n):
                tmp = K[j, c]
                K[j, c] = K[best, c]
                K[best, c] = tmp
        inv = 1.0 / K[j, j]
        for i in range(j + 1, n):
            K[i, j] *= inv
            f = K[i, j]
            if f != 0.0:
                for c in range(j + 1, n):
                    K[i, c] -= f * K[j, c]
    return True


@_inner
def lu_solve(K, n, piv, b):
    """Solve with the factors of lu_factor, b (n,) overwritten with the solution."""
    for j in range(n):
        pj = piv[j]
        if pj != j:
            tmp = b[j]
            b[j] = b[pj]
            b[pj] = tmp
    for i in range(n):
        s = b[i]
        for c in range(i):
            s -= K[i, c] * b[c]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for c in range(i + 1, n):
            s -= K[i, c] * b[c]
        b[i] = s / K[i, i]


# ------------------------------------------------------------------------------------------------
# Phase dynamics: [[M, -A^T], [A, 0]] [q''; lambda] = [-h; -A' q'] (rimless.sim.model.dynamics.accel).


@_inner
def n_constraints(phase):
    if phase == DLSP:
        return 4
    if phase == SLSP_CLUTCHED:
        return 3
    return 2


@_inner
def constraint_rows(phase, Ja, jd):
    """(A (n x 5), A' q' (n,)) of a phase, given foot a's Jacobian J_a and J_a' q'."""
    n = n_constraints(phase)
    A = np.zeros((n, 5))
    adot = np.zeros(n)
    A[0, 0] = 1.0
    A[1, 1] = 1.0
    if phase == DLSP:
        for r in range(2):
            adot[2 + r] = jd[r]
            for c in range(5):
                A[2 + r, c] = Ja[r, c]
    elif phase == SLSP_CLUTCHED:
        A[2, 3] = 1.0
    return A, adot


@_inner
def kkt_factor(mi, phase, q, qd, p, K, piv):
    """Assemble and factor the KKT matrix into K (9x9 workspace); returns (ok, n, M, h, A, A'q')."""
    M, h, Ja, jd = terms(mi, q, qd, p)
    A, adot = constraint_rows(phase, Ja, jd)
    nc = A.shape[0]
    n = 5 + nc
    for i in range(n):
        for j in range(n):
            K[i, j] = 0.0
    for i in range(5):
        for j in range(5):
            K[i, j] = M[i, j]
    for r in range(nc):
        for c in range(5):
            K[c, 5 + r] = -A[r, c]
            K[5 + r, c] = A[r, c]
    ok = lu_factor(K, n, piv)
    return ok, n, M, h, A, adot


WORKSPACE_SIZE = 40  # float64 workspace callers pass to accel_reduced / accel_directional (unused by them)


#: a phase counts as stiff (single support integrated by rimless.sim.fast.stiff.run_phase_stiff, double support's
#: field solved by the pivoted KKT system, `kkt_in_double_support`) when the free leg's fastest root
#: |lambda| = max(c / m, sqrt(k / m)) (1/s) exceeds this: DOP853's stability limit then allows steps below some
#: 6 / 5000 = 1.2 ms, while the step's own motion (hub swing, ~15 rad/s) allows tens of ms at rtol 1e-8.
#: Table 1 (|lambda| ~ 270 1/s) stays on DOP853 and the generated equations with a margin of 18.
STIFF_LEG_RATE = 5000.0


@_jit
def leg_rate(p):
    """The free leg's fastest root |lambda| = max(c / m, sqrt(k / m)), 1/s (p: the parameter vector)."""
    m, k, c = p[1], p[4], p[5]
    return max(c / m, math.sqrt(k / m))


@_jit
def leg_stiff(p):
    """Whether the legs are near-massless in the sense of `STIFF_LEG_RATE` (Table 1's are not)."""
    return leg_rate(p) > STIFF_LEG_RATE


@_inner
def kkt_in_double_support(phase, p):
    """Whether q'' and lambda of `phase` come from the pivoted KKT solve (accel_kkt, accel_jacobian) instead of
    the generated reduced equations: in double support with near-massless legs (`leg_stiff`).

    Why: the reduced equations eliminate foot a's constraints through the Cholesky factor of the free block of M
    (theta, L1, L2), whose L2 row is the trailing foot's mass m alone; the constraint forces then cancel terms of
    size k (L0 - L2) / m, and q'' carries a rounding error of some eps (m_H / m)^2 m/s^2 (measured against a
    40-digit solve of the same KKT system: 1.7e-8 at m = 0.1 g, 6.6e-4 at 1 mg, where q'' is ~3). DOP853 then
    rejects step after step on that noise (1 mg legs: more than 200 000 steps in double support). The pivoted
    9 x 9 KKT solve (as the reference rimless.sim.model.dynamics.accel) has no such cancellation (1e-14 at
    1e-4 to 1e-8 kg). Table 1's legs keep the generated equations (their results bit for bit)."""
    return phase == DLSP and leg_stiff(p)


@_jit
def accel_reduced(mi, phase, q, qd, p, qdd, lam, ws):
    """q'' (5,) and lambda (n,) of a phase from the generated reduced equations (rimless.sim.model.generated.*
    dlsp_accel / slsp_free_accel / slsp_clutched_accel: the free block of M, the pinned rows, the bias and in
    double support foot a's constraint rows, common subexpressions shared). Same solution as the full KKT
    solve (accel_kkt) for any state, which replaces them where they lose accuracy (`kkt_in_double_support`);
    False if singular. ws is not used (kept for the callers' signature)."""
    if kkt_in_double_support(phase, p):
        return accel_kkt(mi, phase, q, qd, p, qdd, lam)
    return _reduced_of(mi, phase, q, qd, p, qdd, lam)


@kernel(inline="always", python=True)  # one call site (two for _guards_at): no library of its own
def accel_directional(mi, phase, q, qd, p, qdd, lam, V, dqdd, ws):
    """q'', lambda (as accel_reduced) and the directional derivatives dqdd[:, c] = (dq''/dy) V[:, c] for the
    columns of V (10 x ncol), exactly, from the generated reduced equations (*_dir): the differentiated KKT
    system [[M, -A^T], [A, 0]] [dq''; dlambda] = [-dh - dM q'' + dA^T lambda ; -d(A' q') - dA q''] in the
    phase's free coordinates, for any state and tangent (the full form is accel_jacobian, used instead where
    the reduced equations lose accuracy, `kkt_in_double_support`)."""
    if kkt_in_double_support(phase, p):
        D = np.empty((5, 10))
        Dlam = np.empty((4, 10))
        if not accel_jacobian(mi, phase, q, qd, p, qdd, lam, D, Dlam):
            return False
        for i in range(5):
            for c in range(V.shape[1]):
                acc = 0.0
                for j in range(10):
                    acc += D[i, j] * V[j, c]
                dqdd[i, c] = acc
        return True
    return _directional_of(mi, phase, q, qd, p, qdd, lam, V, dqdd)


@_jit
def accel(mi, phase, q, qd, p, qdd, lam):
    """q'' (5,) and lambda (n,) of a phase written into qdd and lam; False if singular."""
    ws = np.empty(WORKSPACE_SIZE)
    return accel_reduced(mi, phase, q, qd, p, qdd, lam, ws)


@_jit
def accel_kkt(mi, phase, q, qd, p, qdd, lam):
    """q'' (5,) and lambda (n,) by the full KKT solve (the reference formulation; used to check accel)."""
    K = np.empty((9, 9))
    piv = np.empty(9, dtype=np.int64)
    ok, n, M, h, A, adot = kkt_factor(mi, phase, q, qd, p, K, piv)
    if not ok:
        return False
    b = np.empty(n)
    for i in range(5):
        b[i] = -h[i]
    for r in range(n - 5):
        b[5 + r] = -adot[r]
    lu_solve(K, n, piv, b)
    for i in range(5):
        qdd[i] = b[i]
    for r in range(n - 5):
        lam[r] = b[5 + r]
    return True


@_inner
def jacobian_rhs(col, dlsp, qdd, lam, dM, dh_dq, dh_dqd, dJa, djd_dq, djd_dqd, rhs):
    """The right-hand side of the differentiated KKT system for state direction `col` (0-4: q_k, 5-9: q'_k),
    [-dh - dM q'' + dA^T lambda ; -d(A' q') - dA q''], added into rhs (zero on entry); dlsp: foot a's rows 2..3
    (lambda rows 2..3) depend on the state. Constant constraint rows (a stuck leg's) and constant forces add
    nothing (the guide-friction phases, rimless.sim.fast.stiff)."""
    if col < 5:
        k = col
        for i in range(5):
            s = -dh_dq[i, k]
            for j in range(5):
                s -= dM[k, i, j] * qdd[j]
            rhs[i] = s
        if dlsp:
            # dA/dq_k: rows 2..3 are dJ_a/dq_k
            for r in range(2):
                for i in range(5):
                    rhs[i] += dJa[k, r, i] * lam[2 + r]
                s = -djd_dq[r, k]
                for j in range(5):
                    s -= dJa[k, r, j] * qdd[j]
                rhs[5 + 2 + r] = s
    else:
        k = col - 5
        for i in range(5):
            rhs[i] = -dh_dqd[i, k]
        if dlsp:
            for r in range(2):
                rhs[5 + 2 + r] = -djd_dqd[r, k]


@_jit
def accel_jacobian(mi, phase, q, qd, p, qdd, lam, Dqdd, Dlam):
    """q'', lambda and their exact derivatives with respect to y = [q, q'].

    Differentiating M q'' + h = A^T lambda and A q'' + A' q' = 0 gives, for each of the 10 state directions,
    the same KKT matrix with the right-hand side
    [-dh - dM q'' + dA^T lambda ; -d(A' q') - dA q''].  Dqdd (5x10) and Dlam (n x 10) are filled.
    """
    K = np.empty((9, 9))
    piv = np.empty(9, dtype=np.int64)
    ok, n, M, h, A, adot = kkt_factor(mi, phase, q, qd, p, K, piv)
    if not ok:
        return False
    nc = n - 5
    b = np.empty(n)
    for i in range(5):
        b[i] = -h[i]
    for r in range(nc):
        b[5 + r] = -adot[r]
    lu_solve(K, n, piv, b)
    for i in range(5):
        qdd[i] = b[i]
    for r in range(nc):
        lam[r] = b[5 + r]
    dM, dh_dq, dh_dqd, dJa, djd_dq, djd_dqd = _derivs(mi, q, qd, p)
    for col in range(10):
        rhs = np.zeros(n)
        jacobian_rhs(col, phase == DLSP, qdd, lam, dM, dh_dq, dh_dqd, dJa, djd_dq, djd_dqd, rhs)
        lu_solve(K, n, piv, rhs)
        for i in range(5):
            Dqdd[i, col] = rhs[i]
        for r in range(nc):
            Dlam[r, col] = rhs[5 + r]
    return True


@_inner
def damping_power(phase, qd, p):
    """Power dissipated by the leg dampers, W."""
    l1 = 0.0 if phase == SLSP_CLUTCHED else qd[3]
    return p[5] * (l1 * l1 + qd[4] * qd[4])


# ------------------------------------------------------------------------------------------------
# Guards (rimless.sim.model.guards): value, and gradient with respect to y for the saltation matrices.


@_inner
def swing_height(q, L0):
    """Height of the next swing foot above the slope, m."""
    return q[1] + q[3] * math.cos(q[2]) - L0 * math.cos(ALPHA - q[2])


@_inner
def swing_height_rate(y, L0):
    """d/dt of the swing height along y = [q, q'], m/s."""
    th = y[2]
    return y[6] + y[8] * math.cos(th) - (y[3] * math.sin(th) + L0 * math.sin(ALPHA - th)) * y[7]


@_inner
def guard_value_from(code, y, lam, L0):
    """Guard value given the state and the phase's lambda at that state."""
    if code == STALL:
        return y[7]
    if code == CLUTCH_LOCK:
        return y[8]
    if code == TOUCHDOWN:
        return swing_height(y, L0)
    if code == LIFTOFF_A:
        return lam[3]
    return lam[1]  # LIFTOFF_B


@_inner
def guard_needs_lambda(code):
    return code == LIFTOFF_A or code == LIFTOFF_B


@_jit
def guard_gradient(mi, phase, code, y, p):
    """dg/dy (10,) of a guard during a phase."""
    g = np.zeros(10)
    if code == STALL:
        g[7] = 1.0
    elif code == CLUTCH_LOCK:
        g[8] = 1.0
    elif code == TOUCHDOWN:
        th = y[2]
        g[1] = 1.0
        g[2] = -y[3] * math.sin(th) - p[3] * math.sin(ALPHA - th)
        g[3] = math.cos(th)
    else:
        qdd = np.empty(5)
        lam = np.empty(4)
        Dqdd = np.empty((5, 10))
        Dlam = np.empty((4, 10))
        accel_jacobian(mi, phase, y[:5], y[5:10], p, qdd, lam, Dqdd, Dlam)
        row = 3 if code == LIFTOFF_A else 1
        for j in range(10):
            g[j] = Dlam[row, j]
    return g


@_inner
def phase_field(mi, phase, y, p):
    """f(y) = [q', q''] (10,) of a phase (nan-filled if the KKT matrix is singular)."""
    f = np.empty(10)
    qdd = np.empty(5)
    lam = np.empty(4)
    if not accel(mi, phase, y[:5], y[5:10], p, qdd, lam):
        f[:] = np.nan
        return f
    for i in range(5):
        f[i] = y[5 + i]
        f[5 + i] = qdd[i]
    return f


# ------------------------------------------------------------------------------------------------
# Impact (rimless.sim.model.impact): relabel, then q'+ = q'~ + M^-1 Jc^T Lambda with Jc q'+ = 0.


@_inner
def relabel_with_jacobian(y, L0):
    """(y~ (10,), dy~/dy (10x10)) of the leg exchange."""
    x, yb, th, L1 = y[0], y[1], y[2], y[3]
    dx, dy, dth, dL1 = y[5], y[6], y[7], y[8]
    s, c = math.sin(th), math.cos(th)
    sa, ca = math.sin(ALPHA - th), math.cos(ALPHA - th)
    yt = np.empty(10)
    yt[0] = x + L1 * s + L0 * sa
    yt[1] = yb + L1 * c - L0 * ca
    yt[2] = th - ALPHA
    yt[3] = L0
    yt[4] = L1
    yt[5] = dx + (L1 * c - L0 * ca) * dth + dL1 * s
    yt[6] = dy - (L1 * s + L0 * sa) * dth + dL1 * c
    yt[7] = dth
    yt[8] = 0.0
    yt[9] = dL1
    D = np.zeros((10, 10))
    D[0, 0] = 1.0
    D[0, 2] = L1 * c - L0 * ca
    D[0, 3] = s
    D[1, 1] = 1.0
    D[1, 2] = -L1 * s - L0 * sa
    D[1, 3] = c
    D[2, 2] = 1.0
    D[4, 3] = 1.0
    D[5, 2] = (-L1 * s - L0 * sa) * dth + dL1 * c
    D[5, 3] = c * dth
    D[5, 5] = 1.0
    D[5, 7] = L1 * c - L0 * ca
    D[5, 8] = s
    D[6, 2] = -(L1 * c - L0 * ca) * dth - dL1 * s
    D[6, 3] = -s * dth
    D[6, 6] = 1.0
    D[6, 7] = -(L1 * s + L0 * sa)
    D[6, 8] = c
    D[7, 7] = 1.0
    D[9, 8] = 1.0
    return yt, D


@_jit
def impact(mi, y_minus, p, V, want_jac):
    """Relabel and inelastic impact: returns (ok, y+ (10,), impulse (4,), dy+/dy- V (10 x ncol)).

    V (10 x ncol) are tangent directions at y-; with want_jac the exact derivative of the reset is applied
    to them (differentiating the KKT form [[M, -Jc^T], [Jc, 0]] [q'+; Lambda] = [M q'~; 0]).
    """
    L0 = p[3]
    yt, D = relabel_with_jacobian(y_minus, L0)
    q = yt[:5].copy()
    qdt = yt[5:10].copy()
    K = np.empty((9, 9))
    piv = np.empty(9, dtype=np.int64)
    ok, n, M, h, A, adot = kkt_factor(mi, DLSP, q, qdt, p, K, piv)
    ncol = V.shape[1]
    Vout = np.zeros((10, ncol))
    yp = np.empty(10)
    impulse = np.zeros(4)
    if not ok:
        return False, yp, impulse, Vout
    b = np.zeros(9)
    for i in range(5):
        s = 0.0
        for j in range(5):
            s += M[i, j] * qdt[j]
        b[i] = s
    lu_solve(K, n, piv, b)
    for i in range(5):
        yp[i] = q[i]
        yp[5 + i] = b[i]
    for r in range(4):
        impulse[r] = b[5 + r]
    if want_jac:
        qdp = yp[5:10]
        Vt = D @ V
        dM, dh_dq, dh_dqd, dJa, djd_dq, djd_dqd = _derivs(mi, q, qdt, p)
        for col in range(ncol):
            rhs = np.zeros(9)
            for i in range(5):
                s = 0.0
                for j in range(5):
                    s += M[i, j] * Vt[5 + j, col]
                rhs[i] = s
            for k in range(5):
                vk = Vt[k, col]
                if vk == 0.0:
                    continue
                for i in range(5):
                    s = 0.0
                    for j in range(5):
                        s += dM[k, i, j] * (qdt[j] - qdp[j])
                    for r in range(2):
                        s += dJa[k, r, i] * impulse[2 + r]
                    rhs[i] += vk * s
                for r in range(2):
                    s = 0.0
                    for j in range(5):
                        s += dJa[k, r, j] * qdp[j]
                    rhs[5 + 2 + r] -= vk * s
            lu_solve(K, n, piv, rhs)
            for i in range(5):
                Vout[i, col] = Vt[i, col]
                Vout[5 + i, col] = rhs[i]
    return True, yp, impulse, Vout


# ------------------------------------------------------------------------------------------------
# The Poincaré section (rimless.sim.model.section): z = (theta+, theta'+) -> y and dy/dz.


@_jit
def state_from_section(mi, z, p):
    """(y (10,), dy/dz (10x2)) of the post-impact state: foot b at the origin, L1 = L0, foot a on the slope,
    q' = theta' times the null vector of J_c."""
    th, thd = z[0], z[1]
    L0 = p[3]
    cta = math.cos(th + ALPHA)
    L2 = L0 * math.cos(th) / cta
    dL2 = L0 * math.sin(ALPHA) / (cta * cta)  # dL2/dtheta
    q = np.array([0.0, 0.0, th, L0, L2])
    Ja = terms(mi, q, np.zeros(5), p)[2]
    # rates r = solve(Ja[:, 3:5], -Ja[:, 2]) by Cramer's rule (2x2)
    a11, a12, a21, a22 = Ja[0, 3], Ja[0, 4], Ja[1, 3], Ja[1, 4]
    det = a11 * a22 - a12 * a21
    b1, b2 = -Ja[0, 2], -Ja[1, 2]
    r1 = (b1 * a22 - a12 * b2) / det
    r2 = (a11 * b2 - a21 * b1) / det
    v = np.array([0.0, 0.0, 1.0, r1, r2])
    # dv/dtheta: Ja v = 0 with q depending on theta through q[2] and q[4]
    dJa = _derivs(mi, q, np.zeros(5), p)[3]
    c1 = 0.0
    c2 = 0.0
    for j in range(5):
        c1 += (dJa[2, 0, j] + dJa[4, 0, j] * dL2) * v[j]
        c2 += (dJa[2, 1, j] + dJa[4, 1, j] * dL2) * v[j]
    dr1 = (-c1 * a22 + a12 * c2) / det
    dr2 = (-a11 * c2 + a21 * c1) / det
    y = np.zeros(10)
    T = np.zeros((10, 2))
    for i in range(5):
        y[i] = q[i]
        y[5 + i] = thd * v[i]
        T[5 + i, 1] = v[i]
    T[2, 0] = 1.0
    T[4, 0] = dL2
    T[8, 0] = thd * dr1
    T[9, 0] = thd * dr2
    return y, T
