"""The compiled fast path (rimless.sim.fast) against the reference Python/scipy implementation.

Independent expectations: the reference dynamics/impact/section code, the reference hybrid step with
scipy's DOP853, and central finite differences of the reference map. No timing is asserted.
"""

from __future__ import annotations

import numpy as np
import pytest

from rimless.sim import fast
from rimless.sim.fast import model as fm
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model import dynamics, section
from rimless.sim.model import guards as events
from rimless.sim.model import impact as ref_impact
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import MASS_MODELS, WheelParams
from rimless.sim.step.fast_map import FastPoincareMap
from rimless.sim.step.hybrid import simulate_step
from rimless.sim.step.poincare import PoincareMap, solve_fixed_point

Z_ER = np.array([-0.465155, 2.604441])
Z_VE = np.array([-0.434780, 2.289290])

# Each mass model compiles kernels of its own (tens of seconds on a cold cache): eight-leg (the robot's) runs in
# every run, the other two are marked `full` (CI runs them).
MASS_MODEL_CASES = [m if m == "eight-leg" else pytest.param(m, marks=pytest.mark.full) for m in MASS_MODELS]


def _state(mech: Mechanics, rng: np.random.Generator) -> np.ndarray:
    y = section.state_from_section(mech, Z_ER)
    return y + rng.normal(size=10) * 0.03


@pytest.mark.parametrize("mass_model", MASS_MODEL_CASES)
def test_phase_dynamics_and_exact_derivatives_match_the_reference(mass_model: str) -> None:
    params = WheelParams(mass_model=mass_model)
    mech = Mechanics.of(params)
    mi = fm.MASS_MODEL_INDEX[mass_model]
    rng = np.random.default_rng(3)
    for _ in range(3):
        y = _state(mech, rng)
        for phase in (dynamics.DLSP, dynamics.SLSP_FREE, dynamics.SLSP_CLUTCHED):
            qdd_ref, lam_ref = dynamics.accel(mech, phase, y[:5], y[5:])
            n = len(lam_ref)
            qdd, lam = np.empty(5), np.zeros(4)
            assert fm.accel(mi, phase, y[:5], y[5:], mech.p, qdd, lam)
            np.testing.assert_allclose(qdd, qdd_ref, rtol=1e-11, atol=1e-10)
            np.testing.assert_allclose(lam[:n], lam_ref, rtol=1e-11, atol=1e-10)
            D, Dl = np.empty((5, 10)), np.empty((4, 10))
            assert fm.accel_jacobian(mi, phase, y[:5], y[5:], mech.p, qdd, lam, D, Dl)
            e = 1e-6
            for j in range(10):
                yp, ym = y.copy(), y.copy()
                yp[j] += e
                ym[j] -= e
                a1, l1 = dynamics.accel(mech, phase, yp[:5], yp[5:])
                a2, l2 = dynamics.accel(mech, phase, ym[:5], ym[5:])
                np.testing.assert_allclose(D[:, j], (a1 - a2) / (2 * e), rtol=1e-6, atol=1e-5)
                np.testing.assert_allclose(Dl[:n, j], (l1 - l2) / (2 * e), rtol=1e-6, atol=1e-5)


@pytest.mark.parametrize("mass_model", MASS_MODEL_CASES)
def test_impact_section_and_guard_gradients_match_the_reference(mass_model: str) -> None:
    params = WheelParams(mass_model=mass_model)
    mech = Mechanics.of(params)
    mi = fm.MASS_MODEL_INDEX[mass_model]
    # section map and its tangent
    y, T = fm.state_from_section(mi, Z_ER, mech.p)
    np.testing.assert_allclose(y, section.state_from_section(mech, Z_ER), atol=1e-14)
    e = 1e-6
    for i in range(2):
        dz = np.zeros(2)
        dz[i] = e
        fd = (section.state_from_section(mech, Z_ER + dz) - section.state_from_section(mech, Z_ER - dz)) / (2 * e)
        np.testing.assert_allclose(T[:, i], fd, atol=1e-8)
    # impact and its reset Jacobian
    rng = np.random.default_rng(5)
    y_minus = _state(mech, rng)
    y_minus[2] = 0.39

    def reset(yy: np.ndarray) -> np.ndarray:
        r = ref_impact.impact(mech, yy[:5], yy[5:])
        return np.concatenate((r.q_plus, r.qd_plus))

    ok, yp, impulse, V = fm.impact(mi, y_minus, mech.p, np.eye(10), True)
    assert ok
    r = ref_impact.impact(mech, y_minus[:5], y_minus[5:])
    np.testing.assert_allclose(yp, reset(y_minus), atol=1e-12)
    np.testing.assert_allclose(impulse, r.impulse, atol=1e-12)
    for j in range(10):
        dy = np.zeros(10)
        dy[j] = e
        np.testing.assert_allclose(V[:, j], (reset(y_minus + dy) - reset(y_minus - dy)) / (2 * e), atol=1e-7)
    # guard values and gradients
    for phase, code in (
        (dynamics.DLSP, events.LIFTOFF_A),
        (dynamics.SLSP_FREE, events.LIFTOFF_B),
        (dynamics.SLSP_CLUTCHED, events.TOUCHDOWN),
        (dynamics.SLSP_FREE, events.CLUTCH_LOCK),
    ):
        g = fm.guard_gradient(mi, phase, code, y_minus, mech.p)
        for j in range(10):
            dy = np.zeros(10)
            dy[j] = e
            fd = (
                events.guard_value(mech, phase, code, y_minus + dy)
                - events.guard_value(mech, phase, code, y_minus - dy)
            ) / (2 * e)
            assert g[j] == pytest.approx(fd, rel=1e-6, abs=1e-6)


CASES = [
    ("eight-leg", "er", Z_ER),
    ("eight-leg", "ve", Z_VE),
    ("eight-leg", "er", Z_ER + np.array([0.01, -0.1])),
    ("eight-leg", "ve", Z_VE + np.array([-0.01, 0.15])),
    # the other mass models' step kernels compile for about 30 s each on a cold cache: `full` (CI runs them)
    pytest.param("sliding-leg", "er", Z_ER, marks=pytest.mark.full),
    pytest.param("active-feet", "ve", Z_VE, marks=pytest.mark.full),
]


@pytest.mark.slow
@pytest.mark.parametrize(("mass_model", "model", "z"), CASES)
def test_compiled_map_matches_the_reference_map(mass_model: str, model: str, z: np.ndarray) -> None:
    params = WheelParams(mass_model=mass_model)
    ref = PoincareMap(params, model, ScipyIntegrator(rtol=1e-10, atol=1e-12)).step(z)
    r = fast.fast_step(params, model, z, rtol=1e-10, atol=1e-12)
    # the same algorithm at the same tolerances: agreement far below the tolerance
    np.testing.assert_allclose(r.z_next, section.section_from_state(ref.y_plus), atol=1e-9)
    np.testing.assert_allclose(r.y_plus, ref.y_plus, atol=1e-9)
    assert r.period_s == pytest.approx(ref.period_s, abs=1e-10)
    ends = [rec.t_end_s for rec in ref.phases]
    if model == "er":
        np.testing.assert_allclose(r.phase_end_s, ends, atol=1e-10)
    else:
        np.testing.assert_allclose(r.phase_end_s[[0, 2]], ends, atol=1e-10)


def test_fast_integrator_reproduces_the_reference_step_with_records_and_dissipation() -> None:
    params = WheelParams()
    mech = Mechanics.of(params)
    y0 = section.state_from_section(mech, Z_ER)
    ref = simulate_step(mech, "er", y0, ScipyIntegrator(), record_dt=1e-3, track_dissipation=True, diagnostics=True)
    got = simulate_step(mech, "er", y0, fast.FastIntegrator(), record_dt=1e-3, track_dissipation=True, diagnostics=True)
    np.testing.assert_allclose(got.y_plus, ref.y_plus, atol=1e-9)
    assert got.dissipated_J == pytest.approx(ref.dissipated_J, rel=1e-8)
    assert [p.name for p in got.phases] == [p.name for p in ref.phases]
    assert got.nfev > 0
    assert got.segments is not None and ref.segments is not None
    for sg, sr in zip(got.segments, ref.segments, strict=True):
        # every grid time of the reference is also recorded by the fast backend, with the same state
        common, ig, ir = np.intersect1d(np.round(sg.t, 12), np.round(sr.t, 12), return_indices=True)
        assert len(common) >= len(np.arange(sr.t[0], sr.t[-1], 1e-3)) - 1
        np.testing.assert_allclose(sg.y[ig], sr.y[ir], atol=1e-8)
        assert np.all(np.diff(sg.t) > 0)
    assert got.diagnostics is not None and ref.diagnostics is not None
    for key, value in ref.diagnostics.items():
        assert got.diagnostics[key] == pytest.approx(value, rel=1e-3, abs=1e-5), key


FAILING = [
    ("er", np.array([-0.465, -0.5])),  # theta' <= 0 at the start
    ("er", np.array([-0.465, 0.6])),  # far too slow: rolls back
    ("ve", np.array([-0.435, 0.6])),
    ("er", np.array([-0.40, 9.0])),  # far too fast
    ("ve", np.array([-0.40, 9.0])),
    ("er", np.array([-0.30, 2.6])),
    ("ve", np.array([-0.50, 3.5])),
]


@pytest.mark.parametrize(("model", "z"), FAILING)
def test_failures_are_classified_like_the_reference(model: str, z: np.ndarray) -> None:
    params = WheelParams()
    pm = PoincareMap(params, model)
    try:
        z_ref = pm(z)
        ref_reason = None
    except StepFailure as err:
        ref_reason = err.reason
    try:
        z_fast = fast.fast_step(params, model, z).z_next
        fast_reason = None
    except StepFailure as err:
        fast_reason = err.reason
        assert err.phase
    assert fast_reason == ref_reason
    if ref_reason is None:
        np.testing.assert_allclose(z_fast, z_ref, atol=1e-8)


@pytest.fixture(scope="module")
def tight_reference() -> dict[str, PoincareMap]:
    return {m: PoincareMap(WheelParams(), m, ScipyIntegrator(rtol=1e-12, atol=1e-14)) for m in ("er", "ve")}


@pytest.mark.parametrize(
    ("model", "z"),
    [
        ("er", Z_ER),
        ("ve", Z_VE),
        ("er", Z_ER + np.array([0.015, 0.2])),
        ("ve", Z_VE + np.array([-0.01, -0.1])),
    ],
)
def test_exact_jacobian_matches_central_differences_of_the_reference(
    tight_reference, model: str, z: np.ndarray
) -> None:
    J = fast.exact_jacobian(WheelParams(), model, z, rtol=1e-12, atol=1e-14)
    J_fd = tight_reference[model].jacobian(z, h=1e-5)
    np.testing.assert_allclose(J, J_fd, atol=1e-6, rtol=0)


@pytest.mark.full  # compiles the step kernels of the other two mass models
@pytest.mark.parametrize("mass_model", ["sliding-leg", "active-feet"])
def test_exact_jacobian_other_mass_models(mass_model: str) -> None:
    params = WheelParams(mass_model=mass_model)
    pm = FastPoincareMap(params, "er", fast.FastIntegrator(rtol=1e-12, atol=1e-14))
    J = fast.exact_jacobian(pm, z=Z_ER)
    np.testing.assert_allclose(J, pm.jacobian(Z_ER, h=1e-5), atol=1e-6)


def test_fixed_point_on_the_fast_path_with_the_variational_jacobian(er_fixed_point) -> None:
    """Against the reference path (conftest: scipy DOP853 at rtol 1e-12, central-difference Jacobian)."""
    _, ref = er_fixed_point
    pm = FastPoincareMap(WheelParams(), "er")
    fp = solve_fixed_point(pm, ref.z + np.array([0.01, -0.05]), jacobian=pm.variational_jacobian)
    assert fp.jacobian_method == "variational"
    np.testing.assert_allclose(fp.z, ref.z, atol=1e-8)
    np.testing.assert_allclose(np.sort(np.abs(fp.eigenvalues)), np.sort(np.abs(ref.eigenvalues)), atol=1e-6)
    assert fp.step.period_s == pytest.approx(ref.step.period_s, abs=1e-8)
    # the default jacobian of the fast map is the variational one too
    fp2 = solve_fixed_point(pm, ref.z)
    assert fp2.jacobian_method == "variational"
    np.testing.assert_allclose(fp2.z, fp.z, atol=1e-9)
    # continuation code uses with_params
    pm2 = pm.with_params(WheelParams(slope_rad=0.045))
    assert isinstance(pm2, FastPoincareMap) and pm2.params.slope_rad == 0.045


def test_ve_fixed_point_matches_the_reference_solver() -> None:
    fp_ref = solve_fixed_point(PoincareMap(WheelParams(), "ve"), Z_VE)
    pm = FastPoincareMap(WheelParams(), "ve")
    fp = solve_fixed_point(pm, Z_VE + np.array([0.005, 0.03]))
    np.testing.assert_allclose(fp.z, fp_ref.z, atol=1e-8)
    np.testing.assert_allclose(np.sort(np.abs(fp.eigenvalues)), np.sort(np.abs(fp_ref.eigenvalues)), atol=1e-6)


def test_failure_reason_and_phase_are_reported() -> None:
    with pytest.raises(StepFailure) as info:
        fast.fast_map(WheelParams(), "er", np.array([-0.465, 0.6]))
    assert info.value.reason is FailureReason.STALL
    with pytest.raises(ValueError):
        fast.fast_map(WheelParams(), "rigid", Z_ER)


PHASE_END_GUARD = {
    "dlsp": (dynamics.DLSP, events.LIFTOFF_A),
    "slsp_free": (dynamics.SLSP_FREE, events.CLUTCH_LOCK),
    "slsp_clutched": (dynamics.SLSP_CLUTCHED, events.TOUCHDOWN),
}


@pytest.mark.parametrize(("model", "z"), [("er", Z_ER), ("ve", Z_VE)])
@pytest.mark.parametrize(("rtol", "bound"), [(1e-10, 1e-10), (1e-6, 1e-7)])
def test_phase_ends_lie_on_their_guards_on_the_fast_backend(
    model: str, z: np.ndarray, rtol: float, bound: float
) -> None:
    """The state at a guard comes from a step to the time located on the dense output: on the guard to the
    interpolant's error, at loose rtol too. Bounds in m, m/s, rad/s; a normal-force guard (N) to 100 x the
    bound (1e-8 N is 4e-10 of the wheel's weight at rtol 1e-10)."""
    mech = Mechanics.of(WheelParams())
    res = simulate_step(
        mech,
        model,
        section.state_from_section(mech, z),
        fast.FastIntegrator(rtol=rtol, atol=rtol * 1e-2),
        record_dt=1e-2,
    )
    assert res.segments is not None
    for seg, rec in zip(res.segments, res.phases, strict=True):
        phase, guard = PHASE_END_GUARD[rec.name]
        if model == "ve" and rec.name == "slsp_free":
            guard = events.TOUCHDOWN
        value = events.guard_value(mech, phase, guard, seg.y[-1])
        scale = 100.0 if guard in (events.LIFTOFF_A, events.LIFTOFF_B) else 1.0
        assert abs(value) <= bound * scale, f"{rec.name} ends {value:.2e} off its guard"


@pytest.mark.parametrize(("model", "z"), [("er", Z_ER), ("ve", Z_VE)])
def test_per_phase_counts_add_up_and_a_loose_map_stays_accurate(tight_reference, model: str, z: np.ndarray) -> None:
    r = fast.fast_step(WheelParams(), model, z, rtol=1e-5)
    assert sum(r.phase_nfev) == r.nfev and sum(r.phase_steps) == r.nsteps
    assert all(n > 0 for n in r.phase_nfev[:2]) and (r.phase_nfev[2] > 0) == (model == "er")
    # double support at rtol x 1e-4 and event states from a step: far below the rtol at the map's output
    np.testing.assert_allclose(r.z_next, tight_reference[model](z), atol=1e-8)
