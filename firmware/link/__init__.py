"""The LAN: the authenticated TCP command channel, UDP telemetry, and their PC sides.

`protocol` (wire format, MACs, token rule, message validation: shared by both sides), `commands` (the
robot's command server and reserved UDP path), `remote` (PC side of the commands), `telemetry` (batched
JSON over UDP), `heartbeat` and `listen` (PC side: keep the link alive, record and show telemetry).

May import: rimless.firmware.control (records, fault codes), rimless.firmware.errors, the standard library.
"""
