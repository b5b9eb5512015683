"""The command protocol: the MAC, the token rule, message validation before anything is acted on."""

from __future__ import annotations

import pytest

from rimless.firmware.service.app import RobotApp
from rimless.firmware.link.protocol import WeakToken, check_token, command_mac, parse_command, Rejected
from rimless.firmware.service.config import CommandsConfig, RobotConfig
from tests.support.firmware_app import TOKEN


def test_mac_is_hmac_sha256_of_nonce_and_canonical_command() -> None:
    import hashlib
    import hmac

    # Hand-built expectation: key = token, message = nonce, newline, canonical JSON of [seq, cmd, args].
    want = hmac.new(b"k" * 20, b'abc\n[7,"set",{"name":"x","value":-3}]', hashlib.sha256).hexdigest()
    assert command_mac("k" * 20, "abc", 7, "set", {"value": -3, "name": "x"}) == want


def test_weak_tokens_are_refused() -> None:
    for weak in ("change-me", "s3cret", "short-token", "aaaaaaaaaaaaaaaaaaaa", "abababababababababab"):
        with pytest.raises(WeakToken):
            check_token(weak)
    assert check_token("x7Gq-2mPz_9LrT4vB1nK") == "x7Gq-2mPz_9LrT4vB1nK"
    with pytest.raises(WeakToken):
        RobotApp(RobotConfig(commands=CommandsConfig(token="change-me")), hw=None)  # type: ignore[arg-type]


def test_parse_refuses_surrogates_and_depth_directly() -> None:
    with pytest.raises(Rejected, match="surrogate"):
        parse_command(b'{"seq": 1, "cmd": "\\ud800", "args": {}, "mac": ""}', TOKEN, "n", None)
    with pytest.raises(Rejected, match="nested"):
        parse_command(b"[" * 2000, TOKEN, "n", None)
