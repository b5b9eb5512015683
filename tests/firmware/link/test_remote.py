"""The PC side of the command channel: every failure is one line."""

from __future__ import annotations

import socket
import threading

import pytest

from rimless.firmware.errors import CommandError
from rimless.firmware.link.remote import RobotLink
from tests.support.firmware_app import TOKEN


def test_robot_link_errors_are_one_line(tmp_path) -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    port = s.getsockname()[1]

    def not_a_robot() -> None:
        conn, _ = s.accept()
        conn.sendall(b'{"hello": "something else"}\n')
        conn.close()

    t = threading.Thread(target=not_a_robot)
    t.start()
    with pytest.raises(CommandError, match="not a rimless robot"):
        RobotLink("127.0.0.1", token=TOKEN, port=port, timeout_s=2)
    t.join()
    s.close()


def test_a_robot_of_another_protocol_version_is_a_clear_error_not_a_silent_failure() -> None:
    """A robot of release 0.1 (protocol version 2) greets with version 2: the PC stops there with one line naming
    both versions, before it signs anything."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    port = s.getsockname()[1]

    def old_robot() -> None:
        conn, _ = s.accept()
        conn.sendall(b'{"hello": "rimless-robot", "version": 2, "nonce": "' + b"0" * 32 + b'"}\n')
        conn.recv(100)
        conn.close()

    t = threading.Thread(target=old_robot)
    t.start()
    with pytest.raises(CommandError, match=r"speaks protocol version 2, this PC version 3") as err:
        RobotLink("127.0.0.1", token=TOKEN, port=port, timeout_s=2)
    t.join()
    s.close()
    assert "\n" not in str(err.value)
