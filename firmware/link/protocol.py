"""The command protocol, shared by the robot (`commands`) and the PC (`remote`): the wire format, the MACs,
the token rule and the validation of every message before anything is acted on.

Wire format: one JSON object per line (UTF-8, `\\n`-terminated, at most `max_message_bytes`).
On connect the robot sends a hello line with a fresh random nonce:

    {"hello": "rimless-robot", "version": 2, "nonce": "<32 hex digits>"}

Every command then carries an HMAC-SHA256 keyed with the shared token (the token itself never
crosses the wire) over the connection's nonce and the command:

    {"seq": 1, "cmd": "arm", "args": {}, "mac": "<64 hex digits>"}
    mac = HMAC-SHA256(token, nonce + "\\n" + json.dumps([seq, cmd, args], sort_keys=True,
                                                         separators=(",", ":"), ensure_ascii=True))

`seq` must increase on the connection. A line captured on one connection fails its MAC on any
other (new nonce), and a replay on the same connection fails the `seq` check. Every line gets
exactly one reply: `{"ok": true, "seq": 1, "result": {...}}` or `{"ok": false, "seq": 1 | null,
"error": "..."}`. A refused message changes nothing.

Reserved path for `disarm` and `status`: the same port number on UDP takes one datagram,
`{"disarm": n, "mac": HMAC-SHA256(token, "disarm\\n" + str(n))}` (any integer n; "status" likewise),
served by a thread of its own, and answers `{"ok": true, "n": n, "disarmed": true, "status": {...}}`.
It holds no state per sender, so no number of TCP connections can block it; a replayed disarm can
only disarm, which is always safe, and a replayed status only reads.

Commands: status, ping, arm {stance_leg?}, disarm, set {name, value}, trial_start {name?}, trial_stop.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import stat
from dataclasses import dataclass
from typing import Any

from rimless.errors import ParameterError

DEFAULT_PORT = 9871
PROTOCOL_VERSION = 2
HELLO = "rimless-robot"
COMMANDS: dict[str, frozenset[str]] = {
    "status": frozenset(),
    "ping": frozenset(),
    "arm": frozenset({"stance_leg"}),
    "disarm": frozenset(),
    "set": frozenset({"name", "value"}),
    "trial_start": frozenset({"name"}),
    "trial_stop": frozenset(),
}
REQUIRED_ARGS: dict[str, frozenset[str]] = {"set": frozenset({"name", "value"})}
_TOP_KEYS = frozenset({"seq", "cmd", "args", "mac"})
MAX_DEPTH = 4  # {"args": {"value": ...}} needs 2; anything deeper is refused
MIN_TOKEN_CHARS = 16
# Values that appeared in examples and tests: never accepted as a real token.
KNOWN_EXAMPLE_TOKENS = frozenset({"change-me", "changeme", "s3cret", "secret", "token", "tok", "bench", "password"})


class WeakToken(ParameterError):
    """The command token is too short or a published example value."""


# SHA-256 of tokens published in this repository (tests, docs, examples): never accepted, whatever their
# strength. Tests generate their tokens at run time.
PUBLISHED_TOKEN_SHA256 = frozenset(
    {
        hashlib.sha256(t.encode()).hexdigest()
        for t in (
            "test-token-7f3a9c2e1b5d",
            "cli-test-token-5e8d1f0a9b",
            "signal-test-token-3c9e7a1f",
            "fake-fault-token-8d2b6e4a1c",
            "x7gq-2mpz_9lrt4vb1nk",
            "token1234token1234",
        )
    }
)
# Words and keyboard runs that cost an attacker's dictionary nothing (checked case-insensitively).
COMMON_PARTS = (
    "password",
    "passwort",
    "passw0rd",
    "secret",
    "s3cret",
    "letmein",
    "welcome",
    "admin",
    "qwerty",
    "azerty",
    "asdf",
    "zxcv",
    "123456789",
    "12345",
    "abcdef",
    "abc",
    "changeme",
    "change",
    "default",
    "token",
    "robot",
    "rimless",
    "wheel",
    "test",
    "example",
    "dragon",
    "monkey",
    "iloveyou",
    "master",
    "login",
    "pass",
    "raspberry",
    "pi",
)
MIN_TOKEN_BITS = 64.0
GENERATE_HINT = 'generate one with `python3 -c "import secrets; print(secrets.token_urlsafe(24))"`'


def token_bits(token: str) -> float:
    """A conservative estimate of a token's entropy (bits): dictionary words and keyboard runs removed, each
    remaining character worth log2 of the alphabet its classes span, repeated characters counted once per
    distinct character beyond the first use of a repeated pattern."""
    low = token.lower()
    for part in sorted(COMMON_PARTS, key=len, reverse=True):
        low = low.replace(part, " ")
    rest = low.replace(" ", "")
    if not rest:
        return 0.0
    for k in range(1, len(rest) // 2 + 1):  # a repeated block is worth one block
        if len(rest) % k == 0 and rest == rest[:k] * (len(rest) // k):
            rest = rest[:k]
            break
    alphabet = 0
    original = {c for c in token if c.lower() in rest}
    if any(c.islower() for c in original):
        alphabet += 26
    if any(c.isupper() for c in original):
        alphabet += 26
    if any(c.isdigit() for c in original):
        alphabet += 10
    if any(not c.isalnum() for c in original):
        alphabet += 33
    distinct = len(set(rest))
    effective = min(len(rest), 2 * distinct)  # "aaaaab..." runs add little
    return effective * math.log2(max(alphabet, 2))


def estimated_bits(token: str) -> tuple[float, str]:
    """zxcvbn's estimate of the guesses an attacker needs (as bits: log2 of the guesses), and its warning ("" if
    none). zxcvbn (Dropbox's estimator: sequences, repeats, keyboard walks on QWERTY/Dvorak/keypad, dates, l33t,
    30 000 English words, names and leaked passwords) is imported here, only when a token is checked. Only the
    first 72 characters are rated (zxcvbn's own limit; a prefix never rates above the whole)."""
    try:
        from zxcvbn import zxcvbn
    except ImportError:
        raise WeakToken(
            'cannot rate the command token: the strength estimator zxcvbn is not installed (pip install -e ".[robot]")'
        ) from None
    result = zxcvbn(token[:72])
    warning = str(result.get("feedback", {}).get("warning") or "").rstrip(".")
    return float(result["guesses_log10"]) * math.log2(10.0), warning


def check_token(token: str, *, setting: str = "the command token") -> str:
    """Return `token` if it is acceptable for the command channel, else raise `WeakToken` (one line, starting
    with `setting`: where the token came from) saying why: an example or published value, shorter than
    MIN_TOKEN_CHARS, or under MIN_TOKEN_BITS by the lesser of two estimates: zxcvbn's (`estimated_bits`) and
    this module's own (`token_bits`: dictionary words, keyboard runs and repetitions discounted)."""
    if (
        token.lower() in KNOWN_EXAMPLE_TOKENS
        or hashlib.sha256(token.lower().encode()).hexdigest() in PUBLISHED_TOKEN_SHA256
        or hashlib.sha256(token.encode()).hexdigest() in PUBLISHED_TOKEN_SHA256
    ):
        raise WeakToken(f"{setting}: the command token is an example or published value; {GENERATE_HINT}")
    if len(token) < MIN_TOKEN_CHARS:
        raise WeakToken(
            f"{setting}: the command token is too short ({len(token)} characters, at least {MIN_TOKEN_CHARS})"
        )
    if len(set(token)) < 6:
        raise WeakToken(f"{setting}: the command token repeats too few characters to be secret")
    own = token_bits(token)
    if own < MIN_TOKEN_BITS:
        raise WeakToken(
            f"{setting}: the command token is guessable (about {own:.0f} bits once dictionary words and "
            f"repetitions are discounted, at least {MIN_TOKEN_BITS:.0f}); {GENERATE_HINT}"
        )
    bits, warning = estimated_bits(token)
    if bits < MIN_TOKEN_BITS:
        why = f": {warning}" if warning else ""
        raise WeakToken(
            f"{setting}: the command token is guessable (about {bits:.0f} bits by zxcvbn, at least "
            f"{MIN_TOKEN_BITS:.0f}{why}); {GENERATE_HINT}"
        )
    return token


class TokenFileError(ParameterError):
    """A token file that cannot be read, or that others may read."""


def read_token_file(path: str | os.PathLike[str], what: str) -> str:
    """The token in `path` (stripped). Refused unless it is a regular file owned by this user with no access for
    group or others (mode 0600 or 0400); `what` names the option or setting in the message."""
    try:
        st = os.stat(path)
        text = open(path, encoding="utf-8").read().strip()
    except (OSError, UnicodeDecodeError) as err:
        raise TokenFileError(
            f"{what} {path}: cannot read the token ({getattr(err, 'strerror', None) or err})"
        ) from None
    if st.st_mode & 0o077:
        raise TokenFileError(
            f"{what} {path}: mode {stat.S_IMODE(st.st_mode):04o} lets other users read the token; "
            f"run `chmod 600 {path}`"
        )
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        raise TokenFileError(f"{what} {path}: owned by uid {st.st_uid}, not by this user ({os.getuid()})")
    if not text:
        raise TokenFileError(f"{what} {path}: the file is empty")
    return text


RESERVED_KINDS = ("disarm", "status")
RESERVED_PAD_BYTES = 400  # clients pad their datagram so that the answer (never larger) can carry the status


def reserved_counter() -> int:
    """The number of a new reserved-path datagram: nanoseconds since the epoch, increasing on one PC; the robot
    accepts each kind only with a number above the last one it accepted (a replay is ignored)."""
    import time

    return time.time_ns()


def reserved_mac(token: str, kind: str, n: int) -> str:
    """HMAC-SHA256 (hex) of a reserved-path datagram: `kind` ("disarm" or "status") and number `n`."""
    return hmac.new(token.encode("utf-8"), f"{kind}\n{n}".encode("ascii"), hashlib.sha256).hexdigest()


def disarm_mac(token: str, n: int) -> str:
    """HMAC-SHA256 (hex) of a reserved-path disarm datagram with number `n`."""
    return reserved_mac(token, "disarm", n)


def parse_reserved_datagram(data: bytes, token: str) -> tuple[str, int]:
    """Validate a reserved-path datagram; return (kind, number) or raise `Rejected`."""
    if len(data) > 512 or _max_depth(data) > 1:
        raise Rejected("reserved datagram: too long or nested")
    try:
        obj = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise Rejected("reserved datagram: not UTF-8 JSON") from None
    kinds = [k for k in RESERVED_KINDS if isinstance(obj, dict) and k in obj]
    if not isinstance(obj, dict) or len(kinds) != 1 or set(obj) - {"pad"} != {kinds[0], "mac"}:
        raise Rejected("reserved datagram: expected exactly mac and one of disarm, status (and pad)")
    if "pad" in obj and not isinstance(obj["pad"], str):
        raise Rejected("reserved datagram: pad must be a string")
    kind = kinds[0]
    n, mac = obj[kind], obj["mac"]
    if isinstance(n, bool) or not isinstance(n, int) or not isinstance(mac, str) or not 0 <= n < 2**63:
        raise Rejected(f"reserved datagram: {kind} must be a non-negative integer and mac a string")
    if not hmac.compare_digest(mac.encode("ascii", "replace"), reserved_mac(token, kind, n).encode("ascii")):
        raise Rejected("reserved datagram: bad mac")
    return kind, n


def parse_disarm_datagram(data: bytes, token: str) -> int:
    """Validate a reserved-path disarm datagram; return its number or raise `Rejected`."""
    kind, n = parse_reserved_datagram(data, token)
    if kind != "disarm":
        raise Rejected("reserved datagram: not a disarm")
    return n


def command_mac(token: str, nonce: str, seq: int, cmd: str, args: dict[str, Any]) -> str:
    """HMAC-SHA256 (hex) of one command under `token`, bound to the connection's `nonce`."""
    body = json.dumps([seq, cmd, args], sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hmac.new(token.encode("utf-8"), f"{nonce}\n{body}".encode("ascii"), hashlib.sha256).hexdigest()


@dataclass(frozen=True, slots=True)
class Command:
    """A validated command."""

    seq: int
    cmd: str
    args: dict[str, Any]


class Rejected(ValueError):
    """A message that is refused; `seq` is echoed when it could be read."""

    def __init__(self, msg: str, seq: int | None = None) -> None:
        super().__init__(msg)
        self.seq = seq


def _check_tree(obj: Any, depth: int = 0) -> None:
    """Refuse deep nesting and strings that are not valid Unicode (lone surrogates)."""
    if depth > MAX_DEPTH:
        raise Rejected(f"message nested deeper than {MAX_DEPTH} levels")
    if isinstance(obj, str):
        try:
            obj.encode("utf-8")
        except UnicodeEncodeError:
            raise Rejected("garbled message: a string is not valid Unicode (lone surrogate)") from None
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _check_tree(k, depth + 1)
            _check_tree(v, depth + 1)
    elif isinstance(obj, list):
        for v in obj:
            _check_tree(v, depth + 1)


def _max_depth(line: bytes) -> int:
    """Bracket nesting depth of a JSON text (outside strings), without recursion."""
    depth = best = 0
    in_str = esc = False
    for b in line:
        if in_str:
            if esc:
                esc = False
            elif b == 0x5C:  # backslash
                esc = True
            elif b == 0x22:
                in_str = False
        elif b == 0x22:
            in_str = True
        elif b in (0x5B, 0x7B):
            depth += 1
            best = max(best, depth)
        elif b in (0x5D, 0x7D):
            depth -= 1
    return best


def parse_command(line: bytes, token: str, nonce: str, last_seq: int | None) -> Command:
    """Validate one line; raise `Rejected` with the reason. Checks run before anything is acted on."""
    if _max_depth(line) > MAX_DEPTH + 1:
        raise Rejected(f"message nested deeper than {MAX_DEPTH} levels")
    try:
        obj = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise Rejected("garbled message: not UTF-8 JSON") from None
    if not isinstance(obj, dict):
        raise Rejected("a message must be a JSON object")
    _check_tree(obj)
    raw_seq = obj.get("seq")
    seq = raw_seq if isinstance(raw_seq, int) and not isinstance(raw_seq, bool) and 0 <= raw_seq < 2**63 else None
    echo = seq
    if "token" in obj:
        raise Rejected(
            "unauthenticated: clear-text tokens are not accepted; sign with the connection nonce (protocol version 2)",
            echo,
        )
    extra = sorted(set(obj) - _TOP_KEYS)
    if extra:
        raise Rejected(f"unknown field {extra[0]!r}", echo)
    if seq is None:
        raise Rejected("seq must be a non-negative integer", None)
    cmd = obj.get("cmd")
    args = obj.get("args", {})
    mac = obj.get("mac")
    if not isinstance(cmd, str) or not isinstance(args, dict) or not isinstance(mac, str):
        raise Rejected("unauthenticated: a message needs cmd (string), args (object) and mac (string)", echo)
    expected = command_mac(token, nonce, seq, cmd, args)
    if not hmac.compare_digest(mac.encode("ascii", "replace"), expected.encode("ascii")):
        raise Rejected("unauthenticated: bad mac (wrong token, or a message replayed from another connection)", echo)
    if last_seq is not None and seq <= last_seq:
        raise Rejected(f"out of order: seq {seq} after {last_seq} (replayed?)", echo)
    if cmd not in COMMANDS:
        raise Rejected(f"unknown command {cmd!r}; known: {', '.join(sorted(COMMANDS))}", echo)
    bad = sorted(set(args) - COMMANDS[cmd])
    if bad:
        raise Rejected(f"{cmd}: unknown argument {bad[0]!r}", echo)
    missing = sorted(REQUIRED_ARGS.get(cmd, frozenset()) - set(args))
    if missing:
        raise Rejected(f"{cmd}: missing argument {missing[0]!r}", echo)
    return Command(seq, cmd, args)
