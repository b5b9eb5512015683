"""The studies behind `sim fixed-point`, `gaits` and `critical-slope`, called as library functions: their
results checked against the reference path (scipy solve_ivp) and the definitions, their errors as
ParameterError / RunFailure (never an exit)."""

import numpy as np
import pytest

from rimless.errors import ParameterError, RunFailure
from rimless.sim.model.params import WheelParams
from rimless.sim.step.backend import make_map
from rimless.sim.studies.gaits import critical_slope_study, fixed_point_study, gait_scan, guess_from_options


def test_the_fixed_point_is_a_fixed_point_of_the_reference_map():
    p = WheelParams()
    out = fixed_point_study(p, "er", backend="fast")
    z = np.array([out["theta_plus_rad"], out["theta_dot_plus_rad_s"]])
    ref = make_map(p, "er", backend="reference", rtol=1e-10)
    assert np.max(np.abs(ref(z) - z)) < 1e-6  # the compiled path's fixed point, checked on the other path
    lam = [complex(re, im) for re, im in out["eigenvalues"]]
    assert out["max_abs_eigenvalue"] == pytest.approx(max(abs(v) for v in lam))
    assert out["stable"] is (out["max_abs_eigenvalue"] < 1)


def test_every_gait_the_scan_lists_is_a_fixed_point():
    p = WheelParams()
    out = gait_scan(p, "ve", guesses=6, backend="fast")
    assert out["gaits"] and out["model"] == "ve" and out["k"] == p.k
    pmap = make_map(p, "ve", backend="fast")
    for g in out["gaits"]:
        if g["contact_model"] == "unilateral":
            z = np.array([g["theta_plus_rad"], g["theta_dot_plus_rad_s"]])
            assert np.max(np.abs(pmap(z) - z)) < 1e-8


def test_the_rigid_critical_slope_is_coleman_s_closed_form():
    """tan(phi_c) is the cost of transport, and the eigenvalue is beta^2 of the closed form."""
    out = critical_slope_study(WheelParams(), "rigid")
    assert out["cot"] == pytest.approx(np.tan(out["critical_slope_rad"]), rel=1e-12)
    assert out["eigenvalue"] == pytest.approx(out["beta"] ** 2, rel=1e-12)


@pytest.mark.parametrize(
    ("call", "option"),
    [
        (lambda: guess_from_options(WheelParams(), "er", -1.0), "--theta-dot-guess"),
        (lambda: guess_from_options(WheelParams(), "er", None, 0.3), "--theta-plus-guess"),
        (lambda: gait_scan(WheelParams(), "ve", theta_dot_min=3.0, theta_dot_max=2.0), "--theta-dot-min"),
        (lambda: critical_slope_study(WheelParams(), "er", start_slope_rad=0.5), "--start-slope-rad"),
        (lambda: fixed_point_study(WheelParams(), "er", gait=1, theta_dot_guess=2.0), "--gait"),
    ],
)
def test_bad_inputs_are_parameter_errors_naming_the_option(call, option):
    with pytest.raises(ParameterError, match=option):
        call()


def test_a_gait_number_beyond_the_scan_is_an_error_and_no_gait_a_run_failure():
    with pytest.raises(ParameterError, match="--gait 99"):
        fixed_point_study(WheelParams(), "er", gait=99)
    with pytest.raises(RunFailure, match="no period-1 gait"):  # far below the critical slope (about 1.26 deg)
        fixed_point_study(WheelParams(slope_rad=0.002), "er")
