"""The trial analysis' public API (re-exported lazily by `rimless.analysis`): `load_trials`, `compare`,
`calibrate`, `critical_slope`, `write_report`, each taking the simulator's `rimless.sim.Wheel`.

Layer: above every other part of `rimless.analysis` except its CLI.

May import: every other layer of `rimless.analysis`, `rimless.sim`'s public API and the
shared root modules; only `rimless.analysis.cli` imports it.
"""
