"""The bundled SYNTHETIC example data and the kinematic wheel used to make test recordings.

`bundled` (six Tracker trials made by the simulator), `critical_series` (twelve trials around the critical
slope from a different truth model), `synthetic` (a kinematic rigid wheel seen by Vicon).

May import: rimless.analysis.io, rimless.sim (to generate), numpy, pandas.
"""
