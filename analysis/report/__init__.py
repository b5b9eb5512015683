"""The trials report: HTML with its figures, CSV metrics, from trials compared with the simulation.

May import: rimless.analysis.io, kinematics, inference; rimless.output; numpy, pandas, matplotlib.
"""
