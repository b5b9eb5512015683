"""The `parameters` a calibration reports are the calibrated model's (issue 31: "the output never contradicts
itself"). Where the model choice did not support an extra parameter, the calibration's model takes the simpler
fit's values of the others (`calibrate`: ``used.update(row["without"])``); `calibrated_input` used to list the
fit with the extra parameter instead, so `parameters` said c = 5.0 while the model simulated c = 4.2."""

from __future__ import annotations

import math

import numpy as np


def _estimate(value: float, se: float):
    from rimless.analysis.inference.calibrate import ParamEstimate

    return ParamEstimate("c", "damping_ns_per_m", "N s/m", 8.0, value, se, True)


def _result(estimate, calibrated_c: float):
    from rimless.analysis.inference.calibrate import CalibrationResult
    from rimless.sim.model.params import WheelParams

    model = WheelParams(damping_ns_per_m=calibrated_c)
    return CalibrationResult([estimate], np.eye(1), {}, [], 0.02, 5e-4, model)


def _c_entry(win):
    return next(p for p in win.parameters() if p["name"] == "damping_ns_per_m")


def test_parameters_list_the_calibrated_models_value_when_the_simpler_model_was_kept():
    from rimless.analysis.inference.runs import calibrated_input
    from rimless.sim import Wheel

    win = calibrated_input(Wheel().input, _result(_estimate(5.0, 0.3), calibrated_c=4.2))
    c = _c_entry(win)
    assert c["value"] == 4.2 and c["source"] == "fitted" and c["sd"] == 0.3
    assert "did not support" in c["basis"] and "5" in c["basis"]
    assert win.params.damping_ns_per_m == 4.2  # the wheel the later steps use says the same


def test_parameters_list_the_fit_unchanged_when_the_model_is_the_fit():
    from rimless.analysis.inference.runs import calibrated_input
    from rimless.sim import Wheel

    c = _c_entry(calibrated_input(Wheel().input, _result(_estimate(5.0, 0.3), calibrated_c=5.0)))
    assert c["value"] == 5.0 and c["basis"] == "fitted on these trials" and math.isclose(c["sd"], 0.3)
