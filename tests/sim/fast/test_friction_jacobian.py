"""The exact step-map Jacobian with guide friction (rimless.sim.step.fast_map.friction_step(jacobian=True),
rimless.sim.fast.friction): against central differences of the compiled map itself (an expectation computed
apart from the tangents: the map evaluated four times, no variational equations, no saltation), and (slow)
against central differences of the reference path (scipy DOP853 on the Python right-hand side)."""

from __future__ import annotations

import numpy as np
import pytest

from rimless.sim import fast
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import jacobian_factory
from rimless.sim.step.fast_map import FastPoincareMap, friction_step
from rimless.sim.step.poincare import PoincareMap

Z_TABLE1 = np.array([-0.465155, 2.604441])  # near Table 1's ER fixed point (rad, rad/s)
Z_SLOW = np.array([-0.42, 2.3])
# a wheel away from Table 1 (heavier hub and legs, more inertia, softer and less damped legs)
AWAY = {
    "hub_mass_kg": 2.3,
    "leg_mass_kg": 0.05,
    "inertia_kg_m2": 0.06,
    "stiffness_n_per_m": 1800.0,
    "damping_ns_per_m": 4.0,
}
RTOL = 1e-12  # tight: the central differences' own error is then about 1e-12 / H
H = 1e-5  # rad, rad/s: the central differences' step (truncation error ~ H^2, some 1e-10)
# largest |J - J_fd| relative to the largest |J_fd| entry; measured on CASES: 1e-10 to 3.2e-8 (branch fricjac22).
# Where the map bends sharply the differences' truncation is larger (ER, F_c 0.3 N, AWAY, Z_SLOW: 8e-6 at step
# 1e-5, 7e-8 at 1e-6, 3e-8 at 1e-7, converging on the exact value): not a case here.
REL_TOL = 2e-7

# (model, F_c N, wheel, z): every kind of event the tangents cross is in some case (test below)
CASES = [
    ("er", 0.1, AWAY, Z_TABLE1),  # a stick and a slip again of the trailing leg
    ("er", 0.3, {}, Z_SLOW),  # the same on Table 1's wheel
    ("er", 0.6, AWAY, Z_SLOW),
    ("ve", 0.1, AWAY, Z_SLOW),
    ("ve", 0.3, {}, Z_SLOW),  # the stance leg's slips end too
    ("ve", 0.6, AWAY, Z_TABLE1),
]


def _central(params: WheelParams, model: str, z: np.ndarray, rtol: float, h: float) -> np.ndarray:
    J = np.empty((2, 2))
    for i in range(2):
        dz = np.zeros(2)
        dz[i] = h
        plus = friction_step(params, model, z + dz, rtol=rtol).z_next
        minus = friction_step(params, model, z - dz, rtol=rtol).z_next
        J[:, i] = (plus - minus) / (2 * h)
    return J


@pytest.mark.parametrize(("model", "friction_n", "wheel", "z"), CASES)
def test_friction_jacobian_matches_central_differences_of_the_compiled_map(model, friction_n, wheel, z):
    params = WheelParams(guide_friction_n=friction_n, **wheel)
    r = friction_step(params, model, z, rtol=RTOL, jacobian=True)
    fd = _central(params, model, z, RTOL, H)
    assert r.jacobian is not None
    assert np.max(np.abs(r.jacobian - fd)) <= REL_TOL * np.max(np.abs(fd))
    assert r.events[-1] == "touchdown"


def test_the_cases_cross_every_kind_of_friction_event():
    """The cases above carry the tangents through a slip's end (sticking), a stick's end (slipping again) and the
    base events, on both models (else the comparison would not test those saltation matrices)."""
    seen: dict[str, set[str]] = {"er": set(), "ve": set()}
    for model, friction_n, wheel, z in CASES:
        r = friction_step(WheelParams(guide_friction_n=friction_n, **wheel), model, z, rtol=1e-10, jacobian=True)
        seen[model] |= set(r.events)
    assert {"lift-off-a", "clutch-lock", "slip-end-2", "stick-end-2", "touchdown"} <= seen["er"]
    assert {"lift-off-a", "slip-end-2", "stick-end-2", "touchdown"} <= seen["ve"]


@pytest.mark.parametrize("model", ["er", "ve"])
def test_the_step_with_its_jacobian_is_the_step_to_the_last_bit(model):
    params = WheelParams(guide_friction_n=0.4, **AWAY)
    plain = friction_step(params, model, Z_TABLE1)
    with_j = friction_step(params, model, Z_TABLE1, jacobian=True)
    assert plain.jacobian is None and plain.events == ()
    assert [float(v).hex() for v in with_j.z_next] == [float(v).hex() for v in plain.z_next]
    assert with_j.period_s == plain.period_s and with_j.friction_work_J == plain.friction_work_J


def test_the_poincare_map_with_friction_uses_the_exact_jacobian():
    params = WheelParams(guide_friction_n=0.3)
    pm = FastPoincareMap(params, "er", fast.FastIntegrator(rtol=1e-11, atol=1e-13))
    assert pm.exact_jacobian
    J = pm.jacobian(Z_TABLE1)
    assert pm.last_method == "hybrid+fast-dop853+variational"
    assert np.array_equal(J, friction_step(params, "er", Z_TABLE1, rtol=1e-11, atol=1e-13, jacobian=True).jacobian)
    jac = jacobian_factory("fast")(pm)
    assert getattr(jac, "method_name", "") == "variational"
    assert np.array_equal(fast.exact_jacobian(pm, z=Z_TABLE1), J)
    # central differences when asked for (a step h), as before
    assert np.max(np.abs(pm.jacobian(Z_TABLE1, 1e-5) - J)) < 1e-4 * np.max(np.abs(J))


def test_no_exact_friction_jacobian_where_it_is_not_built():
    """Bilateral contact and a non-ideal clutch keep central differences, labelled; exact_jacobian(params with
    friction) refuses instead of answering with the frictionless one-call map's Jacobian (which ignores F_c)."""
    from rimless.sim.step.hybrid import DelayedClutch

    assert not FastPoincareMap(WheelParams(guide_friction_n=0.3), "er", bilateral=True).exact_jacobian
    assert not FastPoincareMap(WheelParams(guide_friction_n=0.3), "er", clutch=DelayedClutch(0.002)).exact_jacobian
    with pytest.raises(ValueError, match="guide friction"):
        fast.exact_jacobian(WheelParams(guide_friction_n=0.3), "er", Z_TABLE1)


def test_the_one_call_step_refuses_friction_it_would_ignore():
    """fast_step / fast_map have no guide friction: given F_c > 0 they stepped the frictionless wheel silently
    (until session 22; on main their z_next equalled the F_c = 0 map's); now they refuse, and friction_step
    differs from the frictionless step (F_c takes energy)."""
    p = WheelParams(guide_friction_n=0.3)
    for call in (
        lambda: fast.fast_step(p, "er", np.array(Z_TABLE1)),
        lambda: fast.fast_map(p, "er", np.array(Z_TABLE1)),
    ):
        with pytest.raises(ValueError, match="guide friction"):
            call()
    frictionless = fast.fast_step(WheelParams(), "er", np.array(Z_TABLE1)).z_next
    assert abs(friction_step(p, "er", np.array(Z_TABLE1)).z_next[1] - frictionless[1]) > 1e-4


@pytest.mark.slow
def test_light_legs_friction_jacobian_matches_central_differences():
    """Legs of 0.1 g (rimless.sim.studies.stiffbench.light_wheel): single support by the Rosenbrock method with
    the tangents. Central differences at rtol 1e-12 with step 1e-4 (measured: 8.9e-8 relative; at step 1e-5 2e-7,
    at 1e-6 7.7e-7, at 1e-7 1.1e-5: the light map's own noise grows as the step shrinks)."""
    from rimless.sim.studies.stiffbench import light_wheel

    params = light_wheel(0.3)
    z = np.array([-0.40, 2.2])
    r = friction_step(params, "er", z, rtol=1e-10, jacobian=True)
    fd = _central(params, "er", z, RTOL, 1e-4)
    assert np.max(np.abs(r.jacobian - fd)) <= 1e-6 * np.max(np.abs(fd))
    assert [float(v).hex() for v in r.z_next] == [
        float(v).hex() for v in friction_step(params, "er", z, rtol=1e-10).z_next
    ]


@pytest.mark.slow
@pytest.mark.parametrize(("model", "friction_n", "wheel", "z"), [CASES[1], CASES[3]])
def test_friction_jacobian_matches_central_differences_of_the_reference_path(model, friction_n, wheel, z):
    """The reference path (scipy DOP853, the Python model of rimless.sim.model) at rtol 1e-12: its central
    differences (step 1e-5; their error some 1e-7 relative from the path's own error) against the compiled exact
    Jacobian. The ER case differs by 2.0e-7: the reference's tolerance (4.9e-9 at its rtol 1e-13; the steps 1e-4 to
    1e-6 give the same 2e-7; rimless.sim.studies.fricjacbench's docstring)."""
    params = WheelParams(guide_friction_n=friction_n, **wheel)
    ref = PoincareMap(params, model, ScipyIntegrator(rtol=1e-12, atol=1e-14))
    fd = np.column_stack([(ref(z + dz) - ref(z - dz)) / (2 * H) for dz in (np.array([H, 0.0]), np.array([0.0, H]))])
    J = friction_step(params, model, z, rtol=1e-12, jacobian=True).jacobian
    assert np.max(np.abs(J - fd)) <= 1e-6 * np.max(np.abs(fd))
