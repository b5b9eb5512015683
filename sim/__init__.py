"""The hybrid simulator of the rigid, viscoelastic and energy-recycling rimless wheels.

Import-light: numpy/scipy are imported by the modules that need them, not here.
"""
