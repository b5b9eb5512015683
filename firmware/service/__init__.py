"""The running robot: configuration, hardware assembly, the asyncio application, the commands' library calls.

`config` (robot.toml, strictly validated), `hardware` (the one place that picks the real Pi or the fakes
and wires sensors to detectors), `app` (named tasks, orderly safe shutdown), `runner` (`robot run`: the app
with its fail-safes and exit code), `selftest` (`robot check`), `bench` (the whole app on fakes, timed),
`safety` (release the clutches on every catchable signal), `logsetup`, `triallog` (JSON Lines).

May import: rimless.firmware.drivers, control, link, errors; the standard library. Never numpy or scipy.
"""
