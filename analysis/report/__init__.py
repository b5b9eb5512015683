"""The trials report and the batch jobs of the commands.

`html` (the report: HTML with its figures and CSV metrics, from trials compared with the simulation), `batch`
(``trials import`` into Parquet files, the report run with its progress bar, ``rimless demo``),
`calibration_beside` (the report's calibration of c in a second process while the trials are compared).

May import: rimless.analysis.io, kinematics, inference, examples; rimless.output, rimless.progress; numpy,
pandas, matplotlib.
"""
