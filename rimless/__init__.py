"""rimless: the energy-recycling rimless wheel (simulator, firmware, trial analysis).

The package is kept import-light: the robot imports it without numpy, scipy, pandas or matplotlib.
"""

__version__ = "0.1.0"
