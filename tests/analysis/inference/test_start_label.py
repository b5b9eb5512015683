"""The calibration's start at the wheel's stated values is called "Table 1" only when those values are Table 1's
(session 21's audit: a wheel file stating c = 12, k = 2200 N/m had its start, the text's column and the residual
table all called "Table 1")."""

from __future__ import annotations

from rimless.analysis.cli.critical import start_name
from rimless.analysis.inference.calibrate import _Globals
from rimless.sim.model.params import WheelParams


def test_the_start_at_table1_is_called_table1_and_another_wheel_is_not() -> None:
    assert _Globals.of(WheelParams(), ["c", "k"]).start_label == "Table 1"
    stated = WheelParams().replace(damping_ns_per_m=12.0, stiffness_n_per_m=2200.0)
    assert _Globals.of(stated, ["c", "k"]).start_label == "the wheel's values"
    # a wheel that differs only in what is not fitted starts from Table 1's values of what is
    assert _Globals.of(WheelParams().replace(hub_mass_kg=2.1), ["c"]).start_label == "Table 1"


def test_the_text_names_its_comparison_column_after_the_start() -> None:
    t1 = WheelParams()
    rows = [{"name": "c", "table1": t1.damping_ns_per_m}, {"name": "k", "table1": t1.stiffness_n_per_m}]
    assert start_name(rows) == "Table 1"
    assert start_name([rows[0], {"name": "k", "table1": 2200.0}]) == "wheel"
