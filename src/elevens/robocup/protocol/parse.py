"""Dispatch: parse_message (fast path, then the generic decoders) and SafeParser (count, log and
drop a malformed datagram)."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from elevens.robocup.protocol.fast import (
    _fast_decode,
)
from elevens.robocup.protocol.messages import (
    Message,
    PlayerParams,
    PlayerType,
    ServerParams,
    _decode_change_player_type,
    _decode_error,
    _decode_fullstate,
    _decode_global,
    _decode_hear,
    _decode_init,
    _decode_ok,
    _decode_params,
    _decode_reconnect,
    _decode_score,
    _decode_see,
    _decode_sense_body,
    _decode_think,
    _decode_warning,
)
from elevens.robocup.protocol.sexp import (
    ProtocolError,
    Sexp,
    _excerpt,
    _excerpt_at,
    parse_sexp,
)

logger = logging.getLogger("elevens.robocup.protocol")

# --------------------------------------------------------------------------------------
# Dispatch
# --------------------------------------------------------------------------------------



def _decode_server_param(tree: tuple[Sexp, ...]) -> ServerParams:
    return _decode_params(tree, ServerParams)


def _decode_player_param(tree: tuple[Sexp, ...]) -> PlayerParams:
    return _decode_params(tree, PlayerParams)


def _decode_player_type(tree: tuple[Sexp, ...]) -> PlayerType:
    return _decode_params(tree, PlayerType)


_DECODERS: dict[str, Callable[[tuple[Sexp, ...]], Message]] = {
    "see": _decode_see,
    "sense_body": _decode_sense_body,
    "hear": _decode_hear,
    "think": _decode_think,
    "fullstate": _decode_fullstate,
    "see_global": _decode_global,
    "init": _decode_init,
    "reconnect": _decode_reconnect,
    "ok": _decode_ok,
    "error": _decode_error,
    "warning": _decode_warning,
    "score": _decode_score,
    "change_player_type": _decode_change_player_type,
    "server_param": _decode_server_param,
    "player_param": _decode_player_param,
    "player_type": _decode_player_type,
}
#: Message heads :func:`parse_message` understands.
KNOWN_HEADS: frozenset[str] = frozenset(_DECODERS)


def _clean(data: str | bytes | bytearray | memoryview) -> str:
    if isinstance(data, str):
        text = data
    elif isinstance(data, (bytes, bytearray, memoryview)):
        # latin-1 never fails; _check_chars then rejects anything outside ASCII.
        text = bytes(data).decode("latin-1")
    else:
        raise TypeError(f"expected str or bytes, got {type(data).__name__}")
    # The server ends datagrams with NUL (some trainer replies with "\n" first).
    return text.rstrip("\x00").strip()


def parse_message(data: str | bytes | bytearray | memoryview) -> Message:
    """Parse one server datagram (trailing NUL and whitespace stripped) into a message.

    Raises :class:`ProtocolError` for anything malformed: bad structure, unknown head,
    wrong arity, non-numeric or non-finite numbers, unknown names. (Messages in the
    server's own layout take a fast path; the result is the same.)
    """
    text = _clean(data)
    msg = _fast_decode(text)
    if msg is not None:
        return msg
    return _parse_generic(text)


def _parse_generic(text: str) -> Message:
    """The generic path of :func:`parse_message` for a cleaned text: tokenize, build
    the tree, decode. Parses every valid form and raises the strict errors."""
    tree = parse_sexp(text)
    head = tree[0] if tree else None
    decoder = _DECODERS.get(head) if isinstance(head, str) else None
    if decoder is None:
        raise ProtocolError(
            f"unknown message head {_excerpt(head) if head is not None else repr('()')} in "
            f"{_excerpt_at(text, 0)}; expected one of {', '.join(sorted(_DECODERS))}"
        )
    return decoder(tree)


@dataclass
class MessageStats:
    """Counts of parsed and rejected messages per kind (message head, or
    ``"unknown"`` when the head is not a known one)."""

    parsed: Counter[str] = field(default_factory=Counter)
    errors: Counter[str] = field(default_factory=Counter)
    last_error: str | None = None

    @property
    def total_errors(self) -> int:
        """Number of rejected messages of all kinds."""
        return sum(self.errors.values())

    @property
    def total_parsed(self) -> int:
        """Number of successfully parsed messages of all kinds."""
        return sum(self.parsed.values())


def _guess_head(data: str | bytes | bytearray | memoryview) -> str:
    """Cheap head extraction for error counting; never raises."""
    text = data[:64] if isinstance(data, str) else bytes(data[:64]).decode("latin-1")
    text = text.lstrip()
    if not text.startswith("("):
        return "unknown"
    word = text[1:].replace("(", " ").replace(")", " ").split(maxsplit=1)
    # Only known heads become counter keys, so garbage cannot grow the counter.
    return word[0] if word and word[0] in KNOWN_HEADS else "unknown"


class SafeParser:
    """:func:`parse_message` that never raises on bad input.

    ``parse`` returns None for a malformed datagram, counts it in ``stats.errors``
    under its head and logs it: at WARNING for the first ``log_limit`` errors of each
    kind, then at DEBUG, so a stream of bad datagrams cannot flood the log.
    """

    def __init__(self, log: logging.Logger | None = None, log_limit: int = 20) -> None:
        self.stats = MessageStats()
        self._log = log or logger
        self._log_limit = log_limit

    def parse(self, data: str | bytes | bytearray | memoryview) -> Message | None:
        """Parse ``data``; return None (counted and logged) if it is malformed."""
        try:
            msg = parse_message(data)
        except ProtocolError as err:
            kind = _guess_head(data)
            self.stats.errors[kind] += 1
            self.stats.last_error = str(err)
            level = logging.WARNING if self.stats.errors[kind] <= self._log_limit else logging.DEBUG
            self._log.log(level, "dropped malformed %s message: %s", kind, err)
            return None
        self.stats.parsed[type(msg).__name__] += 1
        return msg


