"""Symbolic derivation of the equations of motion and generation of the numeric code.

For each mass model of model.md section 8, T and V are written down in sympy, and M(q), the bias
h(q, q') = Coriolis/centrifugal + dV/dq + damping, the foot-a constraint Jacobian J_a(q), the term
J_a'(q, q') q', their derivatives (for the variational equations), T and V are generated as plain
Python functions (math + numpy only, so numba can compile them) into `rimless/sim/generated/`.

Frame (model.md section 2): slope-aligned, x down the slope, y the outward normal;
q = [x_b, y_b, theta, L1, L2]; parameter vector p = (m_H, m, I_c, L0, k, c, g, phi).

Regenerate with `python -m rimless.sim.model.derive`; a test checks the files match a fresh derivation.
"""

from __future__ import annotations

import sys
from functools import cache
from pathlib import Path
from typing import TypedDict

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

GENERATED_DIR = Path(__file__).resolve().parent / "generated"
N_LEGS = 8

q_syms = sp.symbols("x_b y_b theta L1 L2", real=True)
qd_syms = sp.symbols("dx_b dy_b dtheta dL1 dL2", real=True)
p_syms = sp.symbols("m_H m I_c L0 k c g phi", positive=True)

MODEL_NAMES = {"eight-leg": "eight_leg", "sliding-leg": "sliding_leg", "active-feet": "active_feet"}


def _vec(*xs: sp.Expr) -> sp.Matrix:
    return sp.Matrix(xs)


def geometry() -> dict[str, sp.Matrix]:
    """Positions (slope frame) of the hub and of the foot of every leg j = 0..7."""
    x, y, th, L1, L2 = q_syms
    _, _, _, L0, *_ = p_syms
    alpha = 2 * sp.pi / N_LEGS
    hub = _vec(x + L1 * sp.sin(th), y + L1 * sp.cos(th))
    feet = [_vec(x, y), hub - L2 * _vec(sp.sin(th + alpha), sp.cos(th + alpha))]
    for j in range(2, N_LEGS):
        feet.append(hub - L0 * _vec(sp.sin(th + j * alpha), sp.cos(th + j * alpha)))
    return {"hub": hub, **{f"foot{j}": f for j, f in enumerate(feet)}}


def energies(model: str) -> tuple[sp.Matrix, sp.Expr]:
    """Mass matrix M(q) (from T = 1/2 q'^T M q') and potential V(q) for a mass model."""
    mH, m, Ic, L0, k, c, g, phi = p_syms
    x, y, th, L1, L2 = q_syms
    q = sp.Matrix(q_syms)
    geo = geometry()

    def height(pt: sp.Matrix) -> sp.Expr:
        return -pt[0] * sp.sin(phi) + pt[1] * sp.cos(phi)

    def point_mass(pt: sp.Matrix, mass: sp.Expr) -> sp.Matrix:
        J = pt.jacobian(q)
        return mass * (J.T * J)

    e_th = sp.Matrix([0, 0, 1, 0, 0])
    M = point_mass(geo["hub"], mH) + Ic * (e_th * e_th.T)
    V = mH * g * height(geo["hub"])
    if model == "eight-leg":
        for j in range(N_LEGS):
            M += point_mass(geo[f"foot{j}"], m)
            V += m * g * height(geo[f"foot{j}"])
    elif model == "active-feet":
        for j in (0, 1):
            M += point_mass(geo[f"foot{j}"], m)
            V += m * g * height(geo[f"foot{j}"])
    elif model == "sliding-leg":
        M += m * sp.diag(0, 0, 0, 1, 1)
    else:
        raise ValueError(f"unknown mass model {model!r}")
    V += k * (L1 - L0) ** 2 / 2 + k * (L2 - L0) ** 2 / 2
    M = M.applyfunc(lambda e: sp.trigsimp(sp.expand(e)))
    return M, V


@cache
def equations(model: str) -> dict[str, sp.Matrix | sp.Expr]:
    """Every generated quantity of one mass model, as sympy expressions."""
    q = sp.Matrix(q_syms)
    qd = sp.Matrix(qd_syms)
    c = p_syms[5]
    M, V = energies(model)
    n = len(q_syms)
    # Coriolis/centrifugal: C_i = sum_jk (dM_ij/dq_k - 1/2 dM_jk/dq_i) qd_j qd_k
    dM = [M.diff(qk) for qk in q_syms]
    cor = sp.zeros(n, 1)
    for i in range(n):
        s = 0
        for j in range(n):
            for kk in range(n):
                s += (dM[kk][i, j] - sp.Rational(1, 2) * dM[i][j, kk]) * qd[j] * qd[kk]
        cor[i] = s
    grad_v = sp.Matrix([V.diff(qk) for qk in q_syms])
    damping = sp.Matrix([0, 0, 0, c * qd[3], c * qd[4]])
    h = (cor + grad_v + damping).applyfunc(sp.expand)
    foot_a = geometry()["foot1"]
    Ja = foot_a.jacobian(q)
    jdot_qd = (Ja * qd).jacobian(q) * qd
    T = (qd.T * M * qd)[0, 0] / 2
    return {
        "M": M,
        "h": h,
        "V": V,
        "T": T,
        "Ja": Ja,
        "jdot_qd_a": jdot_qd,
        "dM_dq": dM,
        "dh_dq": h.jacobian(q),
        "dh_dqd": h.jacobian(qd),
        "dJa_dq": [Ja.diff(qk) for qk in q_syms],
        "djdot_dq": jdot_qd.jacobian(q),
        "djdot_dqd": jdot_qd.jacobian(qd),
    }


# ----------------------------------------------------------------------------------------------------
# Code generation


class _Printer(PythonCodePrinter):
    def _print_Pi(self, expr: sp.Expr) -> str:
        return "math.pi"


_PRINTER = _Printer({"standard": "python3"})


def _fmt(expr: sp.Expr) -> str:
    return _PRINTER.doprint(expr)


def _unpack(use_q: bool, use_qd: bool) -> list[str]:
    lines = []
    if use_q:
        lines += [f"    {s} = q[{i}]" for i, s in enumerate(q_syms)]
    if use_qd:
        lines += [f"    {s} = qd[{i}]" for i, s in enumerate(qd_syms)]
    lines += [f"    {s} = p[{i}]" for i, s in enumerate(p_syms)]
    return lines


def _function(
    name: str, doc: str, outputs: list[tuple[str, sp.Expr]], shape: tuple[int, ...] | None, use_qd: bool
) -> str:
    """Emit a function computing `outputs` (index string, expression) with common subexpressions."""
    exprs = [e for _, e in outputs]
    replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t"), optimizations="basic")
    args = "q, qd, p" if use_qd else "q, p"
    lines = [f"def {name}({args}):", f'    """{doc}"""']
    used = set().union(*(e.free_symbols for e in exprs)) if exprs else set()
    for sym, _ in replacements:
        used.discard(sym)
    lines += [ln for ln in _unpack(True, use_qd) if ln.split("=")[0].strip() in {str(s) for s in used}]
    for sym, e in replacements:
        lines.append(f"    {sym} = {_fmt(e)}")
    if shape is None:
        lines.append(f"    return {_fmt(reduced[0])}")
    else:
        lines.append(f"    out = np.zeros({shape})")
        for (idx, _), e in zip(outputs, reduced, strict=True):
            if e != 0:
                lines.append(f"    out[{idx}] = {_fmt(e)}")
        lines.append("    return out")
    return "\n".join(lines) + "\n"


def _matrix_outputs(mat: sp.Matrix, symmetric: bool = False) -> list[tuple[str, sp.Expr]]:
    outs = []
    for i in range(mat.rows):
        for j in range(mat.cols):
            if symmetric and j < i:
                continue
            outs.append((f"{i}, {j}", mat[i, j]))
    return outs


def generate_source(model: str) -> str:
    """The full source of the generated module for one mass model."""
    eq = equations(model)
    M = eq["M"]
    parts = [
        f'"""Generated by rimless.sim.model.derive for the `{model}` mass model. Do not edit.\n\n'
        "q = [x_b, y_b, theta, L1, L2] (m, m, rad, m, m) in the slope frame; qd its rate;\n"
        'p = (m_H, m, I_c, L0, k, c, g, phi) in SI units.\n"""\n\n'
        "import math\n\nimport numpy as np\n\n"
    ]
    # M is symmetric: compute the upper triangle, mirror it exactly.
    body = _function(
        "mass_matrix",
        "Mass matrix M(q), kg and kg m (5x5, symmetric).",
        _matrix_outputs(M, symmetric=True),
        (5, 5),
        False,
    )
    body = body.replace(
        "    return out",
        "    for i in range(5):\n        for j in range(i):\n            out[i, j] = out[j, i]\n    return out",
    )
    parts.append(body)
    parts.append(
        _function(
            "bias",
            "h(q, qd) = Coriolis + dV/dq + damping, generalized forces (5,).",
            [(str(i), eq["h"][i]) for i in range(5)],
            (5,),
            True,
        )
    )
    parts.append(
        _function(
            "potential",
            "Potential energy V(q) in J (gravity on every mass, both springs).",
            [("", eq["V"])],
            None,
            False,
        )
    )
    parts.append(_function("kinetic", "Kinetic energy T(q, qd) in J.", [("", eq["T"])], None, True))
    parts.append(_function("jac_a", "Jacobian of foot a's position (2x5).", _matrix_outputs(eq["Ja"]), (2, 5), False))
    parts.append(
        _function(
            "jdot_qd_a", "J_a'(q, qd) qd, m/s^2 (2,).", [(str(i), eq["jdot_qd_a"][i]) for i in range(2)], (2,), True
        )
    )
    parts.append(
        _function(
            "dmass_dq",
            "dM/dq_k stacked as out[k, i, j] (5x5x5).",
            [(f"{k}, {i}, {j}", eq["dM_dq"][k][i, j]) for k in range(5) for i in range(5) for j in range(5)],
            (5, 5, 5),
            False,
        )
    )
    parts.append(_function("dbias_dq", "dh/dq (5x5).", _matrix_outputs(eq["dh_dq"]), (5, 5), True))
    parts.append(_function("dbias_dqd", "dh/dqd (5x5).", _matrix_outputs(eq["dh_dqd"]), (5, 5), True))
    parts.append(
        _function(
            "djac_a_dq",
            "dJ_a/dq_k stacked as out[k, r, j] (5x2x5).",
            [(f"{k}, {r}, {j}", eq["dJa_dq"][k][r, j]) for k in range(5) for r in range(2) for j in range(5)],
            (5, 2, 5),
            False,
        )
    )
    parts.append(_function("djdot_qd_a_dq", "d(J_a' qd)/dq (2x5).", _matrix_outputs(eq["djdot_dq"]), (2, 5), True))
    parts.append(_function("djdot_qd_a_dqd", "d(J_a' qd)/dqd (2x5).", _matrix_outputs(eq["djdot_dqd"]), (2, 5), True))
    for name in REDUCED_PHASES:
        parts.append(_reduced_function(model, name))
        parts.append(_reduced_function(model, name.replace("_accel", "_dir"), directional=True))
    return "\n\n".join(parts)


class _PhaseSpec(TypedDict):
    free: tuple[int, ...]  # the free coordinates (q indices)
    rows: tuple[int, ...]  # the pinned coordinates (q indices), whose constraint forces are reported
    chain: bool  # double support: foot a's constraint rows J_a solved with the free block


# Phases reduced to their free coordinates (q indices). Foot b is pinned in every phase and L1 too when
# clutched; the pinned coordinates' accelerations are zero in the KKT solution for any state (their constraint
# rows have no velocity term), so the reduced equations equal the full KKT solve for every state, not only
# for consistent rates. Double support is one closed chain: foot a's two constraint rows J_a are kept and
# solved with the free block (Schur complement, 2x2), which again equals the KKT solve for any state.
REDUCED_PHASES: dict[str, _PhaseSpec] = {
    "dlsp_accel": {"free": (2, 3, 4), "rows": (0, 1), "chain": True},
    "slsp_free_accel": {"free": (2, 3, 4), "rows": (0, 1), "chain": False},
    "slsp_clutched_accel": {"free": (2, 4), "rows": (0, 1, 3), "chain": False},
}


def _solve_lines(nf: int, rhs: str, out: str, tmp: str, indent: str) -> list[str]:
    """M_ff x = rhs with the Cholesky factors l (written out): rhs{a} -> out{a}, through tmp{a}."""
    lines = []
    for a in range(nf):
        acc = f"{rhs}{a}" + "".join(f" - l{a}{k}*{tmp}{k}" for k in range(a))
        lines.append(f"{indent}{tmp}{a} = ({acc}) / l{a}{a}")
    for a in reversed(range(nf)):
        acc = f"{tmp}{a}" + "".join(f" - l{k}{a}*{out}{k}" for k in range(a + 1, nf))
        lines.append(f"{indent}{out}{a} = ({acc}) / l{a}{a}")
    return lines


def _reduced_function(model: str, name: str, directional: bool = False) -> str:
    """q'' and the constraint forces of one phase in its free coordinates f:
    M_ff f'' = -h_f + J_f^T lambda_a (Cholesky, written out; in double support with J_f f'' = -J_a' q',
    lambda_a from the 2x2 Schur complement), lambda_r = (M f'' + h)_r - (J_a^T lambda_a)_r for the pinned rows
    r. Only the entries needed are generated, with common subexpressions shared and the angles theta + j pi/4
    expanded in sin(theta), cos(theta). With directional=True also the derivative of q'' along tangent
    columns V (the variational equations): the same system differentiated, solved with the same factors."""
    eq = equations(model)
    M, h, Ja, jd = eq["M"], eq["h"], eq["Ja"], eq["jdot_qd_a"]
    spec = REDUCED_PHASES[name.replace("_dir", "_accel")]
    free, rows, chain = spec["free"], spec["rows"], spec["chain"]
    nf = len(free)
    outs: list[tuple[str, sp.Expr]] = []
    for a, i in enumerate(free):
        for b, j in enumerate(free):
            if b >= a:
                outs.append((f"m{a}{b}", M[i, j]))
    outs += [(f"r{a}", -h[i]) for a, i in enumerate(free)]
    for c, r in enumerate(rows):
        outs += [(f"b{c}{a}", M[r, j]) for a, j in enumerate(free)]
        outs.append((f"hb{c}", h[r]))
    if chain:
        for r in range(2):
            outs += [(f"j{r}{a}", Ja[r, i]) for a, i in enumerate(free)]
            outs += [(f"jb{r}{c}", Ja[r, i]) for c, i in enumerate(rows)]
            outs.append((f"jd{r}", jd[r]))
    positions = (2, 3, 4)  # x_b, y_b never enter M, h, J_a or J_a' q' (translation invariance)
    for k in (0, 1):
        assert all(sp.diff(e, q_syms[k]) == 0 for _, e in outs), "x_b or y_b enters the reduced equations"
    if directional:
        for k in positions:
            for a, i in enumerate(free):
                for b, j in enumerate(free):
                    if b >= a:
                        outs.append((f"dm{a}{b}_{k}", M[i, j].diff(q_syms[k])))
            outs += [(f"dr{a}_q{k}", -h[i].diff(q_syms[k])) for a, i in enumerate(free)]
            if chain:
                for r in range(2):
                    outs += [(f"dj{r}{a}_{k}", Ja[r, i].diff(q_syms[k])) for a, i in enumerate(free)]
                    outs.append((f"djd{r}_q{k}", jd[r].diff(q_syms[k])))
        for k in range(5):
            outs += [(f"dr{a}_v{k}", -h[i].diff(qd_syms[k])) for a, i in enumerate(free)]
            if chain:
                outs += [(f"djd{r}_v{k}", jd[r].diff(qd_syms[k])) for r in range(2)]
    th = q_syms[2]
    outs = [(label, sp.expand_trig(e) if e.has(th) else e) for label, e in outs]
    exprs = [e for _, e in outs]
    replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t"), optimizations="basic")
    used = set().union(*(e.free_symbols for e in exprs))
    phase_name = name.replace("_accel", "").replace("_dir", "")
    nl = len(rows) + (2 if chain else 0)
    if directional:
        lines = [
            f"def {name}(q, qd, p, qdd, lam, V, dqdd):",
            f'    """As {phase_name}_accel, and dqdd[:, c] = (dq\'\'/dy) V[:, c] for the columns of V (10 x n):'
            '\n    exact for any state and tangent (x_b, y_b do not enter M or dh)."""',
        ]
    else:
        lines = [
            f"def {name}(q, qd, p, qdd, lam):",
            f'    """q\'\' (5,) and lambda ({nl},) of {phase_name} written into qdd and lam, '
            "from the phase's free coordinates;\n    False if the free block of M is not positive "
            "definite" + (" or the chain's constraints are singular" if chain else "") + '."""',
        ]
    lines += [ln for ln in _unpack(True, True) if ln.split("=")[0].strip() in {str(x) for x in used}]
    for sym, e in replacements:
        lines.append(f"    {sym} = {_fmt(e)}")
    for (label, _), e in zip(outs, reduced, strict=True):
        lines.append(f"    {label} = {_fmt(e)}")
    # Cholesky M_ff = L L^T, written out
    for a in range(nf):
        for b in range(a + 1):
            acc = f"m{b}{a}" + "".join(f" - l{a}{k}*l{b}{k}" for k in range(b))
            if a == b:
                lines.append(f"    d{a} = {acc}")
                lines.append(f"    if not d{a} > 0.0:\n        return False")
                lines.append(f"    l{a}{a} = math.sqrt(d{a})")
            else:
                lines.append(f"    l{a}{b} = ({acc}) / l{b}{b}")
    lines += _solve_lines(nf, "r", "u", "z", "    ")
    if chain:
        # W = M_ff^-1 J_f^T, S = J_f W, lambda_a = S^-1 (-J_a' q' - J_f u), f'' = u + W lambda_a
        for r in range(2):
            lines += _solve_lines(nf, f"j{r}", f"w{r}", f"x{r}", "    ")
        for r in range(2):
            for c in range(2):
                lines.append(f"    s{r}{c} = " + " + ".join(f"j{r}{a}*w{c}{a}" for a in range(nf)))
        lines.append("    det = s00*s11 - s01*s10")
        lines.append("    if not det != 0.0:\n        return False")
        for r in range(2):
            lines.append(f"    c{r} = -jd{r} - " + " - ".join(f"j{r}{a}*u{a}" for a in range(nf)))
        lines.append("    la0 = (c0*s11 - s01*c1) / det")
        lines.append("    la1 = (s00*c1 - s10*c0) / det")
        for a in range(nf):
            lines.append(f"    a{a} = u{a} + w0{a}*la0 + w1{a}*la1")
    else:
        for a in range(nf):
            lines.append(f"    a{a} = u{a}")
    for i in range(5):
        lines.append(f"    qdd[{i}] = {f'a{free.index(i)}' if i in free else '0.0'}")
    for c in range(len(rows)):
        line = f"    lam[{c}] = " + " + ".join(f"b{c}{a}*a{a}" for a in range(nf)) + f" + hb{c}"
        if chain:
            line += f" - jb0{c}*la0 - jb1{c}*la1"
        lines.append(line)
    if chain:
        lines.append(f"    lam[{len(rows)}] = la0")
        lines.append(f"    lam[{len(rows) + 1}] = la1")
    if directional:
        # M_ff da = sum_k V_k (dr/dy_k - dM_ff/dq_k a + dJ_f^T/dq_k lambda_a), and in double support
        # J_f da = -sum_k V_k (d(J_a' q')/dy_k + dJ_f/dq_k a), solved with the same factors, per column of V
        lines.append("    for col in range(V.shape[1]):")
        for k in positions:
            lines.append(f"        v{k} = V[{k}, col]")
        for k in range(5):
            lines.append(f"        vd{k} = V[{5 + k}, col]")
        for a in range(nf):
            terms = []
            for k in positions:
                parts = [f"dr{a}_q{k}"] + [f"dm{min(a, b)}{max(a, b)}_{k}*a{b}" for b in range(nf)]
                inner = " - ".join(parts)
                if chain:
                    inner += f" + dj0{a}_{k}*la0 + dj1{a}_{k}*la1"
                terms.append(f"v{k}*({inner})")
            terms += [f"vd{k}*dr{a}_v{k}" for k in range(5)]
            lines.append(f"        s{a} = " + " + ".join(terms))
        lines += _solve_lines(nf, "s", "du", "y", "        ")
        if chain:
            for r in range(2):
                terms = []
                for k in positions:
                    terms.append(f"v{k}*(djd{r}_q{k} + " + " + ".join(f"dj{r}{b}_{k}*a{b}" for b in range(nf)) + ")")
                terms += [f"vd{k}*djd{r}_v{k}" for k in range(5)]
                lines.append(
                    f"        e{r} = -(" + " + ".join(terms) + ") - " + " - ".join(f"j{r}{a}*du{a}" for a in range(nf))
                )
            lines.append("        m0 = (e0*s11 - s01*e1) / det")
            lines.append("        m1 = (s00*e1 - s10*e0) / det")
            for a in range(nf):
                lines.append(f"        da{a} = du{a} + w0{a}*m0 + w1{a}*m1")
        else:
            for a in range(nf):
                lines.append(f"        da{a} = du{a}")
        for i in range(5):
            lines.append(f"        dqdd[{i}, col] = {f'da{free.index(i)}' if i in free else '0.0'}")
    lines.append("    return True")
    return "\n".join(lines) + "\n"


def write_all(directory: Path = GENERATED_DIR) -> list[Path]:
    """Regenerate every mass model's module; returns the files written."""
    written = []
    for model, module in MODEL_NAMES.items():
        path = directory / f"{module}.py"
        path.write_text(generate_source(model), encoding="utf-8")
        written.append(path)
    return written


if __name__ == "__main__":
    for path in write_all():
        sys.stdout.write(f"wrote {path}\n")
