"""What the markers say about the wheel, and a trial built from it.

`source` (which object is the wheel; a static ramp), `hub` (hub and wheel angle), `hub_offset` (the hub's offset
from the tracked point, from the height, and its standard error), `slope` (slope frame and
CoM height), `steps` (impacts), `walk` (walking window and how the trial ended), `build` (a
`rimless.analysis.io.trial.Trial` from a parsed export: all of the above in order), `bench_import` (times
the parse and the import against plain pandas).

May import: rimless.analysis.io (the parsed export, the time-series and trial types), numpy, pandas, scipy,
rimless.errors.
"""
