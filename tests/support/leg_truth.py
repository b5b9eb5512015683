"""The independent truth model of the leg test, for the tests of `rimless trials leg-fit` and the leg-test priors:
`rimless.analysis.validation.leg_truth` (it lives in the library because `rimless trials leg-fit-coverage` runs the
same model; it shares no code with the fit or with the firmware's fake leg)."""

from rimless.analysis.validation.leg_truth import LegTruth, free_motion, position, read_times, write_log

__all__ = ["LegTruth", "free_motion", "position", "read_times", "write_log"]
