"""Trials against the model: comparison, calibration, sustained-walk verdicts, the critical slope.

`compare` (CoM height and step periods against the simulation), `calibrate` (least squares on the trials),
`sustained` (a verdict from the measured return map), `critical_slope` (estimates from the verdicts).

May import: rimless.analysis.io, rimless.analysis.kinematics, rimless.sim (model, step, continuation),
numpy, scipy, pandas.
"""
