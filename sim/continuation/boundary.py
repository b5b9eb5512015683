"""Two-parameter continuation of a branch's end: the critical slope as a curve over k (or c, a mass).

The curve is traced directly, by pseudo-arclength continuation of the extended system in
x = (theta+, theta'+, slope, mu), mu the second parameter:
    P(z; slope, mu) - z = 0          (the gait exists)
    g(z; slope, mu) = 0              (it sits on the boundary)
with g one of
- `fold`: det(J - I), J = dP/dz (the VE branches end in folds: an eigenvalue at +1);
- `stall`: exp(-lambda (T - T_STALL)) - 1, T the step period, T_STALL = 1.6 s. The ER branch ends in a stall
  where the period grows without bound (logarithmically, the wheel creeping over the top), so the stall itself
  is no smooth zero of anything the map gives; the level set of a 1.6 s period is a smooth curve some 1e-5 rad
  above it, traced first. Each of its points is then moved down in slope, at its own mu, to the stall itself:
  the fixed point is followed down in slope (Newton from the last one) until it stops existing, and that end
  is bisected to STALL_TOL_RAD = 1e-8 rad (`locate_stall`). The curve's points are the located stalls; the level-set
  points are kept in `BoundaryCurve.level_points`.
Scaled coordinates u = (theta+, theta'+, slope / 0.01, mu / s_mu). dF/dz is the map's exact Jacobian; the
other derivatives are forward differences. Units: rad, rad/s, SI for mu.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rimless.sim.continuation.oracle import PARAMETERS, MapOracle
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.params import WheelParams

T_STALL = 1.6  # s: the step period of the level set traced before the stall is located
STALL_TOL_RAD = 1e-8  # the located stall's bracket in slope
TESTS = ("fold", "stall")


@dataclass
class BoundaryPoint:
    mu: float
    slope_rad: float
    z: np.ndarray
    period_s: float
    eigenvalues: np.ndarray

    @property
    def slope_deg(self) -> float:
        return math.degrees(self.slope_rad)


@dataclass
class BoundaryCurve:
    model: str
    test: str
    parameter: str
    points: list[BoundaryPoint] = field(default_factory=list)
    level_points: list[BoundaryPoint] = field(default_factory=list)  # stall: the T_STALL level set traced
    end_reason: str = ""
    map_evaluations: int = 0
    seconds: float = 0.0

    def slope_at(self, mu: float) -> float:
        """The boundary slope at mu by linear interpolation along the curve (rad); nan outside it."""
        pts = sorted(self.points, key=lambda p: p.mu)
        ms = np.array([p.mu for p in pts])
        if not len(ms) or mu < ms[0] or mu > ms[-1]:
            return math.nan
        return float(np.interp(mu, ms, [p.slope_rad for p in pts]))


class BoundaryContinuation:
    """Trace {P(z) = z, g = 0} in (z, slope, mu) (see module docstring)."""

    def __init__(
        self,
        map_factory: Callable[[WheelParams], Any],
        base: WheelParams,
        model: str,
        parameter: str = "k",
        test: str = "fold",
        *,
        ds: float = 0.05,
        ds_min: float = 1e-4,
        ds_max: float = 0.3,
        tol: float = 1e-10,
        max_points: int = 200,
    ) -> None:
        if test not in TESTS:
            raise ValueError(f"unknown boundary test {test!r}; known: {', '.join(TESTS)}")
        self.slope = MapOracle(map_factory, base, "slope", model)
        self.field, self.mu_scale, self.unit = PARAMETERS[parameter]
        self.base, self.model, self.parameter, self.test = base, model, parameter, test
        self.ds, self.ds_min, self.ds_max, self.tol, self.max_points = ds, ds_min, ds_max, tol, max_points
        self.evaluations = 0

    # the system ---------------------------------------------------------------------------------------
    def _eval(self, u: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, float, np.ndarray | None]:
        slope = u[2] * PARAMETERS["slope"][1]
        mu = u[3] * self.mu_scale
        try:
            params = self.base.replace(**{"slope_rad": float(slope), self.field: float(mu)})
        except ValueError as err:
            raise StepFailure(FailureReason.NO_CONVERGENCE, f"parameter out of range: {err}") from None
        self.evaluations += 1
        from rimless.sim import fast

        if self.slope.compiled:
            r = fast.fast_step(params, self.model, u[:2], rtol=self.slope.rtol, atol=self.slope.atol, jacobian=jacobian)
            zn, T, J = r.z_next, r.period_s, r.jacobian
        else:
            from rimless.sim.model.section import section_from_state

            m = self.slope.map_factory(params)
            st = m.step(u[:2])
            zn, T, J = section_from_state(st.y_plus), st.period_s, (m.jacobian(u[:2]) if jacobian else None)
        if not np.all(np.isfinite(zn)) or not math.isfinite(T):
            raise StepFailure(FailureReason.INTEGRATION, "non-finite map value")
        return zn, T, J

    def _G(self, u: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        zn, T, J = self._eval(u, jacobian=True)
        assert J is not None
        if self.test == "fold":
            g = float(np.linalg.det(J - np.eye(2)))
        else:
            # exp(-lambda T) with lambda = sqrt(g / L0), the inverted pendulum's rate at the top: about linear in
            # the distance to the stall, where T itself diverges like its logarithm
            lam = math.sqrt(self.base.gravity_m_s2 / self.base.leg_length_m)
            g = math.expm1(-lam * (T - T_STALL))
        return np.array([zn[0] - u[0], zn[1] - u[1], g]), T, J

    def _DG(self, u: np.ndarray, G0: np.ndarray, J: np.ndarray) -> np.ndarray:
        """3x4 Jacobian: exact dF/dz, forward differences for the rest (steps in scaled units)."""
        D = np.zeros((3, 4))
        D[:2, :2] = J - np.eye(2)
        for j in range(4):
            if j < 2:
                h = 1e-6
            else:
                h = 1e-6 * max(1.0, abs(u[j]))
            up = u.copy()
            up[j] += h
            Gp, _, _ = self._G(up)
            col = (Gp - G0) / h
            if j < 2:
                D[2, j] = col[2]
            else:
                D[:, j] = col
        return D

    def _correct(
        self, u_pred: np.ndarray, t: np.ndarray | None, fix: int | None = None, max_iter: int = 10
    ) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
        """Newton on [G(u) = 0, t . (u - u_pred) = 0] (or u[fix] fixed); returns (u, period, J, DG)."""
        u = u_pred.copy()
        G, T, J = self._G(u)
        for _ in range(max_iter):
            D = self._DG(u, G, J)
            if np.max(np.abs(G[:2])) <= self.tol and abs(G[2]) <= 1e-9:
                return u, T, J, D
            row = np.zeros(4)
            if fix is not None:
                row[fix] = 1.0
                last = 0.0
            else:
                assert t is not None
                row = t
                last = float(t @ (u - u_pred))
            A = np.vstack((D, row))
            try:
                du = np.linalg.solve(A, -np.concatenate((G, [last])))
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(du)):
                break
            lam = 1.0
            while True:  # damped: a full step may cross into the region where the map fails
                try:
                    G, T, J = self._G(u + lam * du)
                    break
                except StepFailure:
                    lam *= 0.5
                    if lam < 1e-3:
                        raise
            u = u + lam * du
        raise StepFailure(FailureReason.NO_CONVERGENCE, "the boundary corrector did not converge")

    def fixed_point_at(
        self, z0: np.ndarray, slope: float, mu: float, max_iter: int = 15, min_lam: float = 1e-3
    ) -> tuple[np.ndarray, float, np.ndarray]:
        """(z, period_s, J) of the fixed point at (slope, mu) by damped Newton from z0 (step factors down to
        min_lam); raises StepFailure."""
        sc = PARAMETERS["slope"][1]
        u = np.array([z0[0], z0[1], slope / sc, mu / self.mu_scale])
        zn, T, J = self._eval(u)
        assert J is not None
        f = zn - u[:2]
        res = float(np.max(np.abs(f)))
        for _ in range(max_iter):
            if res <= self.tol:
                return u[:2].copy(), T, J
            try:
                dz = -np.linalg.solve(J - np.eye(2), f)
            except np.linalg.LinAlgError:
                break
            lam = 1.0
            while lam >= min_lam:
                trial = u.copy()
                trial[:2] += lam * dz
                try:
                    zn2, T2, J2 = self._eval(trial)
                    assert J2 is not None
                    f2 = zn2 - trial[:2]
                    if float(np.max(np.abs(f2))) < res:
                        break
                except StepFailure:
                    pass
                lam *= 0.5
            else:
                break
            u, f, T, J = trial, f2, T2, J2
            res = float(np.max(np.abs(f)))
        raise StepFailure(
            FailureReason.NO_CONVERGENCE, f"no fixed point at slope {slope:.10g} rad (residual {res:.3g})"
        )

    def locate_stall(
        self, pt: BoundaryPoint, tol: float = STALL_TOL_RAD, offset_hint: float | None = None, hint_width: float = 0.05
    ) -> BoundaryPoint:
        """The stall at pt.mu: follow the fixed point of pt down in slope (steps doubling from 2e-6 rad) until it
        stops existing, then bisect that end to `tol` in slope; returns the last slope where it exists.
        offset_hint: the expected distance of the stall below pt (rad; e.g. from the neighbouring point), tried
        first as a bracket of +-hint_width (relative)."""

        def solve(z0: np.ndarray, slope: float) -> tuple[np.ndarray, float, np.ndarray]:
            # from a fixed point a few 1e-6 rad away Newton converges in 2-3 iterations where a gait exists;
            # where none does it is cut short
            return self.fixed_point_at(z0, slope, pt.mu, max_iter=8, min_lam=0.1)

        z, T, J = self.fixed_point_at(pt.z, pt.slope_rad, pt.mu)
        hi = pt.slope_rad
        d = 2e-6
        lo = None
        if offset_hint is not None and offset_hint > 0:
            try:
                z2, T2, J2 = solve(z, hi - (1.0 - hint_width) * offset_hint)
                try:
                    solve(z2, hi - (1.0 + hint_width) * offset_hint)
                except StepFailure:
                    z, T, J = z2, T2, J2
                    lo, hi = hi - (1.0 + hint_width) * offset_hint, hi - (1.0 - hint_width) * offset_hint
            except StepFailure:
                pass
        while lo is None:
            try:
                z, T, J = solve(z, hi - d)
                hi -= d
                d *= 2.0
            except StepFailure:
                lo = hi - d
            if d > 0.01:
                raise StepFailure(FailureReason.NO_CONVERGENCE, f"no stall within 0.01 rad below {pt.slope_rad} rad")
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            try:
                z, T, J = solve(z, mid)
                hi = mid
            except StepFailure:
                lo = mid
        return BoundaryPoint(pt.mu, hi, z, T, np.linalg.eigvals(J))

    @staticmethod
    def _tangent(D: np.ndarray, previous: np.ndarray) -> np.ndarray:
        _, _, vt = np.linalg.svd(D)
        t = vt[-1]
        return t if float(t @ previous) >= 0 else -t

    def trace(
        self,
        z0: np.ndarray,
        slope0: float,
        *,
        mu_min: float,
        mu_max: float,
        progress: Callable[[BoundaryPoint], None] | None = None,
    ) -> BoundaryCurve:
        """From a point near the boundary at the base mu (z0, slope0, e.g. a located one-parameter end), trace
        the curve both ways until mu leaves [mu_min, mu_max] or the curve ends."""
        t0 = time.perf_counter()
        sc = PARAMETERS["slope"][1]
        mu0 = float(getattr(self.base, self.field))
        u0 = np.array([z0[0], z0[1], slope0 / sc, mu0 / self.mu_scale])
        u, T, J, D = self._correct(u0, None, fix=3)
        curve = BoundaryCurve(self.model, self.test, self.parameter)
        pieces = []
        for direction in (+1.0, -1.0):
            t = self._tangent(D, np.array([0, 0, 0, direction]))
            pts: list[BoundaryPoint] = []
            uu, tt, ds = u.copy(), t, self.ds
            reason = ""
            while len(pts) < self.max_points:
                try:
                    un, Tn, Jn, Dn = self._correct(uu + ds * tt, tt)
                except StepFailure:
                    if ds > self.ds_min:
                        ds *= 0.5
                        continue
                    reason = "the curve ends (the corrector fails)"
                    break
                tn = self._tangent(Dn, tt)
                if float(tn @ tt) < 0.9 and ds > 2 * self.ds_min:
                    ds *= 0.5
                    continue
                uu, tt = un, tn
                pt = BoundaryPoint(
                    float(un[3] * self.mu_scale), float(un[2] * sc), un[:2].copy(), Tn, np.linalg.eigvals(Jn)
                )
                pts.append(pt)
                if progress:
                    progress(pt)
                ds = min(ds * 1.5, self.ds_max)
                if not mu_min <= pt.mu <= mu_max:
                    reason = "parameter range"
                    break
            pieces.append((pts, reason))
        first = BoundaryPoint(mu0, float(u[2] * sc), u[:2].copy(), T, np.linalg.eigvals(J))
        curve.points = list(reversed(pieces[1][0])) + [first] + pieces[0][0]
        curve.end_reason = "; ".join(r for _, r in pieces if r)
        if self.test == "stall":
            curve.level_points = curve.points
            # the stall's distance below the level set changes slowly along the curve (about 1 % per point):
            # extrapolated from the previous two points it brackets the next one to +-0.5 %
            located: list[BoundaryPoint] = []
            offsets: list[tuple[float, float]] = []
            for pt in curve.points:
                hint, width = None, 0.05
                if len(offsets) >= 2:
                    (m1, o1), (m2, o2) = offsets[-2], offsets[-1]
                    hint = o2 + (o2 - o1) * (pt.mu - m2) / (m2 - m1) if m2 != m1 else o2
                    width = 0.005
                elif offsets:
                    hint = offsets[-1][1]
                try:
                    at = self.locate_stall(pt, offset_hint=hint, hint_width=width)
                except StepFailure:
                    continue
                offsets.append((pt.mu, pt.slope_rad - at.slope_rad))
                located.append(at)
            curve.points = located
        curve.map_evaluations = self.evaluations
        curve.seconds = time.perf_counter() - t0
        return curve


def start_on_boundary(
    map_factory: Callable[[WheelParams], Any], base: WheelParams, model: str, z_guess: np.ndarray, test: str
) -> tuple[np.ndarray, float]:
    """(z, slope) near the boundary at the base parameters: the first fold of the branch through z_guess
    (continued down in slope), or for a stall its first point whose period reaches 0.8 T_STALL."""
    from rimless.sim.continuation.arclength import FOLD, ArclengthContinuation

    cont = ArclengthContinuation(map_factory, base, model, "slope")
    if test == "fold":
        br = cont.trace(z_guess, direction=-1.0, stop=lambda pt: False, stop_at_first_loss=True)
        sp = next((s for s in br.special if s.kind == FOLD), None)
        if sp is None:
            raise StepFailure(FailureReason.NO_CONVERGENCE, f"the branch does not end in a fold ({br.end_detail})")
        return sp.point.z, sp.p
    br = cont.trace(z_guess, direction=-1.0, stop=lambda pt: pt.period_s >= 0.8 * T_STALL, stop_at_first_loss=True)
    pt = br.points[-1]
    if pt.period_s < 0.5 * T_STALL:
        raise StepFailure(FailureReason.NO_CONVERGENCE, f"the branch does not end in a stall ({br.end_detail})")
    return pt.z, pt.p


def solve_at(bc: BoundaryContinuation, curve: BoundaryCurve, mu: float) -> BoundaryPoint:
    """The boundary point at exactly mu, corrected from the nearest traced point (a stall: the level set's
    point, then the located stall)."""
    near = min(curve.level_points or curve.points, key=lambda p: abs(p.mu - mu))
    sc = PARAMETERS["slope"][1]
    u0 = np.array([near.z[0], near.z[1], near.slope_rad / sc, mu / bc.mu_scale])
    u, T, J, _ = bc._correct(u0, None, fix=3)
    pt = BoundaryPoint(mu, float(u[2] * sc), u[:2].copy(), T, np.linalg.eigvals(J))
    return bc.locate_stall(pt) if bc.test == "stall" else pt
