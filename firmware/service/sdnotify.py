"""systemd's notification protocol without a dependency: one datagram to $NOTIFY_SOCKET (`READY=1`,
`WATCHDOG=1`, `STOPPING=1`, `STATUS=...`). Outside systemd (no socket) every call does nothing."""

from __future__ import annotations

import os
import socket


def notify(message: str) -> bool:
    """Send `message`; True when a socket took it. Never raises."""
    path = os.environ.get("NOTIFY_SOCKET", "")
    if not path:
        return False
    address = "\0" + path[1:] if path.startswith("@") else path
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as s:
            s.settimeout(0.1)
            s.sendto(message.encode(), address)
        return True
    except OSError:
        return False


def watchdog_interval_s() -> float:
    """Half of systemd's `WatchdogSec=` for this process ($WATCHDOG_USEC, $WATCHDOG_PID), or 0 without one."""
    try:
        usec = int(os.environ.get("WATCHDOG_USEC", "0"))
        pid = int(os.environ.get("WATCHDOG_PID", str(os.getpid())))
    except ValueError:
        return 0.0
    if usec <= 0 or pid != os.getpid():
        return 0.0
    return usec * 1e-6 / 2
