"""One step of the hybrid system and the Poincaré map built on it.

`hybrid` runs the phase sequence of the ER or VE wheel and the impact, `poincare` the map on the
post-impact section with its fixed points and stability, `fast_map` the same map on the compiled path
(rimless.sim.fast), `backend` the map on the path a command asks for (`--backend`), `gait` several steps
with their trajectory (the plain-dict summaries commands print live in rimless.sim.studies.summary).

May import: rimless.sim.model, rimless.sim.integrate, rimless.sim.fast, numpy, scipy, rimless.errors.
"""
