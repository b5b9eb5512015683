"""The exact step-map Jacobian with guide friction: the compiled tangent maps at the events of a step whose
phases run as stick/slip sub-phases (rimless.sim.integrate.friction, docs/simulator.md "Guide friction").

Between events the tangents V = dy/dz (10 x 2) follow the variational equations of the friction phase
(rimless.sim.fast.rk with the variational equations: `_friction_directional`). At every event that ends a
sub-phase (code-) and starts the next (code+) at the same instant, V goes through the saltation matrix
    S = dR + (f+ - dR f-) dg^T / (dg . f-),
f- the field of code- at the event state y-, f+ that of code+ at the state it starts from y+, dg = dg/dy of the
guard that fired (in code-), dR = identity with the rows of the components the switch sets (y+ differs from y-
there: a rate set to 0) zeroed. The events: lift-off (LIFTOFF_A), the clutch's lock (CLUTCH_LOCK, L1' := 0),
a slip's end (SLIP_END_i: the leg sticks, L_i' := 0, or slips on the other way; in double support the slide
reverses) and a stick's end (STICK_END_i = F_c - |lambda_i|, dg = -sign(lambda_i) dlambda_i/dy, from the
differentiated KKT system of the stuck phase, rimless.sim.fast.rk.friction_accel_jacobian). At touchdown,
V is projected along the touchdown-time variation, (I - f- dg^T / (dg . f-)) V, and carried through the exact
derivative of the relabel + impact reset (rimless.sim.fast.model.impact), as the frictionless step kernel does.
Then dz'/dz = rows (theta, theta') of the result.

The step itself (its phase sequence, pre-checks and failures) is rimless.sim.step.hybrid.simulate_step's;
rimless.sim.step.fast_map.friction_step(jacobian=True) runs it with these kernels. Per-mass-model entry points
(index a compile-time constant: one mass model's generated code compiled), indexed by MASS_MODEL_INDEX.
Units: SI; y = [q, q'] with q = [x_b, y_b, theta, L1, L2] (m, m, rad, m, m); p = Mechanics.p (F_c at index 8).
"""

from __future__ import annotations

import math

import numpy as np

from rimless.sim.fast import model as fm
from rimless.sim.fast import rk
from rimless.sim.fast.compiling import kernel
from rimless.sim.model.guards import (
    LIFTOFF_A,
    LIFTOFF_B,
    SLIP_END_1,
    SLIP_END_2,
    STICK_END_1,
    STICK_END_2,
    TOUCHDOWN,
)

_jit = kernel
_inner = kernel(python=False)


@_inner
def _field(mi, code, y, p, f, Dlam):
    """f = [q', q''] (10,) of friction phase `code` at y and dlambda/dy into Dlam (6 x 10); False if singular."""
    qdd = np.empty(5)
    lam = np.zeros(6)
    Dqdd = np.empty((5, 10))
    ok = rk.friction_accel_jacobian(mi, code, p, y[0:5], y[5:10], qdd, lam, Dqdd, Dlam)
    for i in range(5):
        f[i] = y[5 + i]
        f[5 + i] = qdd[i]
    for i in range(10):
        if not math.isfinite(f[i]):
            return False
    return ok


@_inner
def guard_gradient(mi, code, guard, y, p):
    """dg/dy (10,) of `guard` in friction phase `code` at y (the guards of rimless.sim.fast.rk._guard_value)."""
    if guard == SLIP_END_1 or guard == SLIP_END_2:
        g = np.zeros(10)
        leg = 1 if guard == SLIP_END_1 else 2
        g[7 + leg] = 1.0 if rk.leg_state(code, leg) == rk.SLIP_UP else -1.0
        return g
    if guard == STICK_END_1 or guard == STICK_END_2 or guard == LIFTOFF_A or guard == LIFTOFF_B:
        g = np.zeros(10)
        Dlam = np.zeros((6, 10))
        qdd = np.empty(5)
        lam = np.zeros(6)
        Dqdd = np.empty((5, 10))
        rk.friction_accel_jacobian(mi, code, p, y[0:5], y[5:10], qdd, lam, Dqdd, Dlam)
        if guard == LIFTOFF_A:
            row = 3
            sign = 1.0
        elif guard == LIFTOFF_B:
            row = 1
            sign = 1.0
        else:
            row = rk.stuck_row(code, 1 if guard == STICK_END_1 else 2)
            sign = -1.0 if lam[row] > 0.0 else 1.0  # g = F_c - |lambda|
        for j in range(10):
            g[j] = sign * Dlam[row, j]
        return g
    return fm.guard_gradient(mi, code, guard, y, p)  # STALL, CLUTCH_LOCK, TOUCHDOWN: geometric, any phase


@_inner
def event_tangent(mi, code_minus, guard, y_minus, code_plus, y_plus, p, V):
    """(ok, S V): the tangents V (10 x 2) at y_minus (end of sub-phase code_minus, where `guard` fired) carried
    to y_plus (start of code_plus) by the saltation matrix (module docstring). ok False if a KKT matrix is
    singular or the guard is tangent to the flow (dg . f- = 0)."""
    out = np.zeros((10, 2))
    f_minus = np.empty(10)
    f_plus = np.empty(10)
    Dlam = np.zeros((6, 10))
    if not _field(mi, code_minus, y_minus, p, f_minus, Dlam):
        return False, out
    if not _field(mi, code_plus, y_plus, p, f_plus, Dlam):
        return False, out
    dg = guard_gradient(mi, code_minus, guard, y_minus, p)
    den = 0.0
    for i in range(10):
        den += dg[i] * f_minus[i]
    if not (den != 0.0 and math.isfinite(den)):
        return False, out
    for c in range(2):
        gv = 0.0
        for i in range(10):
            gv += dg[i] * V[i, c]
        for i in range(10):
            rv = V[i, c]
            rf = f_minus[i]
            if y_plus[i] != y_minus[i]:  # a component the switch sets (a rate set to 0): its row of dR is 0
                rv = 0.0
                rf = 0.0
            out[i, c] = rv + (f_plus[i] - rf) * gv / den
    return True, out


@_inner
def touchdown_tangent(mi, code, y_minus, p, V):
    """(ok, y+ (10,), impulse (4,), dz'/dz (2 x 2)): V at touchdown (end of friction phase `code`) projected
    along the touchdown-time variation and carried through the exact relabel + impact derivative."""
    J = np.zeros((2, 2))
    f_minus = np.empty(10)
    Dlam = np.zeros((6, 10))
    if not _field(mi, code, y_minus, p, f_minus, Dlam):
        return False, np.zeros(10), np.zeros(4), J
    dg = fm.guard_gradient(mi, code, TOUCHDOWN, y_minus, p)
    den = 0.0
    for i in range(10):
        den += dg[i] * f_minus[i]
    W = np.empty((10, 2))
    for c in range(2):
        gv = 0.0
        for i in range(10):
            gv += dg[i] * V[i, c]
        for i in range(10):
            W[i, c] = V[i, c] - f_minus[i] * gv / den
    ok, yp, impulse, Vp = fm.impact(mi, y_minus, p, W, True)
    J[0, 0] = Vp[2, 0]
    J[0, 1] = Vp[2, 1]
    J[1, 0] = Vp[7, 0]
    J[1, 1] = Vp[7, 1]
    ok = ok and den != 0.0 and math.isfinite(den)
    for i in range(2):
        for j in range(2):
            if not math.isfinite(J[i, j]):
                ok = False
    return ok, yp, impulse, J


# Per-mass-model entry points (called from Python): the section tangent, the event and the touchdown tangents.
@_jit
def section_0(z, p):
    return fm.state_from_section(0, z, p)


@_jit
def section_1(z, p):
    return fm.state_from_section(1, z, p)


@_jit
def section_2(z, p):
    return fm.state_from_section(2, z, p)


@_jit
def event_tangent_0(code_minus, guard, y_minus, code_plus, y_plus, p, V):
    return event_tangent(0, code_minus, guard, y_minus, code_plus, y_plus, p, V)


@_jit
def event_tangent_1(code_minus, guard, y_minus, code_plus, y_plus, p, V):
    return event_tangent(1, code_minus, guard, y_minus, code_plus, y_plus, p, V)


@_jit
def event_tangent_2(code_minus, guard, y_minus, code_plus, y_plus, p, V):
    return event_tangent(2, code_minus, guard, y_minus, code_plus, y_plus, p, V)


@_jit
def touchdown_tangent_0(code, y_minus, p, V):
    return touchdown_tangent(0, code, y_minus, p, V)


@_jit
def touchdown_tangent_1(code, y_minus, p, V):
    return touchdown_tangent(1, code, y_minus, p, V)


@_jit
def touchdown_tangent_2(code, y_minus, p, V):
    return touchdown_tangent(2, code, y_minus, p, V)


SECTION = (section_0, section_1, section_2)
EVENT_TANGENT = (event_tangent_0, event_tangent_1, event_tangent_2)
TOUCHDOWN_TANGENT = (touchdown_tangent_0, touchdown_tangent_1, touchdown_tangent_2)
