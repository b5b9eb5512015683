"""Integrating one continuous phase until a guard of rimless.sim.model.guards fires.

`events` is the one event-location engine (sign change of a guard on a step, root on the dense output,
force-dip check between samples) shared by the reference path, the compiled path and the firmware in the loop;
`reference` integrates with scipy's public `solve_ivp` API; `backend` picks the compiled path when available.

May import: rimless.sim.model, numpy, scipy, rimless.errors. Never step/, continuation/, studies/ or cli/.
"""
