"""The simulator's public API (re-exported lazily by `rimless.sim`): `Wheel`, its result objects, `sweep`.

Layer: above every other part of `rimless.sim` except its CLI (which calls it); imports stay inside functions
where they are heavy, so `import rimless.sim` stays light.
"""
