"""Integrating one continuous phase until a guard of rimless.sim.model.guards fires.

`events` is the one event-location engine (sign change of a guard on a step, root on the dense output,
force-dip search between step ends), called step by step by the reference integrator and the firmware in
the loop; the compiled path (rimless.sim.fast.rk) is its numba twin with the same codes, directions and dip
constants. `reference` integrates with scipy's public ODE solver classes (DOP853 by default); `backend`
picks the compiled integrator when it is available (the map on it is built in rimless.sim.step.backend).
`friction` runs one phase of a wheel with guide friction as its stick/slip sub-phases on either integrator.

May import: rimless.sim.model, rimless.sim.fast (backend only, lazily: the same layer), numpy, scipy,
rimless.errors. Never step/, continuation/, studies/, in_the_loop/ or cli/.
"""
