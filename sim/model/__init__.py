"""The wheel model itself: parameters, mechanics, generated equations, guards, impact, section, clutch.

What lives here is the physics of `../shared/docs/model.md`, independent of how it is integrated:
`params` (Table 1, validated), `derive` (sympy) and `generated/` (its numeric output), `mechanics` (M, h and
Jacobians of one mass model), `dynamics` (the constrained phase dynamics), `guards` (the one guard table:
every event that ends a phase, with its code, direction and failure class), `impact`, `section`
(z <-> full post-impact state), `clutch` (real-clutch constraint sets), `friction` (Coulomb friction in the
leg guides: stick/slip phases on the clutch's constraint sets, beyond the paper), `rigid` (closed form),
`failures`, `uncertain` (each parameter's uncertainty and source: the wheel file).

May import: the standard library, numpy, sympy (derive only), rimless.errors. Nothing else of rimless.
"""
