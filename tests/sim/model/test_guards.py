"""The one guard table (rimless.sim.model.guards): one row per code, and the step's guards and the clutch
modes' guards are the same functions where the constraint sets agree."""

import numpy as np
import pytest

from rimless.sim.model import guards as ev
from rimless.sim.model.clutch import Mode
from rimless.sim.model.dynamics import DLSP, SLSP_FREE
from rimless.sim.model.failures import FailureReason
from rimless.sim.model.mechanics import Mechanics
from rimless.sim.model.params import WheelParams
from tests.support.sim_states import random_states

GUARD_NAMES = (
    "LIFTOFF_A",
    "STALL",
    "CLUTCH_LOCK",
    "TOUCHDOWN",
    "LIFTOFF_B",
    "FOOT_A_DOWN",
    "SLIP_END_1",
    "SLIP_END_2",
    "STICK_END_1",
    "STICK_END_2",
)


def test_the_table_has_one_row_per_code() -> None:
    codes = [getattr(ev, name) for name in GUARD_NAMES]
    assert sorted(codes) == sorted(ev.TABLE) and len(set(codes)) == len(codes)
    for code, row in ev.TABLE.items():
        assert row.code == code and row.direction in (-1, +1)
        assert ev.GUARD_NAMES[code] == row.name
    assert set(ev.FORCE_GUARDS) == {ev.LIFTOFF_A, ev.LIFTOFF_B}
    assert ev.FAILURE == {ev.STALL: FailureReason.STALL, ev.LIFTOFF_B: FailureReason.STANCE_LIFT_OFF}


@pytest.mark.parametrize(
    ("phase", "mode", "codes"),
    [
        (DLSP, Mode(foot_a=True), (ev.LIFTOFF_A, ev.STALL, ev.TOUCHDOWN)),
        (SLSP_FREE, Mode(foot_a=False), (ev.LIFTOFF_B, ev.STALL, ev.TOUCHDOWN)),
    ],
)
def test_a_free_clutch_mode_has_the_guards_of_its_phase(phase: int, mode: Mode, codes: tuple[int, ...]) -> None:
    """Both feet down with free legs is double support, foot b alone single support: same guard values."""
    mech = Mechanics.of(WheelParams())
    rng = np.random.default_rng(3)
    for q, qd in random_states(rng, 20):
        y = np.concatenate((q, qd))
        for code in codes:
            assert ev.mode_guard_value(mech, mode, code, y, 100.0) == pytest.approx(
                ev.guard_value(mech, phase, code, y), rel=1e-9, abs=1e-9
            )
