"""Following fixed points through a parameter: the critical slope and the ends of gait branches.

`algorithm1` is the paper's Algorithm 1 with the located branch end, `arclength` pseudo-arclength continuation
with special points (folds, flips, stalls) over `oracle` (the map and its Jacobian in one parameter) and
`contact` (the contact and stall facts of a recorded step), `boundary` the two-parameter boundary (critical
slope over k or c), `branches` every period-1 gait at a start slope followed down to its end.

May import: rimless.sim.model, integrate, fast, step; numpy, scipy; rimless.errors.
"""
