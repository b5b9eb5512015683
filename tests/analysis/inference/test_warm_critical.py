"""The held parameters carried into the model's critical slope, warm-started (`held.WarmCritical`), against the
straightforward runs (`model_critical_slope` at each perturbed wheel, Algorithm 1 from 0.05 rad): the same
sensitivities to the root location (`held.REFINE_TOL_RAD`), on a wheel away from Table 1.

The reference is the straightforward path itself, run here beside the fast one; the wheel (heavier hub, longer
and heavier legs, stiffer, less damped than Table 1) and its uncertainties are made up for the test.
"""

from __future__ import annotations

import math

import pytest

from rimless.analysis.inference.critical_slope import CriticalSlopeResult, model_critical_slope
from rimless.analysis.inference.held import REFINE_TOL_RAD, WarmCritical, carry_critical
from rimless.sim.model.params import WheelParams
from rimless.sim.model.uncertain import wheel_input_from

WHEEL = WheelParams(
    hub_mass_kg=2.3,
    leg_mass_kg=0.05,
    inertia_kg_m2=0.05,
    leg_length_m=0.25,
    stiffness_n_per_m=3500.0,
    damping_ns_per_m=5.0,
)
TOL_DEG = math.degrees(REFINE_TOL_RAD)
#: held with these sds (the rest exact): m_H, I_c and k move the end a little, c most, F_c > 0 runs the
#: map phase by phase (guide friction) and is one-sided at F_c = 0
HELD = {"m_H": 0.1, "m": 0.0, "I_c": 0.008, "L0": 0.0, "k": 400.0, "c": 2.0, "F_c": 0.2}


@pytest.fixture(scope="module")
def nominal():
    out = model_critical_slope(WHEEL, "er")
    assert out["reason"] == "stall" and 0.5 < out["critical_slope_deg"] < 2.0, out
    return out["critical_slope_deg"]


def _carried(nominal_deg: float, sd: dict[str, float], warm: bool) -> dict:
    res = CriticalSlopeResult([], None, [], None, "no trials: the model's part only")
    res.model = {"critical_slope_deg": {"er": nominal_deg}, "detail": {}}
    return carry_critical(res, [], [], wheel_input_from(WHEEL, sd), models=("er",), warm=warm)["models"]["er"]


def test_warm_started_carry_agrees_with_the_straightforward_one(nominal):
    fast = _carried(nominal, HELD, warm=True)
    slow = _carried(nominal, HELD, warm=False)
    assert fast["differences"] == slow["differences"] == "central"
    assert [r["symbol"] for r in fast["contributions"]] == ["m_H", "I_c", "k", "c", "F_c"]
    for f, s in zip(fast["contributions"], slow["contributions"]):
        assert f["note"] == s["note"], (f, s)
        for key in ("plus_deg", "minus_deg"):
            if s[key] is None:
                assert f[key] is None, (key, f)
            else:
                assert f[key] == pytest.approx(s[key], abs=TOL_DEG), (key, f, s)
        assert f["contribution_deg"] == pytest.approx(s["contribution_deg"], abs=TOL_DEG)
        assert s["contribution_deg"] > 10 * TOL_DEG  # each moves the end by more than the tolerance
    assert fast["se_parameters_deg"] == pytest.approx(slow["se_parameters_deg"], abs=TOL_DEG)
    assert fast["complete"] and slow["complete"]
    # the one-sided F_c: F_c - sd < 0 is not a wheel
    assert fast["contributions"][-1]["note"] == "one-sided"


def test_every_run_is_warm_near_the_nominal_wheel(nominal):
    f = WarmCritical(WHEEL, "er", nominal)
    assert f.start is not None
    start_deg = math.degrees(f.start[0])
    assert nominal + 0.5 <= start_deg < math.degrees(0.05)
    near = WHEEL.replace(inertia_kg_m2=0.052)
    assert f(near) == pytest.approx(model_critical_slope(near, "er")["critical_slope_deg"], abs=TOL_DEG)
    assert (f.warm, f.straightforward) == (1, 0)


def test_a_wheel_whose_critical_slope_is_above_the_warm_start_is_run_straightforwardly(nominal):
    f = WarmCritical(WHEEL, "er", nominal)
    damped = WHEEL.replace(damping_ns_per_m=25.0)  # its branch ends above the nominal branch's start point
    slow = model_critical_slope(damped, "er")["critical_slope_deg"]
    assert slow > math.degrees(f.start[0])
    assert f(damped) == slow  # the straightforward run itself
    assert (f.warm, f.straightforward) == (0, 1)


def test_a_nominal_trace_that_disagrees_with_the_known_value_turns_the_warm_start_off(nominal):
    f = WarmCritical(WHEEL, "er", nominal + 0.01)  # not this wheel's critical slope
    assert f.start is None
    near = WHEEL.replace(hub_mass_kg=2.35)
    assert f(near) == model_critical_slope(near, "er")["critical_slope_deg"]
    assert (f.warm, f.straightforward) == (0, 1)


def test_the_benchmark_prints_both_paths_their_ratio_and_difference(tmp_path, capsys):
    from rimless.analysis.bench.carry import main

    wheel = tmp_path / "wheel.toml"  # plain numbers are exact: only I_c is held
    wheel.write_text(
        "[wheel]\nm_H = 2.3\nm = 0.05\nL0 = 0.25\nk = 3500.0\nc = 5.0\nF_c = 0.0\nI_c = {value = 0.05, sd = 0.008}\n",
        encoding="utf-8",
    )
    main(["--params", str(wheel), "--central"])
    out = capsys.readouterr().out
    assert "straightforward:" in out and "warm:" in out and "ratio (CPU):" in out
    diff = float(out.split("largest difference of a perturbed critical slope:")[1].split("deg")[0])
    assert diff <= TOL_DEG
