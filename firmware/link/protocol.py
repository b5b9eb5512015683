"""The command protocol, shared by the robot (`commands`) and the PC (`remote`): the wire format, the MACs,
the token rule and the validation of every message before anything is acted on.

Wire format: one JSON object per line (UTF-8, `\\n`-terminated, at most `max_message_bytes`).
On connect the robot sends a hello line with a fresh random nonce:

    {"hello": "rimless-robot", "version": 3, "nonce": "<32 hex digits>", "boot": "<32 hex digits>"}

Every command then carries an HMAC-SHA256 keyed with the shared token (the token itself never
crosses the wire) over the connection's nonce and the command:

    {"seq": 1, "cmd": "arm", "args": {}, "mac": "<64 hex digits>"}
    mac = HMAC-SHA256(token, nonce + "\\n" + json.dumps([seq, cmd, args], sort_keys=True,
                                                         separators=(",", ":"), ensure_ascii=True))

`seq` must increase on the connection. A line captured on one connection fails its MAC on any
other (new nonce), and a replay on the same connection fails the `seq` check. Every line gets
exactly one reply: `{"ok": true, "seq": 1, "result": {...}}` or `{"ok": false, "seq": 1 | null,
"error": "..."}`. A refused message changes nothing.

Reserved path for `disarm` and `status` (protocol version 3): the same port number on UDP, served by a
thread of its own, by challenge and response, so that no clock, counter, restart or replay can silence it:

    PC -> robot  rimless3 <kind> <client nonce> <boot nonce | -> <second | -> <mac> [pad]
                 mac = HMAC-SHA256(token, everything before " <mac>")

A first request carries no challenge ("-"). The robot answers each authenticated request it has not seen
(its MAC is the replay key, kept for `RESERVED_WINDOW_S`) with JSON bound to the client nonce:

    {"v": 3, "ok": true, "for": <client nonce>, "challenge": {"boot": <boot nonce>, "t": <robot's uptime s>},
     "disarmed": true (a disarm), "status": {...} (a fresh request only), "mac": HMAC(token, "reply\\n" + JSON)}

A request is fresh when it answers this start's challenge (its boot nonce, a second at most
`RESERVED_WINDOW_S` old on the robot's own clock) and was not seen before; only a fresh request gets the
status. A disarm is acted on whatever its challenge (releasing the clutches is always safe; an old one, a
replay, or one from the last start still disarm), so nothing the PC's clock or an earlier datagram did can
stop it. Answers are never larger than the request (no amplification) and never go to a datagram that fails
its MAC. The robot's boot nonce is also in the TCP hello. The PC (`remote.send_reserved_datagram`) sends a
first request of its kind, then a status answering the challenge it got back.

Commands: status, ping, arm {stance_leg?}, disarm, set {name, value}, trial_start {name?}, trial_stop.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import re
import secrets
import stat
from dataclasses import dataclass
from typing import Any

from rimless.errors import ParameterError

DEFAULT_PORT = 9871
PROTOCOL_VERSION = 3  # 3: reserved path by challenge, authenticated telemetry (CHANGELOG.md)
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
RESERVED_MAGIC = b"rimless3"
RESERVED_PAD_BYTES = 400  # clients pad their datagram so that the answer (never larger) can carry the status
RESERVED_WINDOW_S = 30  # a challenge (the robot's boot nonce and its uptime second) is good this long
_HEX32 = re.compile(rb"[0-9a-f]{32}")
_HEX64 = re.compile(rb"[0-9a-f]{64}")


def new_boot_nonce() -> str:
    """A fresh random nonce (32 hex digits) naming one start of the robot: the reserved path's challenges and the
    telemetry's key are bound to it, so nothing captured before a restart is fresh after it."""
    return secrets.token_hex(16)


def new_client_nonce() -> str:
    """A fresh random nonce (32 hex digits) for one reserved-path request: the robot's answer is bound to it."""
    return secrets.token_hex(16)


@dataclass(frozen=True, slots=True)
class ReservedRequest:
    """An authenticated reserved-path request: `kind` ("disarm" or "status"), the PC's `client_nonce`, the
    challenge it answers (`boot`, `t_s`: None on a first contact) and its `mac` (hex, the replay key)."""

    kind: str
    client_nonce: str
    boot: str | None
    t_s: int | None
    mac: str


def _reserved_body(kind: str, client_nonce: str, boot: str | None, t_s: int | None) -> bytes:
    return b" ".join(
        (
            RESERVED_MAGIC,
            kind.encode(),
            client_nonce.encode(),
            (boot or "-").encode(),
            str("-" if t_s is None else t_s).encode(),
        )
    )


def reserved_request(
    token: str,
    kind: str,
    client_nonce: str,
    boot: str | None = None,
    t_s: int | None = None,
    *,
    pad: int = RESERVED_PAD_BYTES,
) -> bytes:
    """The datagram of a reserved-path request (protocol version 3), padded to `pad` bytes:

        rimless3 <kind> <client nonce> <boot nonce | -> <challenge second | -> <mac> [padding]
        mac = HMAC-SHA256(token, the bytes before " <mac>")

    A fixed layout: the robot checks the MAC on the raw bytes before it parses anything."""
    body = _reserved_body(kind, client_nonce, boot, t_s)
    mac = hmac.digest(token.encode("utf-8"), body, "sha256").hex().encode()
    data = body + b" " + mac
    return data + (b" " + b"x" * (pad - len(data) - 1) if pad > len(data) + 1 else b"")


class Sha256Mac:
    """HMAC-SHA256 under one key with its padded key blocks hashed once (RFC 2104): about half the cost of
    `hmac.digest` per message, for the reserved path's check of every datagram of a flood."""

    def __init__(self, key: bytes) -> None:
        if len(key) > 64:
            key = hashlib.sha256(key).digest()
        block = key.ljust(64, b"\0")
        self._inner = hashlib.sha256(bytes(b ^ 0x36 for b in block))
        self._outer = hashlib.sha256(bytes(b ^ 0x5C for b in block))

    def digest(self, msg: bytes) -> bytes:
        """HMAC-SHA256(key, msg)."""
        inner = self._inner.copy()
        inner.update(msg)
        outer = self._outer.copy()
        outer.update(inner.digest())
        return outer.digest()


def check_reserved_request(data: bytes, mac: Sha256Mac) -> ReservedRequest | str:
    """Validate a version-3 reserved-path datagram with the token's `mac`; the request, or why not (a string:
    no exception, so a flood of garbage costs a layout check and at most one HMAC each, no JSON)."""
    if not 100 <= len(data) <= 512 or not data.startswith(RESERVED_MAGIC + b" "):
        return "reserved datagram: not a version-3 request"
    parts = data.split(b" ", 6)
    if len(parts) < 6:
        return "reserved datagram: not a version-3 request"
    _magic, kind, cnonce, boot, t, sig = parts[:6]
    if kind not in (b"disarm", b"status") or not _HEX32.fullmatch(cnonce) or not _HEX64.fullmatch(sig):
        return "reserved datagram: malformed version-3 request"
    if not (boot == b"-" or _HEX32.fullmatch(boot)) or not (t == b"-" or (t.isdigit() and len(t) <= 12)):
        return "reserved datagram: malformed challenge"
    end = len(kind) + len(cnonce) + len(boot) + len(t) + len(RESERVED_MAGIC) + 4
    if not hmac.compare_digest(mac.digest(data[:end]), bytes.fromhex(sig.decode("ascii"))):
        return "reserved datagram: bad mac"
    return ReservedRequest(
        kind.decode(),
        cnonce.decode(),
        None if boot == b"-" else boot.decode(),
        None if t == b"-" else int(t),
        sig.decode(),
    )


def parse_reserved_request(data: bytes, key: bytes) -> ReservedRequest:
    """`check_reserved_request` with the token's bytes `key`, raising `Rejected` with the reason."""
    out = check_reserved_request(data, Sha256Mac(key))
    if isinstance(out, str):
        raise Rejected(out)
    return out


def reply_mac(token: str, reply: dict[str, Any]) -> str:
    """HMAC-SHA256 (hex) of a reserved-path answer: over its canonical JSON without the "mac" key."""
    body = json.dumps(
        {k: v for k, v in reply.items() if k != "mac"}, sort_keys=True, separators=(",", ":"), default=str
    )
    return hmac.new(token.encode("utf-8"), b"reply\n" + body.encode(), hashlib.sha256).hexdigest()


def check_reply(token: str, data: bytes, client_nonce: str) -> dict[str, Any] | None:
    """The robot's answer to the request with `client_nonce`, if `data` is one and its MAC holds; else None (a
    stranger's datagram, a replayed answer to another request, a robot on another protocol version)."""
    try:
        obj = json.loads(data)
    except ValueError:
        return None
    if not isinstance(obj, dict):
        return None
    if obj.get("for") == client_nonce and obj.get("v") == PROTOCOL_VERSION:
        mac = obj.get("mac")
        if isinstance(mac, str) and hmac.compare_digest(mac.encode("ascii", "replace"), reply_mac(token, obj).encode()):
            return obj
    return None


_V2 = re.compile(rb'\{"(disarm|status)": ?([0-9]{1,19}), ?"mac": ?"([0-9a-f]{64})"(, ?"pad": ?"x*")?\}')


def check_v2_reserved(data: bytes, mac: Sha256Mac) -> tuple[str, int] | str:
    """A protocol-version-2 reserved datagram, as that PC wrote it (`{"disarm": n, "mac": HMAC(token,
    "disarm\\n" + n), "pad": "xx.."}`): (kind, n) if its MAC holds, else why not. One regular expression and one
    HMAC, no JSON. The robot acts on such a disarm (releasing is always safe) and answers it with an error naming
    the versions; it never answers a version-2 status with the status."""
    m = _V2.fullmatch(data) if len(data) <= 512 else None
    if m is None:
        return "reserved datagram: neither a version-3 request nor a version-2 datagram"
    kind, n = m.group(1).decode(), int(m.group(2))
    if n >= 2**63 or not hmac.compare_digest(mac.digest(f"{kind}\n{n}".encode()), bytes.fromhex(m.group(3).decode())):
        return "reserved datagram: bad mac"
    return kind, n


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
            "unauthenticated: clear-text tokens are not accepted; sign with the connection nonce (protocol version 2 and later)",
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
