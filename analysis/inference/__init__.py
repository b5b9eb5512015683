"""Trials against the model: comparison, calibration, sustained-walk verdicts, the critical slope.

`compare` (CoM height and step periods against the simulation), `calibrate` (least squares on the trials),
`sustained` (a verdict from the measured return map), `critical_slope` (estimates from the verdicts), `runs`
(the critical-slope and calibration runs behind the commands: load, fit, estimate, summarise), `background`
(one function in a second process, e.g. the report's calibration beside its comparisons).

May import: rimless.analysis.io, rimless.analysis.kinematics, rimless.sim (model, step, continuation),
rimless.progress, numpy, scipy, pandas.
"""
