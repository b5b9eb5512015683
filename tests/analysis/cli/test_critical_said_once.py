"""The critical slope's printed lines say each thing once, and say why two numbers differ (issue 31: "the output
never contradicts itself").

On main `rimless demo` printed c's "cannot be told from a constant loss per step" sentence twice (inside
"calibrated c:" and again on the next line), and "model critical slope, ER: 1.263 deg" followed, lines later, by
an interval "centred on 1.328 deg" with no word on why. The centre is the held parameters' carried mean shift
(`rimless.analysis.inference.held.carry_rows`: c and F_c carried as their normals truncated at 0); the expected
shift here is computed from the closed-form half-normal mean sqrt(2/pi) (Johnson, Kotz and Balakrishnan) and the
rows' one-sided changes, apart from the code under test.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

from rimless.analysis.cli.critical import critical_lines, held_lines

SEP = (
    "c cannot be told from a constant loss per step such as guide friction: the trials' effective leg speeds span "
    "0.164-0.196 m/s"
)
F_C_PLUS_DEG = 0.066  # the model's critical slope at F_c = +1 sd (0.2 N) minus at 0, a one-sided change
C_SHIFT_DEG = 0.012  # c = 8 +- 4: its truncation at 0 moves its mean a little (given as the row's shift)


def _models() -> dict:
    f_c_shift = math.sqrt(2.0 / math.pi) * F_C_PLUS_DEG  # the half-normal's mean, in sd
    return {
        "er": {
            "critical_slope_deg": 1.263,
            "critical_slope_with_held_deg": 1.263 + f_c_shift + C_SHIFT_DEG,
            "held_shift_deg": f_c_shift + C_SHIFT_DEG,
            "se_parameters_deg": 0.22,
            "ci_deg": [0.895, 1.761],
            "complete": True,
            "contributions": [
                {"symbol": "c", "contribution_deg": 0.215, "shift_deg": C_SHIFT_DEG},
                {"symbol": "F_c", "contribution_deg": 0.040, "shift_deg": f_c_shift},
                {"symbol": "k", "contribution_deg": 0.022, "shift_deg": 0.0},
            ],
        }
    }


def _summary() -> dict:
    return {
        "parameters": [
            {"symbol": "c", "value": 8.0, "sd": 4.0, "unit": "N s/m", "source": "table1", "basis": "assumed"},
            {"symbol": "F_c", "value": 0.0, "sd": 0.2, "unit": "N", "source": "table1", "basis": "assumed"},
        ],
        "warnings": [],
        "parameter_uncertainty": {"method": "finite differences", "trials": None, "models": _models()},
    }


def _result() -> SimpleNamespace:
    chosen = SimpleNamespace(value_deg=1.545, method="fixed-point-extrapolation", ci_deg=(1.532, 1.559))
    cr = SimpleNamespace(
        chosen=chosen,
        bracket_deg=(1.422, 1.595),
        why="",
        model={"critical_slope_deg": {"er": 1.263, "er_calibrated": 1.538}},
        held_summary=_summary,
    )
    c = SimpleNamespace(
        name="c",
        value=13.008,
        se=0.073,
        unit="N s/m",
        table1=8.0,
        identifiable=False,
        note=f"effective only: the model does NOT fit the trials; {SEP}; the fitted c is an effective loss",
    )
    cal = SimpleNamespace(params=[c], loss_separation={"note": SEP})
    return SimpleNamespace(critical=cr, calibration=cal)


def test_the_demo_lines_say_the_loss_sentence_once():
    text = critical_lines(_result())
    assert text.count(SEP) == 1, text
    assert "calibrated c: 13.008" in text


def test_the_model_slope_and_its_interval_centre_are_both_given_once_with_why():
    text = critical_lines(_result())
    centre = 1.263 + math.sqrt(2.0 / math.pi) * F_C_PLUS_DEG + C_SHIFT_DEG  # 1.327
    assert text.count("1.263 deg") == 1 and text.count(f"{centre:.3f} deg") == 1, text
    line = next(ln for ln in text.splitlines() if f"{centre:.3f}" in ln)
    assert line.startswith("model critical slope, ER: 1.263 deg at the held values"), line
    # why: the parameters whose truncation shifts it, each with its part
    assert "truncated at their bound 0" in line and f"{centre - 1.263:+.3f} deg" in line
    assert "F_c = 0 ± 0.2 N +0.053 deg" in line and "c = 8 ± 4 N s/m +0.012 deg" in line
    assert "k = " not in line.split("(largest")[1].split(")")[1]  # a parameter without shift is not named for it
    assert "model critical slope, ER with c calibrated on these trials" in text  # the fitted one still there


def test_the_critical_slope_command_lines_give_the_centre_with_why():
    lines = held_lines(_summary())
    model = [ln for ln in lines if ln.startswith("model ER")]
    assert len(model) == 1 and "1.263 deg at the held values" in model[0] and "not on 1.263" in model[0]
    assert "F_c = 0 ± 0.2 N" in model[0]
