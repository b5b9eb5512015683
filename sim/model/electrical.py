"""The electrical side of the cost of transport: what the clutch and the electronics draw per step.

The ER wheel's clutch is powered while it holds (powered = locked, the paper's clutch): per step it draws
`hold_power_w` for the clutched time (lock at maximum compression to release at the impact) and
`switch_energy_j` per switching event, two per step (one engage, one release). The sensing and computing
draw `electronics_power_w` for the whole step period.

The VE wheel has no clutch, and a passive viscoelastic wheel needs no sensing: by default it draws nothing.
`ve_electronics=True` says that the VE wheel carries the same electronics (a like-for-like comparison of
two robots built on the same board): it then draws `electronics_power_w` for its step period too.

System cost of transport of one period-1 step (model.md section 7 extended):
    system CoT = (M g s_z + E_el) / (M g s_x)
with M the wheel's total mass m_H + 8 m (the eight legs and the hub, whatever the mass model), s_x the
horizontal and s_z the vertical distance the wheel travels in one step (s_z / s_x = tan(phi) on the slope),
and E_el the electrical energy of the step, J. With no electrical power it is the mechanical CoT, tan(phi).

May import: the standard library, rimless.errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypedDict

from rimless.errors import ParameterError

if TYPE_CHECKING:
    from typing_extensions import Unpack

SWITCHES_PER_STEP = 2  # the ER clutch engages once (maximum compression) and releases once (impact) per step

OPTION_OF_FIELD = {
    "hold_power_w": "--clutch-hold-power-w",
    "switch_energy_j": "--clutch-switch-energy-j",
    "electronics_power_w": "--electronics-power-w",
}


class ClutchPowerChanges(TypedDict, total=False):
    """The fields ClutchPower.replace may change."""

    hold_power_w: float
    switch_energy_j: float
    electronics_power_w: float
    ve_electronics: bool


@dataclass(frozen=True)
class ClutchPower:
    """Electrical power of the clutch and the electronics (W, J); all zero by default (the paper's CoT).

    hold_power_w : drawn by the one locked clutch while it holds, W.
    switch_energy_j : drawn per engage or release, J (a bistable clutch: no holding power, only this).
    electronics_power_w : sensing and computing, drawn for the whole step, W.
    ve_electronics : the VE wheel carries the same electronics (else it draws nothing).
    """

    hold_power_w: float = 0.0
    switch_energy_j: float = 0.0
    electronics_power_w: float = 0.0
    ve_electronics: bool = False

    def __post_init__(self) -> None:
        for name, option in OPTION_OF_FIELD.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParameterError(f"{option} must be a number, got {value!r}")
            if not (math.isfinite(value) and value >= 0.0):
                raise ParameterError(f"{option} must be a finite power or energy >= 0, got {value}")

    @property
    def is_zero(self) -> bool:
        """No electrical energy for either wheel: the system CoT is the mechanical one."""
        return self.hold_power_w == 0.0 and self.switch_energy_j == 0.0 and self.electronics_power_w == 0.0

    def replace(self, **changes: Unpack[ClutchPowerChanges]) -> ClutchPower:
        from dataclasses import replace

        return replace(self, **changes)

    def energy_per_step_j(self, model: str, clutched_s: float, period_s: float) -> float:
        """Electrical energy of one step, J: ER P_hold t_clutched + 2 E_switch + P_el T; VE P_el T if it carries
        the electronics, else 0. clutched_s, period_s in s."""
        if model == "er":
            return (
                self.hold_power_w * clutched_s
                + SWITCHES_PER_STEP * self.switch_energy_j
                + self.electronics_power_w * period_s
            )
        if model == "ve":
            return self.electronics_power_w * period_s if self.ve_electronics else 0.0
        raise ValueError(f"unknown model {model!r}")

    def as_dict(self) -> dict[str, float | bool]:
        return {
            "clutch_hold_power_w": self.hold_power_w,
            "clutch_switch_energy_j": self.switch_energy_j,
            "electronics_power_w": self.electronics_power_w,
            "ve_electronics": self.ve_electronics,
        }


def system_cot(total_mass_kg: float, gravity_m_s2: float, s_x_m: float, s_z_m: float, electrical_j: float) -> float:
    """(M g s_z + E_el) / (M g s_x): dimensionless; s_x horizontal, s_z vertical drop per step, m; E_el in J."""
    return (total_mass_kg * gravity_m_s2 * s_z_m + electrical_j) / (total_mass_kg * gravity_m_s2 * s_x_m)
