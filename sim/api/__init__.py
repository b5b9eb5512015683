"""The simulator's public API (re-exported lazily by `rimless.sim`): `Wheel`, its result objects, `sweep`.

Layer: above every other part of `rimless.sim` except its CLI (which calls it); imports stay inside functions
where they are heavy, so `import rimless.sim` stays light.

May import: every other layer of `rimless.sim` (it is the front door over them) and the
shared root modules; only `rimless.sim.cli` imports it.
"""
