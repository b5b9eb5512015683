"""Robustness beyond local stability (issue 33): basin of attraction, gait sensitivity norm, mean first-passage time.

The library functions take any map P(z, slope). The independent expectations come from the rigid rimless wheel,
written here from the physics in a few lines (paper convention of model.md section 7: M = m_H, inertia I_c about
the hub, Table 1 values): over a stance the energy 1/2 (I_c + M L^2) w^2 + M g L cos(theta + phi) is conserved
(theta from the slope normal, theta + phi the world angle of the stance leg), the step ends at theta = alpha/2
and the impact gives w+ = beta w-, beta = (I_c + M L^2 cos alpha) / (I_c + M L^2), theta+ = -alpha/2. A step
fails by a stall (the hub does not pass over the top, theta = -phi) or by lift-off (the stance foot's normal
force M g cos(theta + phi) - M L w^2 < 0 somewhere in the stance; it is smallest at the end of the stance
farthest from the top).
"""

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from rimless.cli import app
from rimless.sim.model.failures import FailureReason, StepFailure
from rimless.sim.studies.basin import basin_of_attraction
from rimless.sim.studies.mfpt import SLOPE_LIMIT_RAD, mesh_mfpt, monte_carlo_mfpt
from rimless.sim.studies.sensitivity import gait_sensitivity

M, I_C, L, G = 1.892, 0.036, 0.237, 9.81  # Table 1: m_H, I_c, L0, g
ALPHA = math.pi / 4
IP = I_C + M * L * L  # inertia about the stance foot
C = M * G * L / IP  # w^2 / 2 + C cos(theta + phi) is constant over a stance
BETA = (I_C + M * L * L * math.cos(ALPHA)) / IP
SLOPE = 0.08  # rad: well above the rigid wheel's critical slope (2.80 deg = 0.049 rad)


def rigid_step(z, slope):
    theta, w = float(z[0]), float(z[1])
    e = w * w + 2 * C * math.cos(theta + slope)  # w(theta)^2 = e - 2 C cos(theta + slope)
    if w <= 0 or (theta < -slope and e < 2 * C):
        raise StepFailure(FailureReason.STALL, "does not pass the top")
    if e - (2 * C + G / L) * min(math.cos(theta + slope), math.cos(ALPHA / 2 + slope)) > 0:
        raise StepFailure(FailureReason.STANCE_LIFT_OFF, "M L w^2 > M g cos")
    return np.array([-ALPHA / 2, BETA * math.sqrt(e - 2 * C * math.cos(ALPHA / 2 + slope))])


def rigid_w_star(slope):
    gain = 2 * C * (math.cos(-ALPHA / 2 + slope) - math.cos(ALPHA / 2 + slope))
    return math.sqrt(BETA**2 * gain / (1 - BETA**2))


def rigid_period(z, slope):
    """Time from theta+ to alpha/2: the integral of d theta / w(theta)."""
    from scipy.integrate import quad

    theta, w = float(z[0]), float(z[1])
    e = w * w + 2 * C * math.cos(theta + slope)
    return quad(lambda th: 1 / math.sqrt(e - 2 * C * math.cos(th + slope)), theta, ALPHA / 2, epsabs=1e-13)[0]


def rigid_step_with_period(z, slope):
    return rigid_step(z, slope), rigid_period(z, slope)


# -- basin of attraction ------------------------------------------------------------------------------------------
def rigid_in_basin(theta, w, slope=SLOPE):
    """Vectorised closed form: the first step and the second (from -alpha/2) neither stall nor lift off; from
    then on the 1-D map is monotone towards w*, so nothing fails later (w* is above the barrier)."""
    e = w * w + 2 * C * np.cos(theta + slope)
    ok1 = (w > 0) & ~((theta < -slope) & (e < 2 * C))
    ok1 &= e - (2 * C + G / L) * np.minimum(np.cos(theta + slope), math.cos(ALPHA / 2 + slope)) <= 0
    w1 = BETA * np.sqrt(np.maximum(e - 2 * C * math.cos(ALPHA / 2 + slope), 0))
    e1 = w1 * w1 + 2 * C * math.cos(-ALPHA / 2 + slope)
    ok2 = (e1 >= 2 * C) & (e1 - (2 * C + G / L) * min(math.cos(-ALPHA / 2 + slope), math.cos(ALPHA / 2 + slope)) <= 0)
    return ok1 & ok2


BOX = ((-0.55, 0.35), (0.02, 7.0))


def test_rigid_wheel_basin_matches_its_closed_form():
    z_star = np.array([-ALPHA / 2, rigid_w_star(SLOPE)])
    assert rigid_w_star(SLOPE) ** 2 > 2 * C * (1 - math.cos(ALPHA / 2 - SLOPE))  # the gait passes the top
    out, pts = basin_of_attraction(rigid_step, SLOPE, z_star, box=BOX, grid=40, steps=200)
    expected = rigid_in_basin(pts["theta_plus_rad"], pts["theta_dot_plus_rad_s"])
    got = pts["fate"] == "gait"
    assert np.array_equal(got, expected)
    assert set(out["fate_counts"]) >= {"gait", "stall", "stance-lift-off"}
    assert out["fate_counts"]["stall"] > 0 and out["fate_counts"]["stance-lift-off"] > 0
    assert sum(out["fate_counts"].values()) == 40 * 40
    # the area against the closed-form region on a 25x finer grid (independent of the library's grid)
    n = 1000
    th = BOX[0][0] + (np.arange(n) + 0.5) * (BOX[0][1] - BOX[0][0]) / n
    ww = BOX[1][0] + (np.arange(n) + 0.5) * (BOX[1][1] - BOX[1][0]) / n
    area = rigid_in_basin(th[None, :], ww[:, None]).mean() * (BOX[0][1] - BOX[0][0]) * (BOX[1][1] - BOX[1][0])
    assert out["basin_area_rad2_per_s"] == pytest.approx(area, rel=0.03)
    assert out["basin_area_fraction"] == pytest.approx(got.mean())
    # the nearest failure, in the stated metric, among the grid's failing points
    fail = ~expected
    d = np.hypot(
        (pts["theta_plus_rad"] - z_star[0]) / (ALPHA / 2), (pts["theta_dot_plus_rad_s"] - z_star[1]) / z_star[1]
    )
    assert out["nearest_failure_distance"] == pytest.approx(d[fail].min(), rel=1e-12)
    assert not out["nearest_failure_is_lower_bound"]
    assert all(v == v for v in (out["basin_area_rad2_per_s"], out["nearest_failure_distance"]))  # never NaN


def test_basin_reports_other_gaits_and_a_lower_bound_without_failures():
    # a map with two attracting fixed points (w = 1 and w = 3, the boundary at w = 2) and no failure at all
    def two_gaits(z, slope):
        w = z[1]
        return np.array([0.5 * z[0], w + 0.5 * (1 - w) if w < 2 else w + 0.5 * (3 - w)])

    out, pts = basin_of_attraction(two_gaits, 0.0, [0.0, 1.0], box=((-0.1, 0.1), (0.5, 3.5)), grid=6, steps=80)
    assert out["fate_counts"]["gait"] == 18 and out["fate_counts"]["other-gait"] == 18
    assert out["other_gaits"] and out["other_gaits"][0]["theta_dot_plus_rad_s"] == pytest.approx(3.0, abs=1e-3)
    assert out["nearest_failure_is_lower_bound"]
    assert out["nearest_failure_distance"] == pytest.approx(min(0.1 / (ALPHA / 2), 0.5))


# -- mean first-passage time ---------------------------------------------------------------------------------------
def rigid_monte_carlo(slope, sd, walks=20000, seed=12345):
    """Vectorised Monte Carlo of the rigid wheel's w-map (steps completed before the first failing step)."""
    rng = np.random.default_rng(seed)
    w = np.full(walks, rigid_w_star(slope))
    n = np.zeros(walks, dtype=np.int64)
    alive = np.ones(walks, dtype=bool)
    while alive.any():
        idx = np.flatnonzero(alive)
        s = np.clip(rng.normal(slope, sd, idx.size), -SLOPE_LIMIT_RAD, SLOPE_LIMIT_RAD)
        e = w[idx] ** 2 + 2 * C * np.cos(-ALPHA / 2 + s)
        lift = e - (2 * C + G / L) * np.minimum(np.cos(-ALPHA / 2 + s), np.cos(ALPHA / 2 + s)) > 0
        ok = (e >= 2 * C) & ~lift
        w[idx] = BETA * np.sqrt(np.maximum(e - 2 * C * np.cos(ALPHA / 2 + s), 0))
        n[idx[ok]] += 1
        alive[idx[~ok]] = False
    return n.mean(), 1.96 * n.std(ddof=1) / math.sqrt(walks)


RIGID_BOX = ((-ALPHA / 2 - 0.01, -ALPHA / 2 + 0.01), (0.02, 6.0))


@pytest.mark.parametrize("sd_deg", [1.5, 2.0, 3.0])
def test_rigid_wheel_mfpt_mesh_and_monte_carlo_match_an_independent_monte_carlo(sd_deg):
    sd = math.radians(sd_deg)
    z0 = np.array([-ALPHA / 2, rigid_w_star(SLOPE)])
    ref, ref_half = rigid_monte_carlo(SLOPE, sd)
    assert 20 <= ref <= 2000
    mc = monte_carlo_mfpt(rigid_step, SLOPE, sd, z0, walks=400, cap=100_000, seed=7)
    lo, hi = mc["mfpt_ci_steps"]
    assert lo - ref_half <= ref <= hi + ref_half
    assert mc["capped_walks"] == 0 and not mc["mfpt_is_lower_bound"]
    assert set(mc["failures_by_reason"]) <= {"stall", "stance-lift-off"}
    mesh = mesh_mfpt(rigid_step, SLOPE, sd, z0, box=RIGID_BOX, nodes=(1, 300), slopes=60)
    assert lo <= mesh["mfpt_steps"] <= hi  # the mesh within the library's Monte Carlo interval
    assert mesh["mfpt_steps"] == pytest.approx(ref, rel=0.03 + mesh["mfpt_discretisation_error_relative"])
    assert mesh["mfpt_discretisation_error_relative"] < 0.05
    assert mesh["fine"]["max_probability_outside_box"] < 1e-9
    # Byl-Tedrake's lambda_2 measure is close to the MFPT from the gait when the MFPT is long
    assert mesh["mfpt_quasi_stationary_steps"] == pytest.approx(mesh["mfpt_steps"], rel=0.1)


def test_rigid_wheel_mfpt_falls_as_the_terrain_gets_rougher():
    z0 = np.array([-ALPHA / 2, rigid_w_star(SLOPE)])
    values = [
        mesh_mfpt(rigid_step, SLOPE, math.radians(s), z0, box=RIGID_BOX, nodes=(1, 120), slopes=40)["mfpt_steps"]
        for s in (1.25, 1.5, 2.0, 3.0, 4.0)
    ]
    assert all(a > b for a, b in zip(values, values[1:], strict=False))


def test_monte_carlo_reports_walks_that_reach_the_cap():
    def never_fails(z, slope):
        return np.asarray(z, dtype=float)

    out = monte_carlo_mfpt(never_fails, 0.05, 0.01, [0.0, 1.0], walks=5, cap=30)
    assert out["capped_walks"] == 5 and out["mfpt_is_lower_bound"] and out["mfpt_steps"] == 30


# -- gait sensitivity norm -----------------------------------------------------------------------------------------
def test_rigid_wheel_gsn_of_theta_dot_matches_the_closed_form():
    """For theta'+ the rigid map is w' = beta sqrt(w^2 + gain(phi)), dw'/dw = beta^2 at the gait: a push gives the
    responses beta^2, beta^4, ... and a one-step slope change b^2 g'(phi) / (2 w*) times 1, beta^2, beta^4, ..."""
    ws = rigid_w_star(SLOPE)
    out = gait_sensitivity(rigid_step_with_period, SLOPE, [-ALPHA / 2, ws], None, push_rad_s=1e-3)
    b2 = BETA**2
    push = b2 / math.sqrt(1 - b2**2)
    dgain = 2 * C * (math.sin(ALPHA / 2 + SLOPE) - math.sin(-ALPHA / 2 + SLOPE))
    slope = b2 * dgain / (2 * ws) / math.sqrt(1 - b2**2)
    assert out["push"]["gsn_by_indicator"]["theta_dot_plus_rad_s"] == pytest.approx(push, rel=1e-6)
    assert out["slope"]["gsn_by_indicator"]["theta_dot_plus_rad_s"] == pytest.approx(slope, rel=1e-6)
    assert out["max_abs_eigenvalue"] == pytest.approx(b2, rel=1e-6)
    for d in ("push", "slope"):
        assert out[d]["relative_difference"] < 0.02


@pytest.fixture(scope="module")
def er_sensitivity():
    from rimless.sim import Wheel

    return Wheel(model="er").sensitivity()


def test_er_gsn_matches_simulated_finite_disturbances(er_sensitivity):
    out = er_sensitivity.to_dict()
    assert out["map_jacobian"].startswith("exact")
    for d in ("slope", "push"):
        block = out[d]
        assert block["relative_difference"] < 0.02
        for k in ("step_period_s", "theta_dot_plus_rad_s"):
            assert block["relative_difference_by_indicator"][k] < 0.02
        assert block["fd_error_estimate"] < 1e-5 * block["gsn"]
    # the linear response decays with the largest eigenvalue (model.md section 9: about 0.79)
    assert out["max_abs_eigenvalue"] == pytest.approx(0.79, abs=0.01)


def test_slope_map_is_the_wheels_map_and_continues_below_zero_slope():
    from rimless.sim import Wheel
    from rimless.sim.studies.section_map import SlopeMap

    wheel = Wheel(model="er")
    smap = SlopeMap(wheel.params, "er")
    z = np.array([-0.465, 2.6])
    for s in (0.0, 0.02, 0.05):
        assert np.allclose(smap(z, s), wheel.with_params(slope_rad=s).map(z), rtol=0, atol=1e-12)
    assert np.allclose(smap(z, -1e-7), smap(z, 1e-7), atol=1e-5)
    # an uphill step slows the wheel more than a level one
    assert smap(z, -0.03)[1] < smap(z, 0.0)[1]


@pytest.mark.slow
def test_er_mfpt_mesh_agrees_with_monte_carlo():
    from rimless.sim import Wheel

    wheel = Wheel(model="er")
    mesh = wheel.mfpt(3.0, method="mesh")
    mc = wheel.mfpt(3.0, method="monte-carlo", walks=300)
    lo, hi = mc["mfpt_ci_steps"]
    err = mesh["mfpt_discretisation_error_steps"]
    assert 20 <= mc["mfpt_steps"] <= 2000
    assert lo - err <= mesh["mfpt_steps"] <= hi + err


# -- command line --------------------------------------------------------------------------------------------------
RUN = CliRunner()


def _json(args):
    res = RUN.invoke(app, args)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_basin_command_json_equals_the_api(tmp_path):
    from rimless.sim import Wheel

    out = _json(["sim", "basin", "--grid", "3", "--steps", "40", "--json", "--out", str(tmp_path / "b")])
    for key in ("basin_area_rad2_per_s", "basin_area_fraction", "nearest_failure_distance", "fate_counts", "box"):
        assert key in out
    assert sum(out["fate_counts"].values()) == 9
    assert (tmp_path / "b" / "basin.png").stat().st_size > 0
    lines = (tmp_path / "b" / "basin.csv").read_text().splitlines()
    assert lines[0] == "theta_plus_rad,theta_dot_plus_rad_s,fate,steps,distance_scaled" and len(lines) == 10
    api = Wheel(model="er").basin(grid=3, steps=40).to_dict()
    del out["files"]
    assert api == out


def test_sensitivity_and_mfpt_commands_json_keys():
    out = _json(["sim", "sensitivity", "--json"])
    for d in ("slope", "push"):
        assert {"gsn", "gsn_by_indicator", "simulated", "relative_difference"} <= set(out[d])
    mc = _json(
        ["sim", "mfpt", "--terrain-sd-deg", "3", "--method", "monte-carlo", "--walks", "3", "--cap", "4", "--json"]
    )
    assert {"mfpt_steps", "mfpt_ci_steps", "walks", "cap_steps", "capped_walks"} <= set(mc)
    mesh = _json(
        ["sim", "mfpt", "--terrain-sd-deg", "3", "--nodes-theta", "2", "--nodes-theta-dot", "3", "--slopes", "3"]
        + ["--json"]
    )
    assert {"mfpt_steps", "mfpt_discretisation_error_steps", "lambda2", "fine", "coarse"} <= set(mesh)


@pytest.mark.parametrize(
    "args",
    [
        ["sim", "basin", "--grid", "1"],
        ["sim", "mfpt", "--terrain-sd-deg", "-1"],
        ["sim", "mfpt", "--terrain-sd-deg", "0"],
        ["sim", "mfpt", "--terrain-sd-deg", "2", "--method", "exact"],
        ["sim", "basin", "--theta-min", "-0.5"],
        ["sim", "sensitivity", "--push-rad-s", "0"],
        ["sim", "basin", "--scheduler", "threads"],
        ["sim", "basin", "--scheduler", "sync", "--workers", "2"],
    ],
)
def test_bad_input_is_one_error_line_and_exit_2(args):
    res = RUN.invoke(app, args)
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:")


@pytest.mark.slow
def test_ve_gsn_differs_from_a_one_sided_push_by_the_maps_curvature_not_by_its_jacobian():
    """The VE wheel's one-sided difference at the default push (0.02 rad/s) is about 14 %: it halves with the
    push (a smooth map's O(e) term) and flips sign with it, and the two-sided simulated response, whose
    difference is O(e^2), agrees with the linear norm (a wrong Jacobian would show there)."""
    from rimless.sim import Wheel

    wheel = Wheel(model="ve")
    big, half = (wheel.sensitivity(push_rad_s=e).to_dict()["push"] for e in (0.02, 0.01))
    assert 0.05 < big["relative_difference"]
    assert half["relative_difference"] / big["relative_difference"] == pytest.approx(0.5, abs=0.05)
    assert big["relative_difference_two_sided"] < 0.1 * big["relative_difference"]
    assert half["relative_difference_two_sided"] < big["relative_difference_two_sided"]
