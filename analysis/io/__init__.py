"""Reading and writing trials: Vicon CSV and C3D in, the one time-series type, Parquet trials.

`vicon_csv` (Tracker and Nexus exports), `c3d` (ezc3d), `timeseries`, `trial` (a trial built from an export
and stored as Parquet), `bench_import` (our parser against plain pandas, in one run).

May import: numpy, pandas, pyarrow, ezc3d, rimless.errors, rimless.analysis.kinematics (trial building only).
"""
