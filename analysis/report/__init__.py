"""The trials report and the batch jobs of the commands.

`html` (the report: HTML with its figures and CSV metrics, from trials compared with the simulation), `sections`
(the page's metrics tables, a section per input, the wheel's parameters, the provenance table, the CSS),
`figures` (the PNG figures: per trial, every trial's CoM height, step periods per series), `series` (which
trials form a series: step periods are averaged within one, never across), `provenance` (version, command,
date, wheel file, inputs by name and hash; no absolute machine path in what the report writes), `batch`
(``trials import`` into Parquet files, the report run with its progress bar, ``rimless demo``),
`calibration_beside` (the report's calibration of c in a second process while the trials are compared),
`clutch` (the robot log's clutched time per step beside the simulated one).

May import: rimless.analysis.io, kinematics, inference, examples; rimless.output, rimless.progress; numpy,
pandas, matplotlib.
"""
