"""Break-even clutch power against hand-computed cases: branches whose least system CoT is tan(phi_c) + a P
(a closed form standing in for a branch), so the break-even is (tan phi_VE - tan phi_ER) / a, and a difference
inside the location tolerance is a tie, not a number."""

import math
from dataclasses import dataclass

import pytest

from rimless.sim.model.electrical import ClutchPower
from rimless.sim.studies.system_cot import SLOPE_TOL_RAD, break_even


@dataclass
class Linear:
    lo_rad: float
    per_w: float  # d(least system CoT)/d(hold power), 1/W
    lo_tol_rad: float = 1e-10
    label: str = "x"

    def minimise(self, power: ClutchPower) -> dict:
        return {"min_system_cot": math.tan(self.lo_rad) + self.per_w * power.hold_power_w}


def test_a_resolved_break_even_is_the_closed_form_with_its_interval():
    er, ve = Linear(0.0220, 2.0, label="er"), Linear(0.0221, 0.0, label="medium")
    out = break_even([er], [ve], ClutchPower(), "hold_power_w", interval=True)
    gap = math.tan(0.0221) - math.tan(0.0220)
    assert out["value"] == pytest.approx(gap / 2.0, rel=1e-5)
    res = out["cot_resolution"]
    assert res == pytest.approx(2e-10 + SLOPE_TOL_RAD / math.cos(0.0220) ** 2, rel=1e-9)
    assert out["interval"] == pytest.approx([(gap - res) / 2.0, (gap + res) / 2.0], rel=1e-4)
    assert out["tie"] is False


@pytest.mark.parametrize("diff", [-5e-7, 0.0, 5e-7])
def test_a_difference_inside_the_location_tolerance_is_a_tie(diff):
    er, ve = Linear(0.0220, 2.0, label="er"), Linear(0.0220 + diff, 0.0, label="medium")
    out = break_even([er], [ve], ClutchPower(), "hold_power_w", interval=True)
    assert out["tie"] is True and out["value"] is None and "tie" in out["reason"]


def test_er_dearer_beyond_the_tolerance_has_no_break_even():
    er, ve = Linear(0.0233, 2.0, label="er"), Linear(0.0224, 0.0, label="medium")
    out = break_even([er], [ve], ClutchPower(), "hold_power_w")
    assert out["value"] is None and out["tie"] is False and "not below" in out["reason"]
