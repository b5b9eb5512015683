"""The LAN: the authenticated TCP command channel, UDP telemetry, and their PC sides.

`commands` (robot side of the commands), `telemetry` (batched JSON over UDP), `heartbeat` and `listen`
(PC side: keep the link alive, record and show telemetry).

May import: rimless.firmware.control (fault codes), rimless.firmware.errors, the standard library.
"""
