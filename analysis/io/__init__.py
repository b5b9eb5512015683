"""Reading and writing trials: Vicon CSV and C3D in, the one time-series type, Parquet trials.

`vicon_file` (the parsed export: sections and columns, SI), `vicon_csv` (the Tracker and Nexus CSV reader,
with `byte_source`), `c3d` (ezc3d), `recording` (either format by its name), `tracker_csv` (the writer),
`timeseries`, `trial` (the trial type and its Parquet storage; `rimless.analysis.kinematics.build` builds it).

May import: numpy, pandas, pyarrow, ezc3d, scipy, rimless.errors. Nothing else of rimless.analysis.
"""
