"""Validation of the trial methods: truth models written apart from them, and the coverage studies that feed
their data to the methods and count how often the stated intervals hold.

Nothing here is a method a user's result comes from: it checks `rimless.analysis.inference` (and the importer,
`rimless.analysis.kinematics`) against wheels and labs it was not fitted with.

May import: rimless.analysis.io, kinematics, inference, examples; rimless.sim (truth dynamics);
rimless.progress; numpy, scipy, pandas.
"""
