"""Guide friction (rimless.sim.model.friction, rimless.sim.integrate.friction) against independent truths:
a single leg's free oscillation with Coulomb friction (closed form, tests/support/friction_leg.py), stick
phases, the energy budget with the friction work, and F_c = 0 unchanged."""

import math

import numpy as np
import pytest

from rimless.sim.integrate.friction import run_with_friction
from rimless.sim.integrate.reference import ScipyIntegrator
from rimless.sim.model.dynamics import SLSP_CLUTCHED
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from rimless.sim.model.section import state_from_section
from rimless.sim.step.hybrid import simulate_step
from tests.support import friction_leg

TIGHT = ScipyIntegrator(rtol=1e-12, atol=1e-14)


def hanging_leg(F: float, x0: float, c: float = 0.0) -> tuple[Mechanics, np.ndarray]:
    """The wheel upright on its clutched stance leg on level ground (theta = 0, at rest) with the trailing leg
    stretched by x0. In the `sliding-leg` mass model the legs' mass m moves only along the leg and carries no
    gravity: the trailing leg is then exactly a mass m on the spring k (and damper c) with guide friction."""
    p = WheelParams(mass_model="sliding-leg", damping_ns_per_m=c, slope_rad=0.0, guide_friction_n=F)
    L0 = p.leg_length_m
    y = np.zeros(10)
    y[3] = L0
    y[4] = L0 + x0
    return Mechanics.of(p), y


@pytest.mark.parametrize("F", [0.5, 2.0])
def test_single_leg_decays_linearly_by_4F_over_k_per_cycle_and_sticks(F):
    mech, y0 = hanging_leg(F, x0=0.004)
    p = mech.params
    k, m, L0 = p.stiffness_n_per_m, p.leg_mass_kg, p.leg_length_m
    w = math.sqrt(k / m)
    t_end = 12 * math.pi / w  # six periods
    run = run_with_friction(TIGHT, mech, SLSP_CLUTCHED, y0, 0.0, (), t_end, record_dt=t_end / 3000)
    assert not run.failed and run.guard is None
    x = run.y[:, 4] - L0
    truth = friction_leg.position(run.t, 0.004, k, m, F)
    assert np.max(np.abs(x - truth)) < 1e-9  # m, against the piecewise closed form
    # successive turning points: the amplitude drops by 2 F/k each half-cycle, 4 F/k per cycle
    tps = friction_leg.turning_points(0.004, k, F)
    for n, xt in enumerate(tps):
        ti = min(n * math.pi / w, t_end)
        i = int(np.argmin(np.abs(run.t - ti)))
        assert x[i] == pytest.approx(xt, abs=1e-8)
    assert len(tps) >= 3
    assert abs(tps[0]) - abs(tps[2]) == pytest.approx(4 * F / k, rel=1e-12)
    # the final stick: the leg stays put for the rest of the run, and the run says how long it was stuck
    t_stick = (len(tps) - 1) * math.pi / w
    stuck = run.t > t_stick + 1e-6
    assert np.ptp(x[stuck]) < 1e-12
    assert run.stick_s[1] == pytest.approx(t_end - t_stick, abs=1e-6)
    # friction work = spring energy lost: 1/2 k (x0^2 - x_end^2)
    assert run.friction_J == pytest.approx(0.5 * k * (0.004**2 - tps[-1] ** 2), rel=1e-9)


def test_a_leg_at_rest_inside_the_friction_band_stays_put():
    F = 5.0
    mech, y0 = hanging_leg(F, x0=0.9 * F / WheelParams().stiffness_n_per_m)
    run = run_with_friction(TIGHT, mech, SLSP_CLUTCHED, y0, 0.0, (), 0.05, record_dt=1e-3)
    assert np.ptp(run.y[:, 4]) == 0.0 and run.friction_J == 0.0 and run.stick_s[1] == pytest.approx(0.05)


def test_friction_and_damping_together_match_an_independent_integration():
    """With a damper as well there is no closed form: compare with a plain fixed-step RK4 of
    m x'' = -k x - c x' - F sign(x') (sign switching by direct simulation, tiny step)."""
    F, c, x0 = 0.8, 0.3, 0.004
    mech, y0 = hanging_leg(F, x0=x0, c=c)
    p = mech.params
    k, m, L0 = p.stiffness_n_per_m, p.leg_mass_kg, p.leg_length_m
    t_end = 0.02
    run = run_with_friction(TIGHT, mech, SLSP_CLUTCHED, y0, 0.0, (), t_end, record_dt=1e-3)

    def f(s: np.ndarray, direction: float) -> np.ndarray:
        return np.array([s[1], (-k * s[0] - c * s[1] - F * direction) / m])

    def rk4(s: np.ndarray, h: float, direction: float) -> np.ndarray:
        k1 = f(s, direction)
        k2 = f(s + h / 2 * k1, direction)
        k3 = f(s + h / 2 * k2, direction)
        k4 = f(s + h * k3, direction)
        return s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    s, dt, direction = np.array([x0, 0.0]), 1e-7, -1.0
    per_sample = 10_000  # RK4 steps per 1 ms sample
    ref = [s[0]]
    for i in range(1, int(round(t_end / dt)) + 1):
        s_new = rk4(s, dt, direction)
        if direction != 0.0 and s_new[1] * direction < 0:  # the slide ends within the step: split it there
            h1 = dt * s[1] / (s[1] - s_new[1])
            for _ in range(3):  # secant refinement of the rest instant
                v1 = rk4(s, h1, direction)[1]
                a1 = f(rk4(s, h1, direction), direction)[1]
                h1 -= v1 / a1
            mid = rk4(s, h1, direction)
            mid[1] = 0.0
            direction = -direction if abs(k * mid[0]) > F else 0.0
            s_new = rk4(mid, dt - h1, direction)
        s = s_new
        if i % per_sample == 0:
            ref.append(s[0])
    ref = np.array(ref)
    grid = np.arange(len(ref)) * 1e-3
    # the samples that fall on the 1 ms grid (each stick/slip sub-phase samples from its own start)
    idx = [(j, int(np.argmin(np.abs(run.t - tg)))) for j, tg in enumerate(grid)]
    idx = [(j, i) for j, i in idx if abs(run.t[i] - grid[j]) < 1e-12]
    assert len(idx) >= 8 and len(ref) == 21
    err = max(abs(run.y[i, 4] - L0 - ref[j]) for j, i in idx)
    assert err < 1e-10


@pytest.mark.parametrize("model", ["er", "ve"])
@pytest.mark.parametrize("F", [0.5, 3.0])
def test_step_energy_budget_closes_with_friction_work(model, F):
    """E(start) - E(end) = damping + friction work + impact + relabelling losses."""
    mech = Mechanics.of(WheelParams(guide_friction_n=F))
    y0 = state_from_section(mech, np.array([-0.46, 2.6]))
    res = simulate_step(mech, model, y0, TIGHT, track_dissipation=True)
    imp = res.impact
    e_start = mech.energy(y0[:5], y0[5:])
    e_end = mech.energy(res.y_plus[:5], res.y_plus[5:])
    impact_loss = imp.kinetic_relabelled - imp.kinetic_plus
    assert res.friction_work_J > 0.0
    assert e_start - e_end == pytest.approx(
        res.dissipated_J + res.friction_work_J + impact_loss + imp.relabel_loss, abs=1e-9
    )
    # the lifted trailing leg comes to rest and sticks before touchdown
    assert res.stick_s[1] > 0.1


def test_large_friction_sticks_the_ve_stance_leg():
    mech = Mechanics.of(WheelParams(guide_friction_n=3.0))
    res = simulate_step(mech, "ve", state_from_section(mech, np.array([-0.46, 2.6])), TIGHT, record_dt=1e-3)
    assert res.stick_s[0] > 0.01
    # during the stick the stance leg's length is constant
    y = np.concatenate([s.y for s in res.segments if s.phase != 0])
    l1 = y[:, 3]
    flat = np.abs(np.diff(l1)) == 0.0
    assert flat.sum() >= 5


# Regression snapshot: simulate_step from z = (-0.46, 2.6) at Table 1 (reference path, default tolerances),
# computed with the code before guide friction existed (commit c503cc9). F_c = 0 reproduced it bit for bit on the
# machine that recorded it; another CPU or numpy/scipy build (OpenBLAS's AVX-512 kernels, a newer numpy) moves the
# last bits (2e-14 relative seen on an AMD EPYC with numpy 2.4.6, scipy 1.17.1), so the test allows SNAPSHOT_REL.
# A friction term leaking into the frictionless step would move these by far more (F_c = 0.05 N: 2e-3 to 1e-2).
SNAPSHOT_REL = 1e-12
# The central-difference Jacobian divides the map's last-bit differences by its step: |eigenvalues| to this.
SNAPSHOT_EIG_REL = 1e-8


def _matches_snapshot(values, hexes, rel):
    want = np.array([float.fromhex(h) for h in hexes])
    return np.allclose(np.asarray(values, dtype=float), want, rtol=rel, atol=0.0)


BEFORE = {
    "er": (
        [
            "-0x1.db977945fa474p-2",
            "0x1.e5604189374bcp-3",
            "0x1.c950187fb0e71p-3",
            "0x1.4a4fc7a36e21dp+1",
            "-0x1.a06789f50b003p-3",
            "0x1.279e822e2399bp-2",
        ],
        "0x1.26b3613725f0dp-4",
        "0x1.40143571e152ap-2",
    ),
    "ve": (
        [
            "-0x1.99addd2eaabecp-2",
            "0x1.e5604189374bcp-3",
            "0x1.e26b100f7eb02p-3",
            "0x1.5a24e7506d3ddp+1",
            "-0x1.0a30259c42022p-2",
            "0x1.13d7de35bdc36p-2",
        ],
        "0x1.d998da1672778p-4",
        "0x1.60e2c28a518cfp-2",
    ),
}


@pytest.mark.parametrize("model", ["er", "ve"])
def test_zero_friction_reproduces_the_step_before_friction(model):
    mech = Mechanics.of(WheelParams(guide_friction_n=0.0))
    r = simulate_step(
        mech, model, state_from_section(mech, np.array([-0.46, 2.6])), ScipyIntegrator(), track_dissipation=True
    )
    ys, diss, period = BEFORE[model]
    assert _matches_snapshot(r.y_plus[[2, 3, 4, 7, 8, 9]], ys, SNAPSHOT_REL)
    assert _matches_snapshot([r.dissipated_J, r.period_s], [diss, period], SNAPSHOT_REL)
    assert r.friction_work_J == 0.0


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf"), "1"])
def test_guide_friction_is_validated(bad):
    from rimless.errors import ParameterError

    with pytest.raises(ParameterError, match="guide_friction_n"):
        WheelParams(guide_friction_n=bad)


def test_frictionless_records_keep_their_keys():
    """to_dict (records, sweep cache keys) is unchanged without friction, and carries F_c with it."""
    assert "guide_friction_n" not in WheelParams().to_dict()
    assert WheelParams(guide_friction_n=0.5).to_dict()["guide_friction_n"] == 0.5
    assert WheelParams(**WheelParams(guide_friction_n=0.5).to_dict()).guide_friction_n == 0.5


# Regression snapshot: the reference path's Table 1 fixed points (PoincareMap default integrator, default guess,
# central-difference Jacobian), computed with the code before guide friction existed (commit c503cc9, run from an
# export of that commit); F_c = 0 reproduced z and |eigenvalues| bit for bit there (tolerances: see BEFORE).
BEFORE_FIXED_POINT = {
    "er": (["-0x1.dc51b1ecd3805p-2", "0x1.4d5e5260c068ap+1"], ["0x1.a06fecf482620p-4", "0x1.923b8d68ffbe3p-1"]),
    "ve": (["-0x1.bd3705988ab90p-2", "0x1.250772176ce53p+1"], ["0x1.360ea86961e2ap-2", "0x1.360ea86961e2ap-2"]),
}


@pytest.mark.slow  # about 15 s per model on a loaded machine
@pytest.mark.parametrize("model", ["er", "ve"])
def test_zero_friction_reproduces_the_fixed_point_before_friction(model):
    from rimless.sim.step.poincare import PoincareMap, default_guess, solve_fixed_point

    p = WheelParams(guide_friction_n=0.0)
    fp = solve_fixed_point(PoincareMap(p, model), default_guess(p, model), record=False)
    z, eig = BEFORE_FIXED_POINT[model]
    assert _matches_snapshot(fp.z, z, SNAPSHOT_REL)
    assert _matches_snapshot(np.abs(fp.eigenvalues), eig, SNAPSHOT_EIG_REL)


@pytest.mark.parametrize("model", ["er", "ve"])
def test_friction_work_is_F_times_the_distance_slid_on_the_recorded_trajectory(model):
    """Independent of the sub-phase bookkeeping: F_c times the total variation of L1 (outside the clutched
    phase) and of L2 over the densely recorded step."""
    from rimless.sim.model.dynamics import SLSP_CLUTCHED

    F = 1.5
    mech = Mechanics.of(WheelParams(guide_friction_n=F))
    res = simulate_step(mech, model, state_from_section(mech, np.array([-0.46, 2.6])), TIGHT, record_dt=2e-5)
    slid = 0.0
    for seg in res.segments:
        if seg.phase != SLSP_CLUTCHED:
            slid += float(np.sum(np.abs(np.diff(seg.y[:, 3]))))
        slid += float(np.sum(np.abs(np.diff(seg.y[:, 4]))))
    assert res.friction_work_J == pytest.approx(F * slid, rel=1e-6)
