"""Classified failures of a step: every step is either valid or ends with one of these reasons."""

from __future__ import annotations

from enum import Enum

from rimless.errors import RimlessError


class FailureReason(str, Enum):
    """Why a step (or a gait) is not a valid period-1 walking step (model.md section 4)."""

    STALL = "stall"  # theta' reached 0 before touchdown: the wheel rolls back
    STANCE_LIFT_OFF = "stance-lift-off"  # lambda_b,y < 0 in single support
    TOUCHDOWN_BEFORE_CLUTCH = "touchdown-before-clutch-lock"  # ER: swing foot landed during free compression
    CLUTCH_MISSED = "compression-peak-in-double-support"  # ER: L1' already >= 0 at lift-off, nothing to lock
    DLSP_NEVER_ENDS = "dlsp-never-ends"  # double support reached the time limit or the swing foot landed in it
    NEGATIVE_IMPULSE = "negative-impulse"  # a normal impact impulse <= 0: the foot would not stay down
    LEADING_FOOT_TENSION = "leading-foot-tension"  # --strict-contact: lambda_b,y < 0 in double support
    TRAILING_FOOT_BELOW = "trailing-foot-below-slope"  # --strict-contact: the lifted foot dips below y = 0
    INTEGRATION = "integration-failure"  # the integrator gave up
    NO_CONVERGENCE = "no-convergence"  # the fixed-point solver did not converge


class StepFailure(RimlessError):
    """A step that ends with a classified reason instead of a valid touchdown."""

    def __init__(self, reason: FailureReason, message: str, *, time_s: float = float("nan"), phase: str = "") -> None:
        self.reason = reason
        self.time_s = time_s
        self.phase = phase
        where = f" in {phase}" if phase else ""
        at = f" at t = {time_s:.6f} s" if time_s == time_s else ""
        super().__init__(f"{reason.value}{where}{at}: {message}")
