import math

import pytest

from rimless.errors import ParameterError
from rimless.sim.model.params import WheelParams, load_params


def test_defaults_are_table_1():
    p = WheelParams()
    assert (p.hub_mass_kg, p.leg_mass_kg, p.inertia_kg_m2, p.leg_length_m) == (1.892, 0.0378, 0.036, 0.237)
    assert (p.k, p.c, p.slope_rad, p.gravity_m_s2) == (2700.0, 8.0, 0.05, 9.81)
    assert p.mass_model == "eight-leg"


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"hub_mass_kg": -1.0}, "hub_mass_kg"),
        ({"leg_mass_kg": 0.0}, "leg_mass_kg"),
        ({"stiffness_n_per_m": 0.0}, "--k"),
        ({"damping_ns_per_m": -0.1}, "--c"),
        ({"slope_rad": math.pi / 8}, "slope_rad"),
        ({"slope_rad": -0.01}, "slope_rad"),
        ({"inertia_kg_m2": float("nan")}, "inertia_kg_m2"),
        ({"leg_length_m": float("inf")}, "leg_length_m"),
        ({"mass_model": "two-leg"}, "mass_model"),
    ],
)
def test_bad_parameters_name_the_parameter(change, named):
    with pytest.raises(ParameterError, match=named):
        WheelParams(**change)


def test_toml_file_with_paper_symbols_and_degrees(tmp_path):
    f = tmp_path / "p.toml"
    f.write_text("[wheel]\nk = 3000\nc = 0\nslope_deg = 1.5\nm_H = 2.0\n")
    p = load_params(f)
    assert p.k == 3000 and p.c == 0 and p.hub_mass_kg == 2.0
    assert p.slope_rad == pytest.approx(math.radians(1.5), rel=1e-15)


def test_toml_errors_name_the_file_and_key(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("kk = 3\n")
    with pytest.raises(ParameterError, match=r"unknown parameter 'kk' in .*bad.toml"):
        load_params(f)
    f.write_text("k = [\n")
    with pytest.raises(Exception, match="bad.toml: not valid TOML"):
        load_params(f)
    with pytest.raises(Exception, match="cannot read parameter file"):
        load_params(tmp_path / "missing.toml")
