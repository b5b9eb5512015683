"""The running robot: configuration, the asyncio application, logs, signals, the trial log, the fake bench.

`config` (robot.toml, strictly validated), `app` (named tasks, orderly safe shutdown), `safety` (release the
clutches on every catchable signal), `logsetup`, `triallog` (JSON Lines), `bench` (the whole app on fakes).

May import: rimless.firmware.drivers, control, link, errors; the standard library. Never numpy or scipy.
"""
