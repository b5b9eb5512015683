"""The Poincaré map on the post-impact section z = (theta+, theta'+), its fixed points and stability.

The map needs only the end state of a step: no trajectory, forces or energies are recorded on this path.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, Self

import numpy as np

from rimless.sim.integrate.reference import Integrator, ScipyIntegrator
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import ALPHA, Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import section_from_state, state_from_section
from rimless.sim.step.hybrid import ClutchPolicy, StepResult, simulate_step

if TYPE_CHECKING:
    from typing_extensions import Unpack

    from rimless.sim.step.hybrid import StepOptions

FIXED_POINT_TOL = 1e-10  # residual |P(z) - z|, rad and rad/s
JACOBIAN_FD_STEP = 1e-4
JACOBIAN_MIN_STEP = 1e-7
JACOBIAN_CURVATURE_TOL = 1e-3  # |forward - backward difference| / (1 + |central|) above which h shrinks


class SectionMap(Protocol):
    """What Newton (solve_fixed_point) and the slope continuation need of a Poincare map: PoincareMap here,
    rimless.sim.step.fast_map.FastPoincareMap on the compiled path."""

    @property
    def params(self) -> WheelParams: ...

    @property
    def model(self) -> str: ...

    def __call__(self, z: np.ndarray) -> np.ndarray: ...

    def jacobian(self, z: np.ndarray) -> np.ndarray: ...

    def step(self, z: np.ndarray, **options: Unpack[StepOptions]) -> StepResult: ...

    def with_params(self, params: WheelParams) -> Self: ...


@dataclass
class PoincareMap:
    """P: z -> z' for one wheel (model 'er' or 've') and parameter set."""

    params: WheelParams
    model: str
    integrator: Integrator = field(default_factory=ScipyIntegrator)
    clutch: ClutchPolicy | None = None
    evaluations: int = 0

    def __post_init__(self) -> None:
        self.mech = Mechanics.of(self.params)

    def step(self, z: np.ndarray, **options: Unpack[StepOptions]) -> StepResult:
        """The full step from section point z (options as for simulate_step)."""
        self.evaluations += 1
        return simulate_step(
            self.mech,
            self.model,
            state_from_section(self.mech, np.asarray(z, dtype=float)),
            self.integrator,
            clutch=self.clutch,
            **options,
        )

    def __call__(self, z: np.ndarray) -> np.ndarray:
        return section_from_state(self.step(z).y_plus)

    def with_params(self, params: WheelParams) -> PoincareMap:
        return PoincareMap(params, self.model, self.integrator, self.clutch)

    def jacobian(self, z: np.ndarray, h: float = JACOBIAN_FD_STEP) -> np.ndarray:
        """dP/dz by central differences, the step scaled to the map's curvature (rad, rad/s).

        Starting from h, each column's forward and backward differences are compared; where they disagree
        by more than JACOBIAN_CURVATURE_TOL (relative) — the map bends sharply, as next to a stall where the
        period grows without bound — or a perturbed step fails, h shrinks tenfold, down to JACOBIAN_MIN_STEP.
        """
        z = np.asarray(z, dtype=float)
        p0 = self(z)
        J = np.empty((2, 2))
        for i in range(2):
            step = h
            while True:
                dz = np.zeros(2)
                dz[i] = step
                try:
                    fwd = (self(z + dz) - p0) / step
                    bwd = (p0 - self(z - dz)) / step
                except StepFailure:
                    if step / 10 < JACOBIAN_MIN_STEP:
                        raise
                    step /= 10
                    continue
                central = 0.5 * (fwd + bwd)
                if (
                    np.max(np.abs(fwd - bwd)) <= JACOBIAN_CURVATURE_TOL * (1.0 + np.max(np.abs(central)))
                    or step / 10 < JACOBIAN_MIN_STEP
                ):
                    break
                step /= 10
            J[:, i] = central
        return J


def default_guess(params: WheelParams, model: str) -> np.ndarray:
    """A post-impact guess near the usual gait: theta+ a little below -alpha/2, theta'+ from the rigid wheel."""
    from rimless.sim.model.rigid import rigid_fixed_point_omega

    omega = rigid_fixed_point_omega(params, consistent=True)
    if not math.isfinite(omega) or omega <= 0:
        omega = 2.5
    return np.array([-ALPHA / 2 - 0.07, max(omega, 1.0) * (1.3 if model == "er" else 1.2)])


@dataclass
class FixedPoint:
    """A period-1 gait: z* with |P(z*) - z*| <= tolerance, and its linear stability."""

    z: np.ndarray
    residual: float
    iterations: int
    jacobian: np.ndarray
    eigenvalues: np.ndarray
    step: StepResult | None  # None when solved with record=False
    jacobian_method: str
    # found under bilateral contact (the stance foot held): it violates unilateral contact; what it violates,
    # rimless.sim.fast.BilateralContact (None for a gait of the unilateral map)
    contact: Any = None

    def __repr__(self) -> str:
        return (
            f"FixedPoint(z=[{self.z[0]:.6g} rad, {self.z[1]:.6g} rad/s], residual {self.residual:.2g}, "
            f"max|eig| {self.max_abs_eigenvalue:.4g}, {'stable' if self.stable else 'unstable'}"
            f"{', bilateral' if self.bilateral else ''}, {self.iterations} Newton iterations)"
        )

    @property
    def bilateral(self) -> bool:
        return self.contact is not None

    @property
    def recorded_step(self) -> StepResult:
        """`step`, for a fixed point solved with record=True (ValueError when it was solved without)."""
        if self.step is None:
            raise ValueError("the fixed point was solved with record=False: no recorded step")
        return self.step

    @property
    def max_abs_eigenvalue(self) -> float:
        return float(np.max(np.abs(self.eigenvalues)))

    @property
    def stable(self) -> bool:
        return self.max_abs_eigenvalue < 1.0


class NoFixedPoint(StepFailure):
    """Newton did not converge; `last_failure` holds the map's failure when that was the cause."""

    def __init__(self, message: str, last_failure: StepFailure | None = None) -> None:
        self.last_failure = last_failure
        super().__init__(FailureReason.NO_CONVERGENCE, message)


class KnownFixedPoint(NoFixedPoint):
    """Newton came within KNOWN_RADIUS of a fixed point it was told is known (find_gaits' scan)."""


KNOWN_RADIUS = 1e-5  # rad, rad/s: well inside Newton's quadratic basin, far below the distance between gaits
NOISE_FACTOR = 10.0
NOISE_ACCEPT_MAX = 1e-6  # never accept a residual above this as noise


def map_noise(pmap: SectionMap, z: np.ndarray, J: np.ndarray, delta: float = 1e-7) -> float:
    """The map's numerical noise at z (rad, rad/s): how far P(z + d) - P(z) departs from J d for tiny
    perturbations d of size delta along each axis and the diagonal (the curvature term, O(delta^2), is far
    below it). Newton cannot push |P(z) - z| below this, whatever its tolerance."""
    z = np.asarray(z, dtype=float)
    try:
        p0 = pmap(z)
        dev = 0.0
        for d in (np.array([delta, 0.0]), np.array([0.0, delta]), np.array([delta, -delta])):
            dev = max(dev, float(np.max(np.abs(pmap(z + d) - p0 - J @ d))))
    except StepFailure:
        return 0.0
    return dev


def solve_fixed_point(
    pmap: SectionMap,
    z_guess: np.ndarray,
    *,
    tol: float = FIXED_POINT_TOL,
    max_iter: int = 30,
    jacobian: Callable[[np.ndarray], np.ndarray] | None = None,
    diagnostics: bool = False,
    strict_contact: bool = False,
    record: bool = True,
    known: list[np.ndarray] | None = None,
) -> FixedPoint:
    """Newton's method on F(z) = P(z) - z with step halving when the map fails or the residual grows.

    Converged when |P(z) - z| <= tol, or, when no step reduces the residual any more, when the residual is
    within NOISE_FACTOR of the map's own noise (map_noise; e.g. very light legs at a loose rtol).
    record=False leaves `step` None (the full recorded step costs more than a Newton iteration).
    known: fixed points already found; an iterate within KNOWN_RADIUS of one raises KnownFixedPoint (Newton
    would converge there)."""
    jac = jacobian or pmap.jacobian
    z = np.asarray(z_guess, dtype=float).copy()
    last_failure: StepFailure | None = None
    try:
        fz = pmap(z) - z
    except StepFailure as err:
        raise NoFixedPoint(f"the map fails at the initial guess {z.tolist()}: {err}", err) from None
    res = float(np.max(np.abs(fz)))
    it = 0
    while res > tol:
        if it >= max_iter:
            raise NoFixedPoint(f"Newton did not converge in {max_iter} iterations (residual {res:.3g})", last_failure)
        it += 1
        try:
            J = jac(z) - np.eye(2)
            dz = -np.linalg.solve(J, fz)
        except (StepFailure, np.linalg.LinAlgError) as err:
            if isinstance(err, StepFailure):
                last_failure = err
            raise NoFixedPoint(f"cannot form the Newton step at z = {z.tolist()}: {err}", last_failure) from None
        lam = 1.0
        break_out = False
        while True:
            z_new = z + lam * dz
            try:
                f_new = pmap(z_new) - z_new
                res_new = float(np.max(np.abs(f_new)))
                if res_new < res or res_new <= tol:
                    break
            except StepFailure as err:
                last_failure = err
            lam *= 0.5
            if lam < 1e-4:
                noise = map_noise(pmap, z, J + np.eye(2))
                if res <= NOISE_FACTOR * noise and res <= NOISE_ACCEPT_MAX:
                    break_out = True
                    break
                msg = f"no Newton step from z = {z.tolist()} reduces the residual {res:.3g}"
                if last_failure is not None:
                    msg += f"; the map fails: {last_failure}"
                raise NoFixedPoint(msg, last_failure)
        if break_out:  # converged to the map's own numerical noise
            break
        z, fz, res = z_new, f_new, res_new
        if known and res > tol and any(float(np.max(np.abs(z - k))) < KNOWN_RADIUS for k in known):
            raise KnownFixedPoint(f"Newton reached a known fixed point near {z.tolist()}")
    J = jac(z)
    step = pmap.step(z, diagnostics=diagnostics, strict_contact=strict_contact) if record else None
    return FixedPoint(
        z=z,
        residual=res,
        iterations=it,
        jacobian=J,
        eigenvalues=np.linalg.eigvals(J),
        step=step,
        jacobian_method=getattr(jac, "method_name", "central-difference"),
    )


_CONTACT_FAILURES = (FailureReason.STANCE_LIFT_OFF, FailureReason.NEGATIVE_IMPULSE)


def _contact_failure(err: StepFailure) -> bool:
    """Did Newton fail because the map met a stance lift-off or a non-positive impulse?"""
    last = getattr(err, "last_failure", None)
    return err.reason in _CONTACT_FAILURES or (last is not None and last.reason in _CONTACT_FAILURES)


def bilateral_map(pmap: Any) -> Any:
    """The same map with the stance foot held (bilateral contact), or None when the map has no such mode
    (the reference PoincareMap, a non-ideal clutch)."""
    if not hasattr(pmap, "bilateral") or not getattr(pmap, "_compiled_ok", lambda: False)():
        return None
    bmap = pmap.with_params(pmap.params)
    bmap.bilateral = True
    return bmap


def bilateral_contact(pmap: Any, z: np.ndarray) -> Any:
    """What the step from z under bilateral contact does that unilateral contact forbids
    (rimless.sim.fast.BilateralContact); raises StepFailure."""
    from rimless.sim.fast import fast_step

    integ = pmap.integrator
    return fast_step(pmap.params, pmap.model, z, rtol=integ.rtol, atol=integ.atol, bilateral=True).contact


def find_gaits(
    pmap: PoincareMap,
    *,
    theta_dot_range: tuple[float, float] = (0.8, 6.0),
    n_guesses: int = 14,
    progress: Callable[[int, int], None] | None = None,
    include_invalid: bool = False,
) -> list[FixedPoint]:
    """Every period-1 gait reachable by Newton from a scan of initial theta'+ (de-duplicated, by period).

    include_invalid (compiled maps): every guess whose Newton run met a stance lift-off or a non-positive
    impulse is solved again with the stance foot held (bilateral contact, `bilateral_map`); a gait found
    so that violates unilateral contact is listed with `contact` set (its violation), one that respects it
    is solved again on the unilateral map and listed as an ordinary gait.
    """
    found: list[FixedPoint] = []
    retry: list[np.ndarray] = []
    bmap = bilateral_map(pmap) if include_invalid else None
    guesses = np.linspace(*theta_dot_range, n_guesses)

    def new(fp: FixedPoint) -> bool:
        return all(np.max(np.abs(fp.z - other.z)) > 1e-6 for other in found)

    for i, w in enumerate(guesses):
        for th in (-ALPHA / 2 - 0.07, -ALPHA / 2 - 0.02):
            try:
                fp = solve_fixed_point(pmap, np.array([th, w]), max_iter=15, record=False, known=[f.z for f in found])
            except KnownFixedPoint:
                continue
            except StepFailure as err:
                if bmap is not None and _contact_failure(err):
                    retry.append(np.array([th, w]))
                continue
            if new(fp):
                found.append(fp)
        if progress:
            progress(i + 1, len(guesses))
    for z0 in retry:
        assert bmap is not None  # only guesses that met a contact failure with a bilateral map are retried
        try:
            fp = solve_fixed_point(bmap, z0, max_iter=15, record=False)
            if not new(fp):
                continue
            contact = bilateral_contact(bmap, fp.z)
        except StepFailure:
            continue
        if contact.unilateral_valid:
            try:  # valid after all (Newton's path crossed a lift-off): the unilateral map's gait
                fp = solve_fixed_point(pmap, fp.z, max_iter=15, record=False)
                contact = None
            except StepFailure:
                pass  # e.g. a dip between the force samples that the located guard catches
        fp.contact = contact
        if new(fp):
            found.append(fp)
    recorded = []
    for fp in found:  # the full step of each distinct gait only
        try:
            smap = bmap if fp.bilateral else pmap
            assert smap is not None  # a bilateral gait comes from the bilateral map
            fp.step = smap.step(fp.z)
        except StepFailure:
            continue
        recorded.append(fp)
    recorded.sort(key=lambda fp: fp.recorded_step.period_s)
    return recorded
