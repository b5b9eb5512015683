"""The robot's own firmware in the simulator: the controller decides when the simulated legs lock.

`loop` runs the step with the firmware's detector and controller sampling the simulated leg at the robot's
rate, with the guards of rimless.sim.model.guards located by rimless.sim.integrate.events; `sweep` sweeps rate and
clutch delay against the ideal clutch; `replay` replays a robot trial log against the simulator.

May import: every sim/ folder except cli/ and studies/ (the sweep runner of studies.sweep excepted);
rimless.firmware.control and rimless.firmware.drivers (fakes); numpy, scipy.
"""
