"""Robot firmware: ADNS-3080 over SPI, zero-velocity clutch control, asyncio loop, telemetry.

Runs on a Raspberry Pi 4B with only the `robot` extra: never imports scipy, pandas or matplotlib.
"""
