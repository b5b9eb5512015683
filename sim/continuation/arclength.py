"""Pseudo-arclength continuation of Poincaré fixed points in one parameter, with special points.

The branch is the curve {(z, p): P(z; p) - z = 0} in R^3, z = (theta+ rad, theta'+ rad/s) on the
post-impact section and p one wheel parameter (slope, k, c, a mass). It is followed by a tangent predictor
and a Newton corrector on the pseudo-arclength equation, in scaled coordinates u = (theta+, theta'+, p / s_p)
(s_p: the parameter's typical size, PARAMETERS), so it goes around folds onto the unstable side.

Test functions, evaluated at every accepted point from the map Jacobian J = dP/dz (2x2):
- fold: det(J - I) = (l1 - 1)(l2 - 1) changes sign where an eigenvalue passes +1;
- period doubling: det(J + I) = (l1 + 1)(l2 + 1), an eigenvalue through -1;
- Neimark-Sacker: det(J) - 1 with a complex pair (|l|^2 = det J), the pair through the unit circle;
- validity and stall, from the recorded step: the smallest stance normal force in single support (N), the
  smallest normal impact impulse (N s) and the smallest theta' in single support (rad/s).
A sign change between two accepted points is bracketed and bisected in arclength (each trial point on the
branch by the same corrector) until the bracket is below `locate_tol` in u. Where the corrector fails (the
map fails: stall, lift-off, negative impulse), the branch end is bisected between the last good point and
the failing step, and its reason is read off the test functions at the located end, not off the failure
message of one trial point.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rimless.sim.continuation.contact import ContactFacts, contact_facts
from rimless.sim.continuation.oracle import MapOracle
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.params import WheelParams

FOLD, PERIOD_DOUBLING, NEIMARK_SACKER = "fold", "period-doubling", "neimark-sacker"
STANCE_FORCE, IMPULSE, STALL = "stance-force", "impulse", "stall"
#: Where Newton fails at a branch end whose last valid point has a single-support stance force this close to
#: zero (N), the end is the stance foot's lift-off: past it the map's located lift-off guard rejects the step.
STANCE_FORCE_END_TOL_N = 0.05
EIGEN_TESTS = (FOLD, PERIOD_DOUBLING, NEIMARK_SACKER)
VALIDITY_TESTS = (STANCE_FORCE, IMPULSE, STALL)


def eigen_tests(J: np.ndarray) -> dict[str, float]:
    """The bifurcation test functions of a 2x2 map Jacobian (see module docstring)."""
    eye = np.eye(2)
    return {
        FOLD: float(np.linalg.det(J - eye)),
        PERIOD_DOUBLING: float(np.linalg.det(J + eye)),
        NEIMARK_SACKER: float(np.linalg.det(J)) - 1.0,
    }


def _complex_pair(J: np.ndarray) -> bool:
    tr, det = float(np.trace(J)), float(np.linalg.det(J))
    return tr * tr - 4.0 * det < 0.0


@dataclass
class BranchPoint:
    """One accepted point of a traced branch (SI; `p` in the continued parameter's unit)."""

    p: float
    z: np.ndarray
    jacobian: np.ndarray
    period_s: float
    arclength: float
    tests: dict[str, float]
    facts: ContactFacts | None = None
    contact_valid: bool | None = None  # unilateral contact holds (None: not known at this point)

    @property
    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.jacobian)

    @property
    def max_abs_eigenvalue(self) -> float:
        return float(np.max(np.abs(self.eigenvalues)))

    @property
    def stable(self) -> bool:
        return self.max_abs_eigenvalue < 1.0


@dataclass
class SpecialPoint:
    """A located special point: kind, where, and the test function's values on both sides of the bracket."""

    kind: str  # fold | period-doubling | neimark-sacker | stance-force | impulse | stall | end
    point: BranchPoint  # the bracket's end on the side the branch came from
    bracket_p: tuple[float, float]
    bracket_values: tuple[float, float]  # the test function at both ends of the final bracket
    detail: str

    @property
    def p(self) -> float:
        return self.point.p


@dataclass
class Branch:
    """A traced branch: points in the order followed, special points, and why it ended."""

    parameter: str
    model: str
    base: WheelParams
    points: list[BranchPoint] = field(default_factory=list)
    special: list[SpecialPoint] = field(default_factory=list)
    end_reason: str = ""
    end_detail: str = ""
    map_evaluations: int = 0
    seconds: float = 0.0

    def first_loss(self) -> SpecialPoint | None:
        """The first special point after which the gait is no longer stable and valid (fold, period doubling,
        Neimark-Sacker, loss of validity, stall or the branch end), in the order followed."""
        for sp in self.special:
            if sp.kind in EIGEN_TESTS:
                return sp
            if sp.kind in VALIDITY_TESTS or sp.kind == "end":
                return sp
        return None


@dataclass
class _State:
    u: np.ndarray  # (theta+, theta'+, p / scale)
    J: np.ndarray
    period_s: float
    f: np.ndarray  # P(z) - z at u


class ArclengthContinuation:
    """Follow one branch (see module docstring). Units: ds in the scaled norm of u."""

    def __init__(
        self,
        map_factory: Callable[[WheelParams], Any],
        base: WheelParams,
        model: str,
        parameter: str = "slope",
        *,
        ds: float = 0.02,
        ds_min: float = 1e-6,
        ds_max: float = 0.2,
        tol: float = 1e-10,
        locate_tol: float = 1e-7,
        end_p_tol: float = 1e-9,
        facts_every: int = 10,
        facts_dt: float = 1e-3,
        max_points: int = 400,
    ) -> None:
        self.oracle = MapOracle(map_factory, base, parameter, model)
        self.parameter = parameter
        self.model = model
        self.ds, self.ds_min, self.ds_max = ds, ds_min, ds_max
        self.tol, self.locate_tol = tol, locate_tol
        self.end_p_tol = end_p_tol  # a branch end (map failure) is bisected until the bracket in p is below this
        self.facts_every = max(1, facts_every)
        self.facts_dt = facts_dt
        self._period_hint = 0.0
        self._Fp_here = np.zeros(2)
        self.max_points = max_points

    def _newton(self, z0: np.ndarray, p: float, max_iter: int = 30) -> _State:
        """The fixed point at a fixed parameter from z0 (Newton with step halving); raises NoFixedPoint."""
        from rimless.sim.step.poincare import NoFixedPoint

        z = z0.copy()
        try:
            zn, period, J = self.oracle.evaluate(z, p, jacobian=True)
        except StepFailure as err:
            raise NoFixedPoint(f"the map fails at the start guess {z.tolist()}: {err}", err) from None
        assert J is not None  # jacobian=True
        f = zn - z
        res = float(np.max(np.abs(f)))
        for _ in range(max_iter):
            if res <= self.tol:
                return _State(np.array([z[0], z[1], p / self.oracle.scale]), J, period, f)
            dz = -np.linalg.solve(J - np.eye(2), f)
            lam = 1.0
            while lam >= 1e-4:
                try:
                    zn2, period2, J2 = self.oracle.evaluate(z + lam * dz, p, jacobian=True)
                    assert J2 is not None  # jacobian=True
                    f2 = zn2 - (z + lam * dz)
                    if float(np.max(np.abs(f2))) < res:
                        break
                except StepFailure:
                    pass
                lam *= 0.5
            else:
                break
            z, f, J, period = z + lam * dz, f2, J2, period2
            res = float(np.max(np.abs(f)))
        raise NoFixedPoint(f"no fixed point at the start from {z0.tolist()} (residual {res:.3g})")

    # -- corrector -------------------------------------------------------------------------------------
    def _F(self, u: np.ndarray, *, jacobian: bool) -> tuple[np.ndarray, float, np.ndarray | None]:
        p = u[2] * self.oracle.scale
        zn, period, J = self.oracle.evaluate(u[:2], p, jacobian=jacobian)
        return zn - u[:2], period, J

    def _Fp(self, u: np.ndarray, f0: np.ndarray) -> np.ndarray:
        """dF/du_p by a forward difference in the scaled parameter (F at u already known)."""
        h = 1e-6 * max(1.0, abs(u[2]))
        up = u.copy()
        up[2] += h
        f1, _, _ = self._F(up, jacobian=False)
        return (f1 - f0) / h

    def _correct(self, u_pred: np.ndarray, tangent: np.ndarray, Fp: np.ndarray, max_iter: int = 8) -> _State:
        """Newton on [F(u) = 0, tangent . (u - u_pred) = 0] with the exact dF/dz and the parameter column Fp
        of the last accepted point (a chord in that one column); raises StepFailure when it does not converge."""
        u = u_pred.copy()
        res_prev = math.inf
        for _ in range(max_iter):
            f, period, J = self._F(u, jacobian=True)
            assert J is not None
            res = float(np.max(np.abs(f)))
            if res <= self.tol:
                return _State(u, J, period, f)
            if res > 4 * res_prev and res_prev < 1e-3:
                break  # diverging
            res_prev = res
            A = np.zeros((3, 3))
            A[:2, :2] = J - np.eye(2)
            A[:2, 2] = Fp
            A[2] = tangent
            rhs = -np.concatenate((f, [float(tangent @ (u - u_pred))]))
            try:
                du = np.linalg.solve(A, rhs)
            except np.linalg.LinAlgError:
                break
            u = u + du
        raise StepFailure(
            FailureReason.NO_CONVERGENCE, f"the pseudo-arclength corrector did not converge (residual {res_prev:.3g})"
        )

    def _tangent(self, s: _State, previous: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """(unit null vector of [J - I, F_p] (the cross product of its two rows), oriented like `previous`;
        F_p)."""
        A = np.zeros((2, 3))
        A[:, :2] = s.J - np.eye(2)
        Fp = self._Fp(s.u, s.f)
        A[:, 2] = Fp
        t = np.cross(A[0], A[1])
        t /= np.linalg.norm(t)
        if previous is not None and float(t @ previous) < 0:
            t = -t
        return t, Fp

    # -- points ---------------------------------------------------------------------------------------
    def _point(self, s: _State, arclength: float, with_facts: bool) -> BranchPoint:
        p = float(s.u[2] * self.oracle.scale)
        self._period_hint = s.period_s
        facts = None
        tests = eigen_tests(s.J)
        valid: bool | None = None if self.oracle.bilateral else True  # the unilateral map accepted the step
        if with_facts:
            facts = self._facts(s.u[:2], p)
            if facts is not None:
                tests[STANCE_FORCE] = facts.min_stance_force_single_support_N
                tests[IMPULSE] = facts.min_impulse_N_s
                tests[STALL] = facts.min_theta_dot_single_support_rad_s
                valid = facts.contact_valid
        elif self.oracle.bilateral and self.oracle.compiled:
            # the stance foot held: the compiled map's own record of the contact at every point (about one map
            # evaluation), so the stance force's sign changes are bracketed point to point
            from rimless.sim import fast

            try:
                c = fast.fast_step(
                    self.oracle.params(p),
                    self.model,
                    s.u[:2],
                    rtol=self.oracle.rtol,
                    atol=self.oracle.atol,
                    bilateral=True,
                ).contact
                assert c is not None  # bilateral=True records it
                tests[STANCE_FORCE] = c.min_stance_force_N
                tests[IMPULSE] = c.min_impulse_N_s
                valid = c.unilateral_valid
            except StepFailure:
                pass
        return BranchPoint(p, s.u[:2].copy(), s.J.copy(), s.period_s, arclength, tests, facts, valid)

    def _facts(self, z: np.ndarray, p: float) -> ContactFacts | None:
        try:
            pmap = self.oracle.pmap(p)
            # about 400 samples per step whatever its period (the period grows without bound near a stall)
            period = self._period_hint if self._period_hint > 0 else 0.4
            return contact_facts(pmap, z, max(self.facts_dt, period / 400))
        except StepFailure:
            return None

    # -- main loop ------------------------------------------------------------------------------------
    def trace(
        self,
        z0: np.ndarray,
        *,
        direction: float = -1.0,
        p_min: float | None = None,
        p_max: float | None = None,
        stop_at_first_loss: bool = False,
        stop: Callable[[BranchPoint], bool] | None = None,
        progress: Callable[[BranchPoint], None] | None = None,
        start_facts: ContactFacts | None = None,
    ) -> Branch:
        """Trace the branch through the fixed point near z0 at the base parameter, first moving p in
        `direction` (-1: decreasing). Stops at the branch end (map failure), at p_min/p_max, after
        max_points, at the first loss of stability or validity if asked, or when `stop(point)` is true."""
        t_start = time.perf_counter()
        p0 = float(getattr(self.oracle.base, self.oracle.field))
        branch = Branch(self.parameter, self.model, self.oracle.base)
        s = self._newton(np.asarray(z0, dtype=float), p0)
        t, Fp = self._tangent(s, np.array([0.0, 0.0, direction]))
        cur = self._point(s, 0.0, start_facts is None)
        if start_facts is not None:
            cur.facts = start_facts
            cur.contact_valid = start_facts.contact_valid
            cur.tests.update(
                {
                    STANCE_FORCE: start_facts.min_stance_force_single_support_N,
                    IMPULSE: start_facts.min_impulse_N_s,
                    STALL: start_facts.min_theta_dot_single_support_rad_s,
                }
            )
        branch.points.append(cur)
        ds = self.ds
        end_reason, end_detail = "", ""
        while True:
            if len(branch.points) >= self.max_points:
                end_reason, end_detail = "max-points", f"stopped after {self.max_points} points"
                break
            try:
                nxt = self._correct(s.u + ds * t, t, Fp)
                t_new, Fp_new = self._tangent(nxt, t)
                # a step that turns the tangent too sharply is too long
                if float(t_new @ t) < 0.9 and ds > self.ds_min * 4:
                    ds *= 0.5
                    continue
            except StepFailure:
                if ds > self.ds_min * 1.01:
                    ds = max(ds * 0.5, self.ds_min)
                    continue
                self._Fp_here = Fp
                sp = self._locate_end(s, t, ds, cur, branch)
                branch.special.append(sp)
                end_reason, end_detail = sp.detail.split(":", 1)[0], sp.detail
                break
            with_facts = (len(branch.points) % self.facts_every) == 0
            pt = self._point(nxt, cur.arclength + ds, with_facts)
            self._Fp_here = Fp
            for sp in self._special_between(s, t, cur, pt, ds):
                branch.special.append(sp)
            branch.points.append(pt)
            if progress:
                progress(pt)
            s, t, cur, Fp = nxt, t_new, pt, Fp_new
            ds = min(ds * 1.4, self.ds_max)
            if stop_at_first_loss and branch.first_loss() is not None:
                end_reason, end_detail = "first-loss", "stopped at the first loss of stability or validity"
                break
            if (p_min is not None and pt.p < p_min) or (p_max is not None and pt.p > p_max):
                end_reason, end_detail = "parameter-range", f"{self.parameter} left [{p_min}, {p_max}]"
                break
            if stop is not None and stop(pt):
                end_reason, end_detail = "stop", "the caller's stop condition"
                break
        branch.end_reason, branch.end_detail = end_reason, end_detail
        branch.map_evaluations = self.oracle.evaluations
        branch.seconds = time.perf_counter() - t_start
        return branch

    # -- special points -------------------------------------------------------------------------------
    def _on_branch(self, s: _State, t: np.ndarray, sigma: float) -> _State:
        return self._correct(s.u + sigma * t, t, self._Fp_here)

    def _special_between(
        self, s: _State, t: np.ndarray, a: BranchPoint, b: BranchPoint, ds: float
    ) -> list[SpecialPoint]:
        found = []
        for kind in EIGEN_TESTS + VALIDITY_TESTS:
            va, vb = a.tests.get(kind), b.tests.get(kind)
            if va is None or vb is None or not (va == va and vb == vb):
                continue
            if (va > 0) == (vb > 0):
                continue
            if kind == NEIMARK_SACKER and not (_complex_pair(a.jacobian) or _complex_pair(b.jacobian)):
                continue  # det J = 1 with real eigenvalues (a neutral saddle): not a bifurcation
            sp = self._bisect(kind, s, t, a, b, ds)
            if sp is not None:
                found.append(sp)
        found.sort(key=lambda sp: sp.point.arclength)
        return found

    def _test_value(self, kind: str, st: _State) -> tuple[float, BranchPoint]:
        # with the stance foot held, the compiled map records the stance force and impulses at every point
        cheap = self.oracle.bilateral and self.oracle.compiled and kind in (STANCE_FORCE, IMPULSE)
        pt = self._point(st, 0.0, kind in VALIDITY_TESTS and not cheap)
        v = pt.tests.get(kind, math.nan)
        return v, pt

    def _bisect(
        self, kind: str, s: _State, t: np.ndarray, a: BranchPoint, b: BranchPoint, ds: float
    ) -> SpecialPoint | None:
        lo, hi = 0.0, ds
        vlo, vhi = a.tests[kind], b.tests[kind]
        plo, phi = a.p, b.p
        best = a  # the located point: the last one on the side the branch came from (e.g. still stable)
        # the bracket shrinks by regula falsi with the Illinois modification (the test functions are smooth along
        # the branch: a few corrector solves instead of some 20 halvings), each trial kept tol/2 inside the
        # bracket so that a converged estimate closes the bracket to tol from both sides
        fa, fb, side = vlo, vhi, 0
        tol = self.locate_tol
        while hi - lo > tol:
            mid = lo + (hi - lo) * fa / (fa - fb) if fa != fb and fa == fa and fb == fb else 0.5 * (lo + hi)
            mid = min(max(mid, lo + 0.5 * tol), hi - 0.5 * tol)
            try:
                st = self._on_branch(s, t, mid)
            except StepFailure:
                break
            v, pt = self._test_value(kind, st)
            if not v == v:
                break
            pt.arclength = a.arclength + mid
            if (v > 0) == (vlo > 0):
                lo, vlo, plo, fa = mid, v, pt.p, v
                best = pt
                if side == -1:
                    fb *= 0.5
                side = -1
            else:
                hi, vhi, phi, fb = mid, v, pt.p, v
                if side == 1:
                    fa *= 0.5
                side = 1
        if kind in VALIDITY_TESTS and best.facts is None:
            best.facts = self._facts(best.z, best.p)
        detail = _describe(kind, best, self.oracle.unit, self.parameter)
        return SpecialPoint(kind, best, (plo, phi), (vlo, vhi), detail)

    def _locate_end(self, s: _State, t: np.ndarray, ds: float, cur: BranchPoint, branch: Branch) -> SpecialPoint:
        """Bisect between the last accepted point (sigma = 0) and the first failing step (sigma = ds)."""
        lo, hi = 0.0, ds
        good_state, good_pt = s, cur
        last_err: StepFailure | None = None
        p_rate = abs(t[2]) * self.oracle.scale  # parameter change per unit arclength
        while hi - lo > self.locate_tol and (hi - lo) * p_rate > self.end_p_tol:
            mid = 0.5 * (lo + hi)
            try:
                st = self._on_branch(s, t, mid)
            except StepFailure as err:
                hi, last_err = mid, err
                continue
            lo, good_state = mid, st
        good_pt = self._point(good_state, cur.arclength + lo, True)
        # the failing side: what the map says just past the end
        past = self.oracle.params(float((s.u[2] + hi * t[2]) * self.oracle.scale))
        cause = _map_failure(self.oracle, s.u[:2] + hi * t[:2], past)
        kind, detail = _end_reason(good_pt, cause, last_err, self.oracle.unit, self.parameter)
        bad_val = _failing_side_value(kind, cause)
        return SpecialPoint(
            kind,
            good_pt,
            (good_pt.p, float(getattr(past, self.oracle.field))),
            (good_pt.tests.get(kind, math.nan), bad_val),
            detail,
        )


def _map_failure(oracle: MapOracle, z: np.ndarray, params: WheelParams) -> StepFailure | None:
    """The map's own failure at z just past the end (None when the map succeeds there: Newton failed)."""
    try:
        oracle.evaluate(z, float(getattr(params, oracle.field)), jacobian=False)
    except StepFailure as err:
        return err
    return None


def _failing_side_value(kind: str, cause: StepFailure | None) -> float:
    """The test function's value on the failing side: the map's own stance, impulse or stall check failed
    there, i.e. the quantity reached 0 (reported as 0.0); nan when the map did not fail."""
    if kind in VALIDITY_TESTS and cause is not None:
        return 0.0
    return math.nan


def _end_reason(
    pt: BranchPoint, cause: StepFailure | None, newton_err: StepFailure | None, unit: str, parameter: str
) -> tuple[str, str]:
    """Why the branch ends, from the test functions at the located end (model.md section 7)."""
    ev = pt.eigenvalues
    evs = ", ".join(f"{e.real:.5f}{e.imag:+.5f}j" for e in ev)
    where = f"at {parameter} = {pt.p:.9g} {unit} (eigenvalues {evs})"
    f = pt.facts
    reason = cause.reason if cause is not None else None
    if reason == FailureReason.STALL or (f is not None and f.min_theta_dot_single_support_rad_s < 0.05):
        th = f.min_theta_dot_single_support_rad_s if f is not None else math.nan
        return STALL, (
            f"stall: the wheel no longer clears mid-stance (smallest theta' in single support "
            f"{th:.4g} rad/s, period {pt.period_s:.4f} s) {where}"
        )
    near_lift_off = (
        reason is None and f is not None and abs(f.min_stance_force_single_support_N) < STANCE_FORCE_END_TOL_N
    )
    if reason == FailureReason.STANCE_LIFT_OFF or near_lift_off:
        fs = f.min_stance_force_single_support_N if f is not None else math.nan
        return STANCE_FORCE, (
            f"stance-force: the stance foot's normal force in single support falls through 0 "
            f"(last valid minimum {fs:.4g} N) {where}"
        )
    if reason == FailureReason.NEGATIVE_IMPULSE:
        imp = f.min_impulse_N_s if f is not None else math.nan
        return IMPULSE, f"impulse: a normal impact impulse falls through 0 (last {imp:.4g} N s) {where}"
    fold = pt.tests.get(FOLD, math.nan)
    if abs(fold) < 1e-3:
        return FOLD, f"fold: an eigenvalue reaches +1 {where}"
    detail = f"{reason.value if reason else 'solver'}: the map fails past this point"
    if cause is not None:
        detail += f" ({cause})"
    elif newton_err is not None:
        detail += f" ({newton_err})"
    return "end", f"{detail} {where}"


def _describe(kind: str, pt: BranchPoint, unit: str, parameter: str) -> str:
    ev = pt.eigenvalues
    evs = ", ".join(f"{e.real:.6f}{e.imag:+.6f}j" for e in ev)
    where = f"at {parameter} = {pt.p:.9g} {unit}, eigenvalues {evs}"
    f = pt.facts
    if kind == FOLD:
        return f"fold: an eigenvalue passes +1 {where}"
    if kind == PERIOD_DOUBLING:
        return f"period-doubling: an eigenvalue passes -1 {where}"
    if kind == NEIMARK_SACKER:
        return f"neimark-sacker: a complex pair crosses the unit circle (|l| = {abs(ev[0]):.6f}) {where}"
    if kind == STANCE_FORCE:
        return f"stance-force: the single-support stance force changes sign ({f.min_stance_force_single_support_N if f else math.nan:.4g} N) {where}"
    if kind == IMPULSE:
        return f"impulse: a normal impact impulse changes sign {where}"
    return f"stall: the smallest theta' in single support reaches 0 {where}"
