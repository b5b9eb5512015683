"""The robot's own firmware in the simulator: the controller decides when the simulated legs lock.

`loop` runs the step with the firmware's detector and controller sampling the simulated leg at the robot's
rate, with the guards of rimless.sim.model.guards located by rimless.sim.integrate.events; `ideal` is the
ideal-clutch fixed point every firmware walk starts from; `studies` the firmware fixed point, critical slope and
slope boundaries built on the loop's walks; `config` builds the loop's configuration from the
command's options or a robot.toml; `firmware_gait` the walk, fitted fixed point, critical slope and speed
under the firmware; `sweep` sweeps rate and clutch delay against the ideal clutch (on the sweep runner of
rimless.sim.studies.sweep); `replay` replays a robot trial log against the simulator.

May import: every sim/ folder below it (model .. studies; never cli/); rimless.firmware.control,
rimless.firmware.drivers (fakes), rimless.firmware.service.config and .triallog; rimless.errors,
rimless.output, rimless.values; numpy, scipy.
"""
