"""The command protocol: the MAC, the token rule, message validation before anything is acted on."""

from __future__ import annotations

import pytest

from rimless.firmware.link.protocol import Rejected, WeakToken, check_token, command_mac, parse_command
from rimless.firmware.service.app import RobotApp
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
    import secrets

    fresh = secrets.token_urlsafe(18)
    assert check_token(fresh) == fresh
    with pytest.raises(WeakToken):
        RobotApp(RobotConfig(commands=CommandsConfig(token="change-me")), hw=None)  # type: ignore[arg-type]


def test_parse_refuses_surrogates_and_depth_directly() -> None:
    with pytest.raises(Rejected, match="surrogate"):
        parse_command(b'{"seq": 1, "cmd": "\\ud800", "args": {}, "mac": ""}', TOKEN, "n", None)
    with pytest.raises(Rejected, match="nested"):
        parse_command(b"[" * 2000, TOKEN, "n", None)


def test_dictionary_like_published_and_repeated_tokens_are_refused() -> None:
    """Fails on today's main: `passwordpassword` and the tokens published in the tests were accepted."""
    import secrets

    for weak in (
        "passwordpassword",
        "Password12345678",
        "qwertyuiopasdfgh",
        "robotrobot1234567890",
        "test-token-7f3a9c2e1b5d",
        "cli-test-token-5e8d1f0a9b",
        "signal-test-token-3c9e7a1f",
        "x7Gq-2mPz_9LrT4vB1nK",
        "Token1234Token1234",
    ):
        with pytest.raises(WeakToken):
            check_token(weak)
    for _ in range(50):  # what the README's generator gives is always accepted
        tok = secrets.token_urlsafe(24)
        assert check_token(tok) == tok
        tok = secrets.token_hex(16)
        assert check_token(tok) == tok


def test_a_token_file_must_be_private(tmp_path, monkeypatch) -> None:
    """Fails on today's main: a 0644 token file was accepted silently."""
    import secrets

    from rimless.firmware.link.protocol import TokenFileError
    from rimless.firmware.service.config import RobotConfig

    tok = secrets.token_urlsafe(24)
    path = tmp_path / "token"
    path.write_text(tok + "\n")
    path.chmod(0o644)
    monkeypatch.delenv("RIMLESS_TOKEN", raising=False)
    monkeypatch.setenv("RIMLESS_TOKEN_FILE", str(path))
    with pytest.raises(TokenFileError, match="chmod 600"):
        RobotConfig().token()
    path.chmod(0o600)
    assert RobotConfig().token() == tok


def test_sequences_keyboard_walks_and_dictionary_words_are_refused_by_a_real_estimator() -> None:
    """Fails on today's main: the hand-made estimate gave these 94-113 bits and accepted them."""
    import secrets
    import subprocess
    import sys

    for weak in (
        "abcdefghijklmnopqrstuvwxyz",  # a sequence
        "1q2w3e4r5t6y7u8i9o0p",  # a keyboard walk
        "correcthorsebatterystaple",  # dictionary words (xkcd 936: now in every list)
        "zaqwsxcderfvbgtyhnmjuiklop",  # a keyboard walk down the columns
        "monkeydragonsunshine2024",
    ):
        with pytest.raises(WeakToken, match="guessable") as err:
            check_token(weak, setting="$RIMLESS_TOKEN")
        msg = str(err.value)
        assert msg.startswith("$RIMLESS_TOKEN: ") and "\n" not in msg and "bits" in msg, msg
    for _ in range(100):  # what the firmware and the README generate always passes
        tok = secrets.token_urlsafe(24)
        assert check_token(tok) == tok
    # the estimator is imported only where a token is checked: not by the firmware's modules themselves
    code = "import sys, rimless.firmware.service.app, rimless.firmware.cli; print('zxcvbn' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
