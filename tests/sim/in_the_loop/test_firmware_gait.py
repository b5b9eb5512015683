"""The firmware-in-the-loop studies called as library functions: errors are ParameterError / RunFailure
(the command turns them into exit 2 / 1), and the configuration comes from the options or a robot.toml."""

import pytest

from rimless.errors import ParameterError, RunFailure
from rimless.sim.in_the_loop.config import build_config
from rimless.sim.in_the_loop.firmware_gait import firmware_critical, firmware_gait
from rimless.sim.model.params import WheelParams

OPTIONS = dict(
    rate_hz=300.0,
    clutch_delay_ms=5.0,
    release_delay_ms=None,
    noise_counts=1.0,
    jitter_ms=0.05,
    holding_force_n=100.0,
    seed=0,
)


def test_the_config_is_in_si_and_the_release_delay_follows_the_engage_delay():
    cfg = build_config(**OPTIONS)
    assert cfg.engage_delay_s == cfg.release_delay_s == pytest.approx(5e-3) and cfg.jitter_s == pytest.approx(5e-5)
    with pytest.raises(ParameterError, match="--holding-force-n"):
        build_config(**{**OPTIONS, "holding_force_n": 0.0})


def test_no_ideal_gait_to_start_from_is_a_run_failure():
    with pytest.raises(RunFailure, match="no ideal-clutch ER gait"):
        firmware_gait(WheelParams(slope_rad=0.002), build_config(**OPTIONS), steps=6, backend="fast", rtol=1e-10)


def test_the_critical_slope_checks_its_low_end_before_any_walk():
    p = WheelParams()
    with pytest.raises(ParameterError, match="--critical-low-deg"):
        firmware_critical(p, build_config(**OPTIONS), steps=6, low_deg=p.slope_deg, tol_deg=0.05)
