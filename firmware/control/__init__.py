"""The control path: sensor health, zero-velocity detection, the stance-leg state machine, the sampler.

`faults` (fault codes and per-sample checks), `detector` (zero-velocity and leg sequence; its parameters in
`detector_params`), `controller` (read, check, detect, switch the clutches), `sampler` (the steady-rate thread on
absolute deadlines).

May import: rimless.firmware.drivers, rimless.firmware.errors, the standard library. Never numpy or scipy.
"""
