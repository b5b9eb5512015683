"""Numeric code generated from the symbolic derivation (see rimless.sim.model.derive)."""
