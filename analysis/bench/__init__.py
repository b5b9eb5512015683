"""Benchmarks of the trial methods: each runs a fast path and its reference side by side in one run and prints
the ratio (from CPU time) and the difference between their results.

A reference algorithm kept only to be compared lives here, not in the method's module.

May import: rimless.analysis.io, kinematics, inference; rimless.sim; numpy, scipy.
"""
