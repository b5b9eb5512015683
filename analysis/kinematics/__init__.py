"""What the markers say about the wheel: which object it is, its hub and angle, the slope, steps, the walk.

`source` (which object is the wheel; a static ramp), `hub` (hub and wheel angle), `slope` (slope frame and
CoM height), `steps` (impacts), `walk` (walking window and how the trial ended).

May import: rimless.analysis.io (the time-series type), numpy, pandas, scipy, rimless.errors.
"""
