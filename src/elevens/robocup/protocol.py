"""Strict parser and command serialiser for the rcssserver 19 text protocol.

The RoboCup Soccer Simulator 2D server (rcssserver, github rcsoccersim/rcssserver,
tag rcssserver-19.0.0) talks to its clients in UDP datagrams that each hold one
s-expression terminated by a NUL byte. This module turns such datagrams into typed,
immutable Python objects and builds the commands a player or the offline trainer
sends back.

Layers:

* :func:`parse_sexp` / :func:`parse_sexps` -- a small tokenizer (one ``split`` pass
  per quoted/unquoted segment, no regex per token, no ``eval``) and an iterative
  tree builder with a nesting limit (:data:`MAX_DEPTH`); atoms are ``str``, lists are
  ``tuple``. Quoted strings keep their quotes, so ``'"LeftTeam"'`` and ``'LeftTeam'``
  stay distinguishable.
* :func:`parse_message` -- dispatches on the head of the expression and decodes it
  into one of the frozen dataclasses below (see :data:`Message`). The hot kinds (see,
  sense_body, see_global, hear, think) first go through fast paths that read the
  server's exact layout 3-5x faster and hand anything else, including every error,
  to this generic path, so results and errors are the same either way.
* :class:`SafeParser` -- wraps :func:`parse_message` for clients: a malformed datagram
  is counted per kind, logged and dropped (``None``) instead of raising.
* Commands (:class:`Dash`, :class:`Kick`, ..., :class:`MovePlayer`) -- frozen
  dataclasses with ``encode() -> bytes``; :func:`datagram` joins several of them and
  appends the NUL byte the server expects.

Every malformed input raises :class:`ProtocolError` (a ``ValueError``) whose message
quotes the offending part and says what was expected; no other exception escapes
:func:`parse_message` for ``str``/``bytes`` input.

Coordinates are the server's: x towards the right goal, **y downward**, angles in
degrees, positive from +x towards +y. Message formats follow the v18 serializers of
rcssserver 19 (v19 clients get identical output): ``src/serializerplayerstdv8.cpp``,
``...v13.cpp``, ``...v14.cpp``, ``...v18.cpp``, ``src/serializercoachstdv14.cpp``,
``src/fullstatesender.cpp``, ``src/visualsenderplayer.cpp``.
"""

from __future__ import annotations

import abc
import logging
import math
import numbers
import re
from collections import Counter
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, fields
from itertools import repeat
from typing import ClassVar, TypeAlias, TypeVar

__all__ = [
    "KNOWN_HEADS",
    "MAX_DEPTH",
    "MAX_MESSAGE_CHARS",
    "PLAY_MODES",
    "ArmState",
    "BallState",
    "Bye",
    "Catch",
    "ChangeMode",
    "ChangePlayerType",
    "ChangeView",
    "CoachInit",
    "Command",
    "CommandCounts",
    "Dash",
    "Done",
    "Ear",
    "ErrorReply",
    "Eye",
    "FullState",
    "GlobalView",
    "Hear",
    "Init",
    "InitPlayer",
    "InitTrainer",
    "Kick",
    "Look",
    "Message",
    "MessageStats",
    "Move",
    "MoveBall",
    "MovePlayer",
    "NoOp",
    "OkReply",
    "ParamMap",
    "PlayerParams",
    "PlayerState",
    "PlayerType",
    "ProtocolError",
    "Reconnect",
    "ReconnectPlayer",
    "Recover",
    "RequestTeamNames",
    "SafeParser",
    "Say",
    "Score",
    "SeeMessage",
    "SeenObject",
    "SenseBody",
    "ServerParams",
    "Sexp",
    "Start",
    "SynchSee",
    "Tackle",
    "TeamNames",
    "Think",
    "TrainerEar",
    "Turn",
    "TurnNeck",
    "WarningReply",
    "datagram",
    "parse_message",
    "parse_sexp",
    "parse_sexps",
    "sexp_to_text",
]

logger = logging.getLogger(__name__)

#: Deepest nesting accepted. Server messages nest at most 4 deep (sense_body ->
#: arm -> target); the limit only guards against hostile or corrupt input.
MAX_DEPTH = 32
#: Longest text accepted (the UDP payload limit); longer input is rejected unread.
MAX_MESSAGE_CHARS = 65536

#: Play mode names, in the order of PLAYMODE_STRINGS in rcssserver ``src/types.h``.
PLAY_MODES: frozenset[str] = frozenset(
    (
        "before_kick_off",
        "time_over",
        "play_on",
        "kick_off_l",
        "kick_off_r",
        "kick_in_l",
        "kick_in_r",
        "free_kick_l",
        "free_kick_r",
        "corner_kick_l",
        "corner_kick_r",
        "goal_kick_l",
        "goal_kick_r",
        "goal_l",
        "goal_r",
        "drop_ball",
        "offside_l",
        "offside_r",
        "penalty_kick_l",
        "penalty_kick_r",
        "first_half_over",
        "pause",
        "human_judge",
        "foul_charge_l",
        "foul_charge_r",
        "foul_push_l",
        "foul_push_r",
        "foul_multiple_attack_l",
        "foul_multiple_attack_r",
        "foul_ballout_l",
        "foul_ballout_r",
        "back_pass_l",
        "back_pass_r",
        "free_kick_fault_l",
        "free_kick_fault_r",
        "catch_fault_l",
        "catch_fault_r",
        "indirect_free_kick_l",
        "indirect_free_kick_r",
        "penalty_setup_l",
        "penalty_setup_r",
        "penalty_ready_l",
        "penalty_ready_r",
        "penalty_taken_l",
        "penalty_taken_r",
        "penalty_miss_l",
        "penalty_miss_r",
        "penalty_score_l",
        "penalty_score_r",
        "illegal_defense_l",
        "illegal_defense_r",
    )
)
# fullstate reports these two pseudo modes instead of free_kick_l/r after a catch
# (src/fullstatesender.cpp FullStateSenderPlayerV5::sendFullState).
_FULLSTATE_MODES = PLAY_MODES | {"goalie_catch_ball_l", "goalie_catch_ball_r"}

Sexp: TypeAlias = str | tuple["Sexp", ...]
"""A parsed s-expression: an atom (``str``; quoted strings keep their quotes) or a
tuple of s-expressions."""


class ProtocolError(ValueError):
    """A server message that does not follow the rcssserver protocol.

    The message quotes the offending part (an excerpt around the error position or
    the offending sub-expression) and says what was expected.
    """


# --------------------------------------------------------------------------------------
# Tokenizer and tree builder
# --------------------------------------------------------------------------------------

# Only printable ASCII and ordinary whitespace may appear; one search per message.
_BAD_CHAR = re.compile(r"[^\t\n\r\x20-\x7e]")
_EXCERPT = 30


def _excerpt_at(text: str, pos: int) -> str:
    """Return ``text`` around ``pos`` with a ``<HERE>`` marker, shortened to ~60 chars."""
    lo = max(0, pos - _EXCERPT)
    hi = min(len(text), pos + _EXCERPT)
    pre = ("..." if lo > 0 else "") + text[lo:pos]
    post = text[pos:hi] + ("..." if hi < len(text) else "")
    return repr(pre + "<HERE>" + post)


def _excerpt(node: Sexp) -> str:
    """Return a short quoted rendering of a sub-expression for error messages."""
    text = sexp_to_text(node)
    if len(text) > 2 * _EXCERPT:
        text = text[: 2 * _EXCERPT] + "..."
    return repr(text)


def _locate_structure_error(text: str) -> tuple[int, str]:
    """Slow character scan that finds where a structurally bad text goes wrong.

    Only called after the fast path has failed, to point at the exact position.
    """
    depth = 0
    quote_start = -1
    for i, ch in enumerate(text):
        if quote_start >= 0:
            if ch == '"':
                quote_start = -1
            continue
        if ch == '"':
            quote_start = i
        elif ch == "(":
            depth += 1
            if depth > MAX_DEPTH:
                return i, f"nesting deeper than the limit of {MAX_DEPTH} levels"
        elif ch == ")":
            if depth == 0:
                return i, "a ')' without a matching '('"
            depth -= 1
    if quote_start >= 0:
        return quote_start, "a string opened with '\"' but never closed"
    if depth:
        return len(text), f"truncated message: {depth} '(' never closed"
    return len(text), "malformed expression"


def _structure_error(text: str, expected: str) -> ProtocolError:
    pos, problem = _locate_structure_error(text)
    return ProtocolError(f"{problem} at {_excerpt_at(text, pos)}; expected {expected}")


def _tokenize(text: str) -> list[str]:
    """Split ``text`` into '(' / ')' / atom / quoted-string tokens."""
    if '"' not in text:
        return text.replace("(", " ( ").replace(")", " ) ").split()
    parts = text.split('"')
    if len(parts) % 2 == 0:
        raise _structure_error(text, "balanced double quotes")
    tokens: list[str] = []
    for i, part in enumerate(parts):
        if i % 2:
            tokens.append('"' + part + '"')
        elif part:
            tokens.extend(part.replace("(", " ( ").replace(")", " ) ").split())
    return tokens


def _build(tokens: list[str], text: str) -> list[Sexp]:
    """Assemble tokens into nested tuples without recursion, bounding the depth."""
    stack: list[list[Sexp]] = []
    cur: list[Sexp] = []
    for tok in tokens:
        if tok == "(":
            stack.append(cur)
            if len(stack) > MAX_DEPTH:
                raise _structure_error(text, f"at most {MAX_DEPTH} nested levels")
            cur = []
        elif tok == ")":
            if not stack:
                raise _structure_error(text, "balanced parentheses")
            done = tuple(cur)
            cur = stack.pop()
            cur.append(done)
        else:
            cur.append(tok)
    if stack:
        raise _structure_error(text, "a complete message (balanced parentheses)")
    return cur


def _check_chars(text: str) -> None:
    if len(text) > MAX_MESSAGE_CHARS:
        raise ProtocolError(
            f"message of {len(text)} characters is longer than the limit of "
            f"{MAX_MESSAGE_CHARS}: {_excerpt_at(text, 0)}"
        )
    bad = _BAD_CHAR.search(text)
    if bad is not None:
        raise ProtocolError(
            f"character {bad.group()!r} at {_excerpt_at(text, bad.start())}; expected "
            "printable ASCII and whitespace only"
        )


def parse_sexps(text: str) -> tuple[Sexp, ...]:
    """Parse zero or more top-level s-expressions (e.g. ``"(dash 50)(done)"``).

    Raises :class:`ProtocolError` on unbalanced parentheses or quotes, nesting deeper
    than :data:`MAX_DEPTH`, forbidden characters or input longer than
    :data:`MAX_MESSAGE_CHARS`. Top-level atoms are rejected too.
    """
    _check_chars(text)
    items = _build(_tokenize(text), text)
    for item in items:
        if not isinstance(item, tuple):
            raise ProtocolError(
                f"stray atom {item!r} outside any parentheses in {_excerpt_at(text, 0)}; "
                "expected only (...) expressions"
            )
    return tuple(items)


def parse_sexp(text: str) -> tuple[Sexp, ...]:
    """Parse exactly one parenthesised s-expression and return it as a tuple."""
    items = parse_sexps(text)
    if len(items) != 1:
        what = "an empty message" if not items else f"{len(items)} expressions"
        raise ProtocolError(f"got {what} in {_excerpt_at(text, 0)}; expected exactly one (...)")
    item = items[0]
    assert isinstance(item, tuple)
    return item


def sexp_to_text(node: Sexp) -> str:
    """Render a parsed s-expression back to text (single spaces, no trailing NUL)."""
    if isinstance(node, str):
        return node
    # Iterative to stay safe on deep trees.
    out: list[str] = []
    stack: list[Iterator[Sexp]] = [iter((node,))]
    need_space = False
    while stack:
        nxt = next(stack[-1], None)
        if nxt is None:
            stack.pop()
            if stack:
                out.append(")")
                need_space = True
            continue
        if need_space:
            out.append(" ")
        if isinstance(nxt, str):
            out.append(nxt)
            need_space = True
        else:
            out.append("(")
            need_space = False
            stack.append(iter(nxt))
    return "".join(out)


# --------------------------------------------------------------------------------------
# Scalar helpers
# --------------------------------------------------------------------------------------


def _bad(expected: str, node: Sexp, where: str) -> ProtocolError:
    return ProtocolError(f"in {where}: expected {expected}, got {_excerpt(node)}")


def _f(tok: Sexp, what: str, where: str) -> float:
    """Parse a finite float atom (no ``nan``/``inf``/``1_0``)."""
    if isinstance(tok, str) and "_" not in tok:
        try:
            v = float(tok)
        except ValueError:
            pass
        else:
            if v - v == 0.0:  # false for nan and +-inf
                return v
    raise _bad(f"a finite number for {what}", tok, where)


def _i(tok: Sexp, what: str, where: str) -> int:
    """Parse an integer atom (``"3"``, ``"-0"``; not ``"3.0"``)."""
    if isinstance(tok, str) and "_" not in tok:
        try:
            return int(tok)
        except ValueError:
            pass
    raise _bad(f"an integer for {what}", tok, where)


def _atom(tok: Sexp, what: str, where: str) -> str:
    if isinstance(tok, str) and not tok.startswith('"'):
        return tok
    raise _bad(f"a bare word for {what}", tok, where)


def _choice(tok: Sexp, choices: frozenset[str] | tuple[str, ...], what: str, where: str) -> str:
    if isinstance(tok, str) and tok in choices:
        return tok
    shown = "|".join(sorted(choices)) if len(choices) <= 8 else "a known name"
    raise _bad(f"{what} ({shown})", tok, where)


def _quoted(tok: Sexp, what: str, where: str) -> str:
    if isinstance(tok, str) and len(tok) >= 2 and tok[0] == '"' and tok[-1] == '"':
        return tok[1:-1]
    raise _bad(f"a quoted string for {what}", tok, where)


def _list(node: Sexp, what: str, where: str) -> tuple[Sexp, ...]:
    if isinstance(node, tuple):
        return node
    raise _bad(f"a (...) list for {what}", node, where)


def _arity(node: tuple[Sexp, ...], n: int | tuple[int, ...], where: str) -> None:
    ok = len(node) == n if isinstance(n, int) else len(node) in n
    if not ok:
        want = str(n) if isinstance(n, int) else " or ".join(str(k) for k in n)
        raise ProtocolError(
            f"in {where}: expected {want} elements in ({node[0] if node else ''} ...), "
            f"got {len(node)}: {_excerpt(node)}"
        )


_SIDES = ("l", "r")


# --------------------------------------------------------------------------------------
# Messages: parameters
# --------------------------------------------------------------------------------------

ParamValue: TypeAlias = int | float | str


class ParamMap(Mapping[str, ParamValue]):
    """Read-only ``name -> value`` mapping of a parameter message.

    Values are ``int`` for integer-looking numbers, ``float`` for other numbers and
    ``str`` for quoted strings (quotes removed). Typed accessors convert and fall back
    to the given default when the name is missing.
    """

    __slots__ = ("_values",)
    #: rcssserver-19 defaults used by the typed properties when a name is missing.
    DEFAULTS: ClassVar[Mapping[str, ParamValue]] = {}

    def __init__(self, values: Mapping[str, ParamValue]) -> None:
        self._values: dict[str, ParamValue] = dict(values)

    def __getitem__(self, name: str) -> ParamValue:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({len(self._values)} values)"

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ParamMap):
            return type(self) is type(other) and self._values == other._values
        return NotImplemented

    def __hash__(self) -> int:
        return hash((type(self), tuple(sorted(self._values.items(), key=lambda kv: kv[0]))))

    def _lookup(self, name: str, default: ParamValue | None) -> ParamValue:
        if name in self._values:
            return self._values[name]
        if default is not None:
            return default
        if name in self.DEFAULTS:
            return self.DEFAULTS[name]
        raise KeyError(f"{type(self).__name__} has no parameter {name!r}")

    def get_float(self, name: str, default: float | None = None) -> float:
        """Return parameter ``name`` as a float (``default``, then class default if missing)."""
        value = self._lookup(name, default)
        if isinstance(value, str):
            raise ValueError(f"parameter {name!r} is the string {value!r}, not a number")
        return float(value)

    def get_int(self, name: str, default: int | None = None) -> int:
        """Return parameter ``name`` as an int; raises ValueError if it is fractional."""
        value = self._lookup(name, default)
        if isinstance(value, str) or float(value) != int(value):
            raise ValueError(f"parameter {name!r} is {value!r}, not an integer")
        return int(value)

    def get_bool(self, name: str, default: bool | None = None) -> bool:
        """Return a 0/1 flag parameter as a bool."""
        value = self._lookup(name, None if default is None else int(default))
        if isinstance(value, str) or value not in (0, 1):
            raise ValueError(f"parameter {name!r} is {value!r}, not a 0/1 flag")
        return bool(value)

    def get_str(self, name: str, default: str | None = None) -> str:
        """Return a string parameter (quotes removed)."""
        value = self._lookup(name, default)
        if not isinstance(value, str):
            raise ValueError(f"parameter {name!r} is {value!r}, not a string")
        return value


# rcssserver 19.0.0 defaults (src/serverparam.cpp; identical to the server_param the
# server sent in shared/rcss_transcripts/server_param.txt) for the values we use.
_SERVER_DEFAULTS: dict[str, ParamValue] = {
    "min_dash_power": 0,
    "max_dash_power": 100,
    "min_dash_angle": -180,
    "max_dash_angle": 180,
    "dash_angle_step": 1,
    "minpower": -100,
    "maxpower": 100,
    "minmoment": -180,
    "maxmoment": 180,
    "minneckmoment": -180,
    "maxneckmoment": 180,
    "minneckang": -90,
    "maxneckang": 90,
    "min_catch_angle": -90,
    "max_catch_angle": 90,
    "max_tackle_power": 100,
    "max_back_tackle_power": 0,
    "stamina_max": 8000,
    "stamina_capacity": 130600,
    "visible_angle": 90,
    "visible_distance": 3,
    "say_msg_size": 10,
    "tackle_cycles": 10,
    "half_time": 300,
    "drop_ball_time": 100,
    "synch_mode": 0,
    "player_size": 0.3,
    "ball_size": 0.085,
    "kickable_margin": 0.7,
    "goal_width": 14.02,
    "quantize_step": 0.1,
    "quantize_step_l": 0.01,
    "port": 6000,
    "coach_port": 6001,
    "olcoach_port": 6002,
}


class ServerParams(ParamMap):
    """The ``(server_param ...)`` message: every server parameter by name.

    Typed properties cover the values the bridge needs; when a parameter is missing
    they return the rcssserver 19.0.0 default. ``ServerParams.defaults()`` gives an
    instance holding only those defaults (use it before the message has arrived).
    """

    __slots__ = ()
    DEFAULTS: ClassVar[Mapping[str, ParamValue]] = _SERVER_DEFAULTS

    @classmethod
    def defaults(cls) -> ServerParams:
        """Return the rcssserver 19.0.0 defaults for the parameters this module uses."""
        return cls(_SERVER_DEFAULTS)

    @property
    def min_dash_power(self) -> float:
        """Lowest dash power the server accepts (0 since v17)."""
        return self.get_float("min_dash_power")

    @property
    def max_dash_power(self) -> float:
        """Highest dash power (100)."""
        return self.get_float("max_dash_power")

    @property
    def min_dash_angle(self) -> float:
        """Lowest dash direction in degrees relative to the body (-180)."""
        return self.get_float("min_dash_angle")

    @property
    def max_dash_angle(self) -> float:
        """Highest dash direction in degrees relative to the body (180)."""
        return self.get_float("max_dash_angle")

    @property
    def min_power(self) -> float:
        """Lowest kick power (server ``minpower``, -100)."""
        return self.get_float("minpower")

    @property
    def max_power(self) -> float:
        """Highest kick power (server ``maxpower``, 100)."""
        return self.get_float("maxpower")

    @property
    def min_moment(self) -> float:
        """Lowest turn moment / kick and tackle direction (``minmoment``, -180)."""
        return self.get_float("minmoment")

    @property
    def max_moment(self) -> float:
        """Highest turn moment / kick and tackle direction (``maxmoment``, 180)."""
        return self.get_float("maxmoment")

    @property
    def min_neck_moment(self) -> float:
        """Lowest turn_neck moment (-180)."""
        return self.get_float("minneckmoment")

    @property
    def max_neck_moment(self) -> float:
        """Highest turn_neck moment (180)."""
        return self.get_float("maxneckmoment")

    @property
    def min_neck_angle(self) -> float:
        """Lowest neck angle relative to the body (-90)."""
        return self.get_float("minneckang")

    @property
    def max_neck_angle(self) -> float:
        """Highest neck angle relative to the body (90)."""
        return self.get_float("maxneckang")

    @property
    def min_catch_angle(self) -> float:
        """Lowest catch direction (-90)."""
        return self.get_float("min_catch_angle")

    @property
    def max_catch_angle(self) -> float:
        """Highest catch direction (90)."""
        return self.get_float("max_catch_angle")

    @property
    def stamina_max(self) -> float:
        """Full stamina (8000)."""
        return self.get_float("stamina_max")

    @property
    def say_msg_size(self) -> int:
        """Longest ``say`` message in characters (10)."""
        return self.get_int("say_msg_size")

    @property
    def tackle_cycles(self) -> int:
        """Cycles a tackle blocks body commands (10)."""
        return self.get_int("tackle_cycles")

    @property
    def visible_angle(self) -> float:
        """View cone width of a normal view without synch-see, degrees (90)."""
        return self.get_float("visible_angle")

    @property
    def half_time(self) -> int:
        """Half length in server units (cycles/10); negative disables time keeping."""
        return self.get_int("half_time")

    @property
    def synch_mode(self) -> bool:
        """Whether the server runs in synchronous mode."""
        return self.get_bool("synch_mode")


class PlayerParams(ParamMap):
    """The ``(player_param ...)`` message (heterogeneous player type ranges)."""

    __slots__ = ()

    @property
    def player_types(self) -> int:
        """Number of player types the server offers (18)."""
        return self.get_int("player_types", 18)


class PlayerType(ParamMap):
    """One ``(player_type (id N) ...)`` message: the parameters of a player type."""

    __slots__ = ()

    @property
    def id(self) -> int:
        """The player type id (0 is the default type)."""
        return self.get_int("id")

    @property
    def kickable_margin(self) -> float:
        """Kickable margin of this type, metres."""
        return self.get_float("kickable_margin")

    @property
    def player_speed_max(self) -> float:
        """Maximum speed of this type."""
        return self.get_float("player_speed_max")


_P = TypeVar("_P", bound=ParamMap)


def _decode_params(tree: tuple[Sexp, ...], cls: type[_P]) -> _P:
    head = tree[0]
    where = f"({head} ...)"
    values: dict[str, ParamValue] = {}
    for item in tree[1:]:
        pair = _list(item, "a (name value) pair", where)
        if len(pair) != 2:
            raise _bad("a (name value) pair", pair, where)
        name = _atom(pair[0], "a parameter name", where)
        raw = pair[1]
        if not isinstance(raw, str):
            raise _bad(f"a number or quoted string for {name}", raw, where)
        value: ParamValue
        if raw[0] == '"':
            value = _quoted(raw, name, where)
        elif "." in raw or "e" in raw or "E" in raw:
            value = _f(raw, name, where)
        else:
            value = _i(raw, name, where)
        if name in values:
            raise _bad(f"each parameter once, but {name} repeats", item, where)
        values[name] = value
    params = cls(values)
    if cls is PlayerType and "id" not in values:
        raise ProtocolError(f"in {where}: expected an (id N) entry, got {_excerpt(tree)}")
    return params


# --------------------------------------------------------------------------------------
# Messages: simple replies
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Init:
    """Server reply to a player ``(init ...)``: ``(init l|r UNUM PLAYMODE)``."""

    side: str
    unum: int
    play_mode: str


@dataclass(frozen=True, slots=True)
class CoachInit:
    """Reply to a coach init: trainer ``(init ok)`` (side None) or online coach
    ``(init l|r ok)``."""

    side: str | None


@dataclass(frozen=True, slots=True)
class Reconnect:
    """Reply to ``(reconnect TEAM UNUM)``: ``(reconnect l|r PLAYMODE)``."""

    side: str
    play_mode: str


@dataclass(frozen=True, slots=True)
class Think:
    """Synch-mode ``(think)``: all sensor messages of this cycle have been sent; answer
    with the cycle's commands and exactly one ``(done)``."""


@dataclass(frozen=True, slots=True)
class OkReply:
    """A generic ``(ok COMMAND ARGS...)`` reply, e.g. ``(ok move)``, ``(ok eye on)``,
    ``(ok synch_see)``; ``args`` keeps the remaining s-expressions unchanged."""

    command: str
    args: tuple[Sexp, ...] = ()


@dataclass(frozen=True, slots=True)
class TeamNames:
    """Trainer reply ``(ok team_names (team l NAME) (team r NAME))``; a side is None
    while no team has connected on it."""

    left: str | None
    right: str | None


@dataclass(frozen=True, slots=True)
class ErrorReply:
    """``(error REASON)``, e.g. ``illegal_command_form``, ``no_more_team``."""

    reason: str


@dataclass(frozen=True, slots=True)
class WarningReply:
    """``(warning REASON)``, e.g. ``message_not_null_terminated``."""

    reason: str


@dataclass(frozen=True, slots=True)
class Score:
    """Reply to the player ``(score)`` command: ``(score TIME OUR THEIR)``."""

    time: int
    our: int
    their: int


@dataclass(frozen=True, slots=True)
class ChangePlayerType:
    """``(change_player_type UNUM [TYPE])``: a teammate (with its new type) or an
    opponent (type hidden, None) was substituted."""

    unum: int
    type_id: int | None


def _decode_init(tree: tuple[Sexp, ...]) -> Init | CoachInit:
    where = "(init ...)"
    if len(tree) == 2 and tree[1] == "ok":
        return CoachInit(None)
    if len(tree) == 3 and tree[2] == "ok":
        return CoachInit(_choice(tree[1], _SIDES, "a side", where))
    _arity(tree, 4, where)
    return Init(
        _choice(tree[1], _SIDES, "a side", where),
        _i(tree[2], "the uniform number", where),
        _choice(tree[3], PLAY_MODES, "a play mode", where),
    )


def _decode_reconnect(tree: tuple[Sexp, ...]) -> Reconnect:
    where = "(reconnect ...)"
    _arity(tree, 3, where)
    return Reconnect(
        _choice(tree[1], _SIDES, "a side", where),
        _choice(tree[2], PLAY_MODES, "a play mode", where),
    )


def _decode_think(tree: tuple[Sexp, ...]) -> Think:
    _arity(tree, 1, "(think)")
    return Think()


def _reason(tree: tuple[Sexp, ...], where: str) -> str:
    if len(tree) < 2:
        raise _bad("a reason after the head", tree, where)
    return " ".join(_atom(t, "a reason word", where) for t in tree[1:])


def _decode_error(tree: tuple[Sexp, ...]) -> ErrorReply:
    return ErrorReply(_reason(tree, "(error ...)"))


def _decode_warning(tree: tuple[Sexp, ...]) -> WarningReply:
    return WarningReply(_reason(tree, "(warning ...)"))


def _decode_score(tree: tuple[Sexp, ...]) -> Score:
    where = "(score ...)"
    _arity(tree, 4, where)
    return Score(
        _i(tree[1], "the time", where),
        _i(tree[2], "our score", where),
        _i(tree[3], "their score", where),
    )


def _decode_change_player_type(tree: tuple[Sexp, ...]) -> ChangePlayerType:
    where = "(change_player_type ...)"
    _arity(tree, (2, 3), where)
    unum = _i(tree[1], "the uniform number", where)
    type_id = _i(tree[2], "the player type", where) if len(tree) == 3 else None
    return ChangePlayerType(unum, type_id)


def _decode_ok(tree: tuple[Sexp, ...]) -> OkReply | TeamNames | GlobalView:
    where = "(ok ...)"
    if len(tree) < 2:
        raise _bad("a command name after ok", tree, where)
    command = _atom(tree[1], "the acknowledged command", where)
    if command == "look":
        return _decode_global(tree[1:], look=True)
    if command == "team_names":
        names: dict[str, str] = {}
        for item in tree[2:]:
            team = _list(item, "(team l|r NAME)", "(ok team_names ...)")
            if len(team) != 3 or team[0] != "team":
                raise _bad("(team l|r NAME)", item, "(ok team_names ...)")
            side = _choice(team[1], _SIDES, "a side", "(ok team_names ...)")
            names[side] = _atom(team[2], "a team name", "(ok team_names ...)")
        return TeamNames(names.get("l"), names.get("r"))
    return OkReply(command, tuple(tree[2:]))


# --------------------------------------------------------------------------------------
# Messages: see
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SeenObject:
    """One object of a player's ``see`` message, relative to the player's head.

    ``kind`` is ``"flag"``, ``"goal"``, ``"ball"``, ``"player"`` or ``"line"``.
    ``name`` is the server's name without parentheses and team/unum, e.g.
    ``"f r t 10"``, ``"g l"``, ``"b"``, ``"p"``, ``"l b"``; the close forms ``(F)``,
    ``(G)``, ``(B)``, ``(P)`` (objects within ``visible_distance`` outside the view
    cone, not identified) have ``close=True`` and names ``"F"``, ``"G"``, ``"B"``,
    ``"P"``.

    ``direction`` (degrees, relative to the head, positive clockwise on screen since y
    points down) is always present; the server truncates it towards zero to an
    integer. ``distance`` is None only in low-quality views. For flags it is the log-
    quantised distance (step ``quantize_step_l``), for lines the distance along the line
    of sight and ``direction`` the angle between sight line and line
    (src/visualsenderplayer.cpp ``sendLine``). The change/body/head/pointing fields are
    None when the server omitted them (far objects). ``tackling``/``kicking`` are the
    ``t``/``k`` markers of players.

    (No ``__slots__``: the parser builds instances through :func:`_seen`, which fills
    ``__dict__`` directly and is ~5x faster than the frozen ``__init__``.)
    """

    kind: str
    name: str
    close: bool
    direction: float
    distance: float | None = None
    dist_change: float | None = None
    dir_change: float | None = None
    body_dir: float | None = None
    head_dir: float | None = None
    point_dir: float | None = None
    team: str | None = None
    unum: int | None = None
    goalie: bool = False
    tackling: bool = False
    kicking: bool = False


@dataclass(frozen=True, slots=True)
class SeeMessage:
    """A player's visual message ``(see TIME OBJECTS...)``."""

    time: int
    objects: tuple[SeenObject, ...]

    @property
    def ball(self) -> SeenObject | None:
        """The ball (identified ``(b)`` preferred over a close ``(B)``), or None."""
        close = None
        for obj in self.objects:
            if obj.kind == "ball":
                if not obj.close:
                    return obj
                close = obj
        return close

    @property
    def players(self) -> tuple[SeenObject, ...]:
        """All seen players, including close unidentified ``(P)``."""
        return tuple(o for o in self.objects if o.kind == "player")

    @property
    def landmarks(self) -> tuple[SeenObject, ...]:
        """Identified flags and goals (close ``(F)``/``(G)`` excluded)."""
        return tuple(o for o in self.objects if o.kind in ("flag", "goal") and not o.close)

    @property
    def lines(self) -> tuple[SeenObject, ...]:
        """The seen field lines ``(l l|r|t|b)``."""
        return tuple(o for o in self.objects if o.kind == "line")


_new_object = object.__new__
_object_setattr = object.__setattr__


def _seen(kind: str, key: str, close: bool, direction: float, **extra: object) -> SeenObject:
    """Build a SeenObject without its frozen ``__init__`` (the parser's hot path).

    Fields left out keep the dataclass defaults, which live on the class.
    """
    obj = _new_object(SeenObject)
    extra["kind"] = kind
    extra["name"] = key
    extra["close"] = close
    extra["direction"] = direction
    _object_setattr(obj, "__dict__", extra)
    return obj


def _seen_names() -> dict[tuple[Sexp, ...], tuple[str, str, bool]]:
    # Names of the 55 default landmarks (src/landmarkreader.cpp loadDefaults), goals,
    # lines, ball and the close forms: one dict lookup per seen object.
    flags = [
        "c",
        "c t",
        "c b",
        "l t",
        "l b",
        "r t",
        "r b",
        "g l t",
        "g l b",
        "g r t",
        "g r b",
        "p l t",
        "p l c",
        "p l b",
        "p r t",
        "p r c",
        "p r b",
        "t 0",
        "b 0",
        "l 0",
        "r 0",
    ]
    flags += [f"{a} {b} {d}" for a in "tb" for b in "lr" for d in (10, 20, 30, 40, 50)]
    flags += [f"{a} {b} {d}" for a in "lr" for b in "tb" for d in (10, 20, 30)]
    table: dict[tuple[Sexp, ...], tuple[str, str, bool]] = {
        tuple(("f " + f).split()): ("flag", "f " + f, False) for f in flags
    }
    for side in "lr":
        table[("g", side)] = ("goal", "g " + side, False)
    for side in "lrtb":
        table[("l", side)] = ("line", "l " + side, False)
    table[("b",)] = ("ball", "b", False)
    for close, kind in (("F", "flag"), ("G", "goal"), ("B", "ball"), ("P", "player")):
        table[(close,)] = (kind, close, True)
    return table


_SEEN_NAMES = _seen_names()
_GOAL_NAMES = {"l": "g l", "r": "g r"}
_FLAG_WORD = frozenset(("c", "l", "r", "t", "b", "p", "g", "0", "10", "20", "30", "40", "50"))
_PLAYER_ARITIES = (1, 2, 3, 4, 6, 7)


def _numbers(vals: tuple[Sexp, ...], what: str, where: str) -> list[float]:
    """Parse all values as finite floats; fast path first, exact error on failure."""
    try:
        nums = [float(v) for v in vals]  # type: ignore[arg-type]
    except (TypeError, ValueError):
        nums = []
    else:
        # The sum is finite iff every value is (nan/inf propagate); float() also takes "1_0".
        total = sum(nums)
        if total - total == 0.0 and "_" not in "".join(vals):  # type: ignore[arg-type]
            return nums
    for v in vals:
        _f(v, what, where)
    raise AssertionError("unreachable: _f raises on the bad value")  # pragma: no cover


def _decode_seen_player(obj: tuple[Sexp, ...], name: tuple[Sexp, ...], where: str) -> SeenObject:
    n_name = len(name)
    extra: dict[str, object] = {}
    if n_name >= 2:
        extra["team"] = _quoted(name[1], "the team name", where)
        if n_name >= 3:
            extra["unum"] = _i(name[2], "the uniform number", where)
            if n_name == 4 and name[3] == "goalie":
                extra["goalie"] = True
            elif n_name != 3:
                raise _bad('(p "TEAM" UNUM [goalie])', name, where)
    vals = obj[1:]
    last = vals[-1]
    if last == "t":
        extra["tackling"] = True
        vals = vals[:-1]
    elif last == "k":
        extra["kicking"] = True
        vals = vals[:-1]
    nums = _numbers(vals, "a player value", where)
    n = len(nums)
    if n not in _PLAYER_ARITIES:
        raise _bad(
            "DIR, DIST DIR [POINTDIR], or DIST DIR DISTCHG DIRCHG [BODY HEAD "
            "[POINTDIR]] [t|k] after a player",
            obj,
            where,
        )
    if n == 1:
        return _seen("player", "p", False, nums[0], **extra)
    extra["distance"] = nums[0]
    if n == 3:
        extra["point_dir"] = nums[2]
    elif n >= 4:
        extra["dist_change"] = nums[2]
        extra["dir_change"] = nums[3]
        if n >= 6:
            extra["body_dir"] = nums[4]
            extra["head_dir"] = nums[5]
            if n == 7:
                extra["point_dir"] = nums[6]
    return _seen("player", "p", False, nums[1], **extra)


def _decode_seen(obj: Sexp, where: str) -> SeenObject:
    if not isinstance(obj, tuple) or len(obj) < 2 or not isinstance(obj[0], tuple):
        raise _bad("a seen object ((NAME) VALUES...)", obj, where)
    name = obj[0]
    known = _SEEN_NAMES.get(name)
    if known is None:
        if name and name[0] == "p":
            return _decode_seen_player(obj, name, where)
        words = [w for w in name[1:] if isinstance(w, str) and w in _FLAG_WORD]
        if not (name and name[0] == "f" and 2 <= len(name) <= 4 and len(words) == len(name) - 1):
            raise _bad(
                "a seen object name (f ...), (g l|r), (b), (p ...), (l l|r|t|b), "
                "(F), (G), (B) or (P)",
                name,
                where,
            )
        # A flag from a custom landmark file: same grammar as the default flags.
        known = ("flag", "f " + " ".join(words), False)
    kind, key, close = known
    nums = _numbers(obj[1:], f"a value of ({key})", where)
    n = len(nums)
    if n == 2:
        return _seen(kind, key, close, nums[1], distance=nums[0])
    if n == 1:
        return _seen(kind, key, close, nums[0])
    if n == 4 and not close and kind != "line":
        return _seen(
            kind, key, close, nums[1], distance=nums[0], dist_change=nums[2], dir_change=nums[3]
        )
    longest = "" if close or kind == "line" else " or DIST DIR DISTCHG DIRCHG"
    raise _bad(f"DIR, DIST DIR{longest} after ({key})", obj, where)


def _decode_see(tree: tuple[Sexp, ...]) -> SeeMessage:
    if len(tree) < 2:
        raise _bad("(see TIME OBJECTS...)", tree, "(see ...)")
    time = _i(tree[1], "the time", "(see ...)")
    where = f"(see {time} ...)"
    return SeeMessage(time, tuple([_decode_seen(obj, where) for obj in tree[2:]]))


# --------------------------------------------------------------------------------------
# Messages: sense_body
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CommandCounts:
    """Cumulative counts of executed commands (compare with what you sent to detect
    lost or late actions); None when the message did not carry that counter."""

    kick: int | None = None
    dash: int | None = None
    turn: int | None = None
    say: int | None = None
    turn_neck: int | None = None
    catch: int | None = None
    move: int | None = None
    change_view: int | None = None
    change_focus: int | None = None


@dataclass(frozen=True, slots=True)
class ArmState:
    """The pointing arm: ``(arm (movable N) (expires N) (target DIST DIR) (count N))``."""

    movable: int
    expires: int
    target_dist: float
    target_dir: float
    count: int


@dataclass(frozen=True, slots=True)
class SenseBody:
    """A player's ``(sense_body ...)`` message (v18 layout, fields in server order).

    ``speed_dir`` is relative to the head; ``head_angle`` is the neck angle relative to
    the body (add it to the body direction to get the head direction). Optional parts
    missing from the message are None.
    """

    time: int
    view_quality: str
    view_width: str
    stamina: float
    effort: float
    stamina_capacity: float | None
    speed: float
    speed_dir: float | None
    head_angle: float
    counts: CommandCounts
    arm: ArmState | None = None
    focus_target: tuple[str, int] | None = None
    focus_count: int | None = None
    tackle_expires: int | None = None
    tackle_count: int | None = None
    collisions: tuple[str, ...] | None = None
    foul_charged: int | None = None
    card: str | None = None
    focus_point: tuple[float, float] | None = None


_COUNT_NAMES = frozenset(CommandCounts.__dataclass_fields__)
_VIEW_QUALITIES = ("high", "low")
_VIEW_WIDTHS = ("narrow", "normal", "wide")
_CARDS = ("none", "yellow", "red")
_COLLISIONS = ("ball", "player", "post")


def _named_children(
    node: tuple[Sexp, ...], names: tuple[str, ...], where: str
) -> dict[str, tuple[Sexp, ...]]:
    out: dict[str, tuple[Sexp, ...]] = {}
    for child in node[1:]:
        item = _list(child, f"one of ({' | '.join(names)} ...)", where)
        key = item[0] if item else None
        if not isinstance(key, str) or key not in names or key in out:
            raise _bad(f"each of ({' | '.join(names)} ...) once", child, where)
        out[key] = item
    missing = [n for n in names if n not in out]
    if missing:
        raise _bad(f"({missing[0]} ...) inside", node, where)
    return out


def _decode_arm(node: tuple[Sexp, ...], where: str) -> ArmState:
    parts = _named_children(node, ("movable", "expires", "target", "count"), where)
    for key in ("movable", "expires", "count"):
        _arity(parts[key], 2, where)
    _arity(parts["target"], 3, where)
    return ArmState(
        _i(parts["movable"][1], "arm movable", where),
        _i(parts["expires"][1], "arm expires", where),
        _f(parts["target"][1], "arm target distance", where),
        _f(parts["target"][2], "arm target direction", where),
        _i(parts["count"][1], "arm count", where),
    )


def _decode_sense_body(tree: tuple[Sexp, ...]) -> SenseBody:
    if len(tree) < 2:
        raise _bad("(sense_body TIME ...)", tree, "(sense_body ...)")
    time = _i(tree[1], "the time", "(sense_body ...)")
    where = f"(sense_body {time} ...)"
    counts: dict[str, int] = {}
    seen: set[str] = set()
    view: tuple[str, str] | None = None
    stamina: list[float] | None = None
    speed: list[float] | None = None
    head_angle: float | None = None
    arm: ArmState | None = None
    focus_target: tuple[str, int] | None = None
    focus_count = tackle_expires = tackle_count = foul_charged = None
    collisions: tuple[str, ...] | None = None
    card: str | None = None
    focus_point: tuple[float, float] | None = None
    for child in tree[2:]:
        item = _list(child, "a (NAME VALUES...) entry", where)
        key = item[0] if item else None
        if not isinstance(key, str) or key in seen:
            raise _bad("each (NAME VALUES...) entry once", child, where)
        seen.add(key)
        if key in _COUNT_NAMES:
            _arity(item, 2, where)
            counts[key] = _i(item[1], f"the {key} count", where)
        elif key == "view_mode":
            _arity(item, 3, where)
            view = (
                _choice(item[1], _VIEW_QUALITIES, "view quality", where),
                _choice(item[2], _VIEW_WIDTHS, "view width", where),
            )
        elif key == "stamina":
            _arity(item, (3, 4), where)
            stamina = [_f(v, "stamina values", where) for v in item[1:]]
        elif key == "speed":
            _arity(item, (2, 3), where)
            speed = [_f(v, "speed", where) for v in item[1:]]
        elif key == "head_angle":
            _arity(item, 2, where)
            head_angle = _f(item[1], "head angle", where)
        elif key == "arm":
            arm = _decode_arm(item, where)
        elif key == "focus":
            parts = _named_children(item, ("target", "count"), where)
            target = parts["target"]
            if len(target) == 3:
                focus_target = (
                    _choice(target[1], _SIDES, "focus side", where),
                    _i(target[2], "focus unum", where),
                )
            elif len(target) != 2 or target[1] != "none":
                raise _bad("(target none) or (target l|r UNUM)", target, where)
            _arity(parts["count"], 2, where)
            focus_count = _i(parts["count"][1], "focus count", where)
        elif key == "tackle":
            parts = _named_children(item, ("expires", "count"), where)
            _arity(parts["expires"], 2, where)
            _arity(parts["count"], 2, where)
            tackle_expires = _i(parts["expires"][1], "tackle expires", where)
            tackle_count = _i(parts["count"][1], "tackle count", where)
        elif key == "collision":
            if len(item) == 2 and item[1] == "none":
                collisions = ()
            else:
                hits: list[str] = []
                for hit in item[1:]:
                    what = hit[0] if isinstance(hit, tuple) and len(hit) == 1 else None
                    if not isinstance(what, str) or what not in _COLLISIONS:
                        raise _bad("none or (ball) (player) (post)", hit, where)
                    hits.append(what)
                if not hits:
                    raise _bad("none or (ball) (player) (post)", item, where)
                collisions = tuple(hits)
        elif key == "foul":
            parts = _named_children(item, ("charged", "card"), where)
            _arity(parts["charged"], 2, where)
            _arity(parts["card"], 2, where)
            foul_charged = _i(parts["charged"][1], "foul charged", where)
            card = _choice(parts["card"][1], _CARDS, "card", where)
        elif key == "focus_point":
            _arity(item, 3, where)
            focus_point = (
                _f(item[1], "focus distance", where),
                _f(item[2], "focus direction", where),
            )
        else:
            raise _bad("a known sense_body entry", child, where)
    if view is None or stamina is None or speed is None or head_angle is None:
        raise ProtocolError(
            f"in {where}: expected (view_mode ...), (stamina ...), "
            f"(speed ...) and (head_angle ...), got {_excerpt(tree)}"
        )
    return SenseBody(
        time=time,
        view_quality=view[0],
        view_width=view[1],
        stamina=stamina[0],
        effort=stamina[1],
        stamina_capacity=stamina[2] if len(stamina) == 3 else None,
        speed=speed[0],
        speed_dir=speed[1] if len(speed) == 2 else None,
        head_angle=head_angle,
        counts=CommandCounts(**counts),
        arm=arm,
        focus_target=focus_target,
        focus_count=focus_count,
        tackle_expires=tackle_expires,
        tackle_count=tackle_count,
        collisions=collisions,
        foul_charged=foul_charged,
        card=card,
        focus_point=focus_point,
    )


# --------------------------------------------------------------------------------------
# Messages: hear
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Hear:
    """An audio message.

    ``sender`` is ``"referee"``, ``"self"``, ``"our"`` (teammate), ``"opp"``
    (opponent), ``"player"`` (a player of unknown team, pre-v8 form), or a coach name
    such as ``"online_coach_left"``. ``message`` is the text without quotes (a clang
    s-expression is rendered back to text; None for the short ``(hear T our UNUM)`` /
    ``(hear T opp)`` forms that carry no text). ``direction`` (degrees, relative to the
    head) is set for players, ``unum`` for teammates. Handles both the player form
    ``(hear TIME SENDER MSG)`` and the trainer's ``(hear SENDER TIME MSG)``, and a player's
    say as the trainer hears it, ``(hear TIME (p "TEAM" UNUM [goalie]) MSG)`` (sender
    ``"player"``, ``unum`` set).
    """

    time: int
    sender: str
    message: str | None
    direction: float | None = None
    unum: int | None = None

    @property
    def play_mode(self) -> str | None:
        """The new play mode if this is a referee play-mode announcement."""
        if self.sender == "referee" and self.message in PLAY_MODES:
            return self.message
        return None

    @property
    def goal(self) -> tuple[str, int] | None:
        """``(side, new_total)`` for the referee's ``goal_l_N`` / ``goal_r_N``."""
        msg = self.message
        if self.sender != "referee" or msg is None or not msg.startswith("goal_"):
            return None
        parts = msg.split("_")
        if len(parts) == 3 and parts[1] in _SIDES and parts[2].isdigit() and parts[2].isascii():
            return parts[1], int(parts[2])
        return None


def _is_number(tok: Sexp) -> bool:
    if not isinstance(tok, str) or "_" in tok:
        return False
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _text(tok: Sexp, where: str) -> str:
    if isinstance(tok, tuple):
        return sexp_to_text(tok)
    if tok.startswith('"'):
        return _quoted(tok, "the message", where)
    return tok


def _decode_hear(tree: tuple[Sexp, ...]) -> Hear:
    where = "(hear ...)"
    if len(tree) < 3:
        raise _bad("(hear TIME SENDER [MESSAGE])", tree, where)
    if not _is_number(tree[1]):
        # Trainer / old coach form: (hear SENDER TIME MSG).
        _arity(tree, 4, where)
        sender = _atom(tree[1], "the sender", where)
        return Hear(_i(tree[2], "the time", where), sender, _text(tree[3], where))
    time = _i(tree[1], "the time", where)
    who = tree[2]
    rest = tree[3:]
    if who == "our":
        if len(rest) != 1:
            raise _bad("(hear TIME our UNUM)", tree, where)
        return Hear(time, "our", None, unum=_i(rest[0], "the uniform number", where))
    if who == "opp":
        if rest:
            raise _bad("(hear TIME opp)", tree, where)
        return Hear(time, "opp", None)
    if _is_number(who):
        direction = _f(who, "the direction", where)
        if len(rest) == 3 and rest[0] == "our":
            return Hear(
                time,
                "our",
                _text(rest[2], where),
                direction,
                _i(rest[1], "the uniform number", where),
            )
        if len(rest) == 2 and rest[0] == "opp":
            return Hear(time, "opp", _text(rest[1], where), direction)
        if len(rest) == 1:
            return Hear(time, "player", _text(rest[0], where), direction)
        raise _bad(
            "(hear TIME DIR our UNUM MSG), (hear TIME DIR opp MSG) or (hear TIME DIR MSG)",
            tree,
            where,
        )
    if isinstance(who, tuple) and len(who) >= 3 and who[0] == "p" and len(rest) == 1:
        # The trainer hears a player's say as (hear TIME (p "TEAM" UNUM [goalie]) MSG).
        return Hear(time, "player", _text(rest[0], where),
                    unum=_i(who[2], "the uniform number", where))
    sender = _atom(who, "the sender", where)
    if len(rest) != 1:
        raise _bad(f"one message after {sender}", tree, where)
    return Hear(time, sender, _text(rest[0], where))


# --------------------------------------------------------------------------------------
# Messages: fullstate, see_global / look
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class BallState:
    """Ball position and velocity in the global server frame (y down)."""

    x: float
    y: float
    vx: float
    vy: float


@dataclass(frozen=True, slots=True)
class PlayerState:
    """A player in the global frame, from ``fullstate`` (``side`` set, ``team`` None)
    or the trainer's ``see_global``/``look`` (``team`` set, ``side`` None).

    ``body``/``neck`` in degrees (neck relative to body). ``marker`` is the state
    flag ``t`` (tackling), ``k`` (kicked) or ``f`` (foul charged) or None; ``card`` is
    ``"yellow"``/``"red"`` or None. Fullstate-only fields (type, focus, stamina) are
    None in a global view.
    """

    x: float
    y: float
    vx: float
    vy: float
    body: float
    neck: float
    unum: int
    goalie: bool = False
    side: str | None = None
    team: str | None = None
    type_id: int | None = None
    point_dist: float | None = None
    point_dir: float | None = None
    focus_dist: float | None = None
    focus_dir: float | None = None
    stamina: float | None = None
    effort: float | None = None
    recovery: float | None = None
    stamina_capacity: float | None = None
    marker: str | None = None
    card: str | None = None


@dataclass(frozen=True, slots=True)
class GlobalView:
    """The trainer's ``(see_global TIME ...)`` or ``(ok look TIME ...)`` (``look``
    True): goals, ball and all players in the global frame."""

    time: int
    ball: BallState | None
    players: tuple[PlayerState, ...]
    goals: tuple[tuple[str, float, float], ...] = ()
    look: bool = False


@dataclass(frozen=True, slots=True)
class FullState:
    """A ``(fullstate ...)`` message (server::fullstate_l/r): exact global state.

    ``score_our``/``score_their`` are from the receiving player's side (the server swaps
    them for side r). ``counts`` is the raw ``(count ...)`` tuple (kick dash turn catch
    move turn_neck change_view say change_focus in v18).
    """

    time: int
    play_mode: str
    view_quality: str
    view_width: str
    counts: tuple[int, ...]
    arm: ArmState | None
    score_our: int
    score_their: int
    ball: BallState
    players: tuple[PlayerState, ...]


_MARKERS = ("t", "k", "f")
_CARD_MARKS = {"y": "yellow", "r": "red"}


def _decode_ball(obj: tuple[Sexp, ...], where: str) -> BallState:
    _arity(obj, 5, where)
    return BallState(
        _f(obj[1], "ball x", where),
        _f(obj[2], "ball y", where),
        _f(obj[3], "ball vx", where),
        _f(obj[4], "ball vy", where),
    )


def _split_marks(vals: tuple[Sexp, ...]) -> tuple[tuple[Sexp, ...], str | None, str | None]:
    marker = card = None
    last = vals[-1] if vals else None
    if isinstance(last, str) and last in _CARD_MARKS:
        card = _CARD_MARKS[last]
        vals = vals[:-1]
        last = vals[-1] if vals else None
    if isinstance(last, str) and last in _MARKERS:
        marker = last
        vals = vals[:-1]
    return vals, marker, card


def _decode_global_player(obj: tuple[Sexp, ...], where: str) -> PlayerState:
    name = obj[0]
    assert isinstance(name, tuple)
    if not 3 <= len(name) <= 4 or (len(name) == 4 and name[3] != "goalie"):
        raise _bad('(p "TEAM" UNUM [goalie])', name, where)
    team = _quoted(name[1], "the team name", where)
    unum = _i(name[2], "the uniform number", where)
    vals, marker, card = _split_marks(obj[1:])
    if len(vals) not in (6, 7):
        raise _bad("X Y VX VY BODY NECK [POINTDIR] [t|k|f] [y|r] after a player", obj, where)
    nums = [_f(v, "player state", where) for v in vals]
    return PlayerState(
        nums[0],
        nums[1],
        nums[2],
        nums[3],
        nums[4],
        nums[5],
        unum,
        len(name) == 4,
        team=team,
        point_dir=nums[6] if len(nums) == 7 else None,
        marker=marker,
        card=card,
    )


def _decode_global(tree: tuple[Sexp, ...], look: bool = False) -> GlobalView:
    head = "ok look" if look else "see_global"
    if len(tree) < 2:
        raise _bad(f"({head} TIME ...)", tree, f"({head} ...)")
    time = _i(tree[1], "the time", f"({head} ...)")
    where = f"({head} {time} ...)"
    ball: BallState | None = None
    players: list[PlayerState] = []
    goals: list[tuple[str, float, float]] = []
    for child in tree[2:]:
        obj = _list(child, "((NAME) VALUES...)", where)
        if not obj or not isinstance(obj[0], tuple) or not obj[0]:
            raise _bad("((NAME) VALUES...)", child, where)
        name = obj[0]
        assert isinstance(name, tuple)
        if name[0] == "p":
            players.append(_decode_global_player(obj, where))
        elif name == ("b",):
            if ball is not None:
                raise _bad("one ball", child, where)
            ball = _decode_ball(obj, where)
        elif (
            name[0] == "g"
            and len(name) == 2
            and isinstance(name[1], str)
            and name[1] in _GOAL_NAMES
        ):
            _arity(obj, 3, where)
            goals.append(
                (_GOAL_NAMES[name[1]], _f(obj[1], "goal x", where), _f(obj[2], "goal y", where))
            )
        else:
            raise _bad("(g l|r), (b) or (p ...)", name, where)
    return GlobalView(time, ball, tuple(players), tuple(goals), look)


def _decode_fs_player(obj: tuple[Sexp, ...], where: str) -> PlayerState:
    name = obj[0]
    assert isinstance(name, tuple)
    # ((p l|r UNUM [g] TYPE) X Y VX VY BODY NECK [ARM_DIST ARM_DIR] [(focus_point D A)]
    #  (stamina S E R [CAP]) [t|k|f] [y|r])  -- src/serializerplayerstdv14.cpp
    if len(name) == 5 and name[3] == "g":
        goalie = True
    elif len(name) == 4:
        goalie = False
    else:
        raise _bad("(p l|r UNUM [g] TYPE)", name, where)
    side = _choice(name[1], _SIDES, "a side", where)
    unum = _i(name[2], "the uniform number", where)
    type_id = _i(name[-1], "the player type", where)
    vals, marker, card = _split_marks(obj[1:])
    nums: list[float] = []
    focus: tuple[float, float] | None = None
    stamina: tuple[float, ...] | None = None
    for v in vals:
        if isinstance(v, str):
            if focus is not None or stamina is not None:
                raise _bad("numbers before (focus_point ...) and (stamina ...)", obj, where)
            nums.append(_f(v, "player state", where))
        elif v and v[0] == "focus_point" and focus is None and stamina is None:
            _arity(v, 3, where)
            focus = (_f(v[1], "focus distance", where), _f(v[2], "focus direction", where))
        elif v and v[0] == "stamina" and stamina is None:
            _arity(v, (4, 5), where)
            stamina = tuple(_f(x, "stamina", where) for x in v[1:])
        else:
            raise _bad("(focus_point D DIR) or (stamina S E R CAP)", v, where)
    if len(nums) not in (6, 8) or stamina is None:
        raise _bad(
            "X Y VX VY BODY NECK [ARM_DIST ARM_DIR] ... (stamina ...) after a player", obj, where
        )
    return PlayerState(
        nums[0],
        nums[1],
        nums[2],
        nums[3],
        nums[4],
        nums[5],
        unum,
        goalie,
        side=side,
        type_id=type_id,
        point_dist=nums[6] if len(nums) == 8 else None,
        point_dir=nums[7] if len(nums) == 8 else None,
        focus_dist=focus[0] if focus else None,
        focus_dir=focus[1] if focus else None,
        stamina=stamina[0],
        effort=stamina[1],
        recovery=stamina[2],
        stamina_capacity=stamina[3] if len(stamina) == 4 else None,
        marker=marker,
        card=card,
    )


def _decode_fullstate(tree: tuple[Sexp, ...]) -> FullState:
    if len(tree) < 2:
        raise _bad("(fullstate TIME ...)", tree, "(fullstate ...)")
    time = _i(tree[1], "the time", "(fullstate ...)")
    where = f"(fullstate {time} ...)"
    play_mode = quality = width = None
    counts: tuple[int, ...] | None = None
    arm: ArmState | None = None
    score: tuple[int, int] | None = None
    ball: BallState | None = None
    players: list[PlayerState] = []
    for child in tree[2:]:
        obj = _list(child, "a (NAME ...) entry", where)
        if not obj:
            raise _bad("a (NAME ...) entry", child, where)
        key = obj[0]
        if isinstance(key, tuple):
            if key == ("b",) and ball is None:
                ball = _decode_ball(obj, where)
            elif key and key[0] == "p":
                players.append(_decode_fs_player(obj, where))
            else:
                raise _bad("((b) ...) once or ((p ...) ...)", child, where)
        elif key == "pmode" and play_mode is None:
            _arity(obj, 2, where)
            play_mode = _choice(obj[1], _FULLSTATE_MODES, "a play mode", where)
        elif key == "vmode" and quality is None:
            _arity(obj, 3, where)
            quality = _choice(obj[1], _VIEW_QUALITIES, "view quality", where)
            width = _choice(obj[2], _VIEW_WIDTHS, "view width", where)
        elif key == "count" and counts is None:
            counts = tuple(_i(v, "a command count", where) for v in obj[1:])
        elif key == "arm" and arm is None:
            arm = _decode_arm(obj, where)
        elif key == "score" and score is None:
            _arity(obj, 3, where)
            score = (_i(obj[1], "our score", where), _i(obj[2], "their score", where))
        else:
            raise _bad(
                "(pmode) (vmode) (count) (arm) (score) once each, ((b) ...) or ((p ...) ...)",
                child,
                where,
            )
    if play_mode is None or quality is None or width is None or score is None or ball is None:
        raise ProtocolError(
            f"in {where}: expected (pmode ...), (vmode ...), (score ...) and "
            f"((b) ...), got {_excerpt(tree)}"
        )
    return FullState(
        time, play_mode, quality, width, counts or (), arm, score[0], score[1], ball, tuple(players)
    )


# --------------------------------------------------------------------------------------
# Fast paths for the hot messages
# --------------------------------------------------------------------------------------
#
# Per cycle every player gets a sense_body and a think, every few cycles a see; the
# trainer a see_global. The generic path above (tokenize, build tuples, decode) costs
# 30-150 us for those; the fast paths below take 3.4-5x less by reading the server's
# canonical layout directly: single spaces, objects as " ((NAME) V V ...)".
#
# Contract: a fast path returns either exactly what the generic path returns for the
# same text, or None ("not handled"), and never raises. parse_message then runs the
# generic path, which parses the unusual-but-valid forms (tabs, double spaces, custom
# flags, exponents in see numbers, old sense_body layouts, ...) and produces the strict
# error message for malformed input. So a fast path only has to accept a subset of
# the valid messages, and each check below errs towards None. What makes a text
# acceptable (it is ASCII, checked first):
#
# * see / see_global / ok look: the text is "(HEAD TIME ((N1) V1) ((N2) V2) ...)" with
#   TIME decimal digits and every Ni/Vi free of parentheses (_split_objects). That
#   holds because each name is looked up in a table of known names or matched by
#   _PLAYER_NAME, and every value word is a number (see below) or a marker compared
#   exactly; so the text is exactly that layout and the generic tokenizer splits it
#   the same way. Numbers in see: looked up in _SEE_NUMBERS, which holds canonical
#   decimals only. Numbers in see_global: float(), like the generic path, plus its
#   extra rules: no "_" (float() accepts "1_0"), none of the control characters
#   float() strips, and finite (checked once on a running sum; a sum that overflows
#   only sends a valid message down the generic path).
# * sense_body / hear: a full-match regular expression of the v18 layout with
#   explicit ASCII character classes.
#
# Objects are built without their frozen __init__ (~2 us for the 21-field
# PlayerState): SeenObject by filling its __dict__ (as _seen does), the slotted
# dataclasses by _slot_builder.

_T = TypeVar("_T")


def _slot_builder(cls: type[_T]) -> Callable[..., _T]:
    """Return ``make(v1, ..., vn)`` that builds ``cls`` from all its field values.

    ``cls`` is a frozen ``slots=True`` dataclass; ``make`` takes every field,
    positionally in declaration order, without defaults or ``__post_init__`` (the
    parsed dataclasses have none). It stores the values on a plain twin class with the
    same ``__slots__`` and then assigns ``__class__``, which Python allows between
    classes of identical layout: about 7x faster than the frozen ``__init__`` (which
    calls ``object.__setattr__`` once per field). The code is generated from
    ``dataclasses.fields`` like ``__init__`` itself, so new fields are picked up.
    """
    names = tuple(f.name for f in fields(cls))  # type: ignore[arg-type]
    if names != tuple(cls.__dict__.get("__slots__", ())) or cls.__bases__ != (object,):
        raise TypeError(f"{cls.__name__} is not a plain slots dataclass")
    twin = type(f"_{cls.__name__}Twin", (), {"__slots__": names})
    src = (
        f"def make_{cls.__name__}({', '.join(names)}):\n"
        "    o = _new(_twin)\n"
        + "".join(f"    o.{n} = {n}\n" for n in names)
        + "    o.__class__ = _cls\n    return o\n"
    )
    scope: dict[str, object] = {"_new": object.__new__, "_twin": twin, "_cls": cls}
    exec(src, scope)
    make = scope[f"make_{cls.__name__}"]
    assert callable(make)
    return make


_make_see = _slot_builder(SeeMessage)
_make_sense_body = _slot_builder(SenseBody)
_make_counts = _slot_builder(CommandCounts)
_make_arm = _slot_builder(ArmState)
_make_ball = _slot_builder(BallState)
_make_player = _slot_builder(PlayerState)
_make_global = _slot_builder(GlobalView)
_make_hear = _slot_builder(Hear)

#: "((f c t" -> ("flag", "f c t", False): kind, name and close of each landmark, line
#: and ball, keyed by how the name appears in the message ("((" + the single-spaced
#: name, see _split_objects).
_FAST_SEEN_NAMES: dict[str, tuple[str, str, bool]] = {
    "((" + " ".join(k for k in key if isinstance(k, str)): value
    for key, value in _SEEN_NAMES.items()
}
#: The names above that may also carry DISTCHG DIRCHG (not lines, not close objects).
_FAST_SEEN_MOVING = frozenset(
    name for name, (kind, _, close) in _FAST_SEEN_NAMES.items() if not close and kind != "line"
)
_FAST_GOALS = {"((g l": "g l", "((g r": "g r"}
#: A player's name as the fast paths accept it: ((p ["TEAM" [UNUM [goalie]]].
_PLAYER_NAME = re.compile(r'\(\(p(?: "([-+_.a-zA-Z0-9]*)"(?: ([0-9]+)(?: (goalie))?)?)?')
_PlayerName: TypeAlias = tuple[str | None, int | None, bool]
_PLAYER_NAMES: dict[str, _PlayerName] = {}
_PLAYER_NAMES_MAX = 512  # team names x 12 is plenty; bounded against garbage


def _player_name(name: str) -> _PlayerName | None:
    """``'((p "A" 3 goalie'`` -> ``("A", 3, True)`` (team, unum, goalie; cached); None if
    the name is not of that form."""
    hit = _PLAYER_NAMES.get(name)
    if hit is not None:
        return hit
    m = _PLAYER_NAME.fullmatch(name)
    if m is None:
        return None
    team, unum, goalie = m.groups()
    hit = (team, None if unum is None else int(unum), goalie is not None)
    if len(_PLAYER_NAMES) < _PLAYER_NAMES_MAX:
        _PLAYER_NAMES[name] = hit
    return hit


def _has_float_space(text: str) -> bool:
    """Whether ``text`` holds one of the ASCII control characters float() strips.

    (float() accepts no other control character, and names are matched exactly, so on
    ASCII text this replaces the generic path's printable-characters check.)"""
    return "\t" in text or "\n" in text or "\r" in text or "\x0b" in text or "\x0c" in text


def _split_objects(text: str, start: int) -> tuple[int, list[str]] | None:
    """Split ``(HEAD TIME ((N1) V1) ... ((Nk) Vk))`` (TIME at ``start``) into TIME and
    ``["((N1", "V1", ..., "((Nk", "Vk"]``; None if not of that shape.

    The text is only split at ") "; the callers accept a name part only if it is a
    known name and a value part only if its words are numbers (or markers), so neither
    holds a parenthesis and the text was exactly that layout.
    """
    parts = text.split(") ")
    head, sep, first = parts[0].partition(" ((")
    time_tok = head[start:]
    if not time_tok.isdigit():
        if sep or not time_tok.endswith(")") or not time_tok[:-1].isdigit():
            return None
        return int(time_tok[:-1]), []  # "(see TIME)": no objects
    last = parts[-1]
    if not sep or len(parts) % 2 or not last.endswith("))"):
        return None
    parts[0] = "((" + first
    parts[-1] = last[:-2]
    return int(time_tok), parts


#: Token -> float() of the numbers in see messages. The server quantises them
#: (distances to 0.1 m after log quantisation, directions to whole degrees), so there
#: are only a few thousand distinct tokens; a dict lookup is ~3x cheaper than float().
#: Only canonical decimals are learnt (_SEE_DECIMAL: no sign but "-", no exponent,
#: no "_", finite), so a token found here is a valid number for the generic path too.
_SEE_NUMBERS: dict[str, float] = {}
_SEE_NUMBERS_MAX = 8192  # then cleared; the steady state holds ~1000 tokens
_SEE_DECIMAL = re.compile(r"-?[0-9]{1,9}(?:\.[0-9]{1,9})?")


def _learn_see_numbers(parts: list[str]) -> None:
    """Add the canonical decimals among the value parts' words to _SEE_NUMBERS; if they
    do not fit, the cache starts over with just them."""
    numbers = _SEE_NUMBERS
    words = set(" ".join(parts[1::2]).split(" "))
    if len(numbers) + len(words) > _SEE_NUMBERS_MAX:
        numbers.clear()
    numbers.update(
        (tok, float(tok)) for tok in words if tok not in numbers and _SEE_DECIMAL.fullmatch(tok)
    )


def _fast_see(text: str) -> SeeMessage | None:
    """``(see TIME ((NAME) V...) ...)`` in the server's layout, or None."""
    split = _split_objects(text, 5)
    if split is None:
        return None
    time, parts = split
    try:
        return _fast_see_objects(time, parts)
    except KeyError:  # a number not in _SEE_NUMBERS yet (or not a number)
        _learn_see_numbers(parts)
    try:
        return _fast_see_objects(time, parts)
    except KeyError:
        return None


_PLAYER_FIELDS_BY_COUNT = {
    1: ("direction",),
    2: ("distance", "direction"),
    3: ("distance", "direction", "point_dir"),
    4: ("distance", "direction", "dist_change", "dir_change"),
    6: ("distance", "direction", "dist_change", "dir_change", "body_dir", "head_dir"),
    7: ("distance", "direction", "dist_change", "dir_change", "body_dir", "head_dir", "point_dir"),
}
"""A seen player's fields by how many numbers follow its name (tackle/kick mark removed)."""


def _fast_see_objects(time: int, parts: list[str]) -> SeeMessage | None:
    """The objects of :func:`_fast_see`; KeyError for a word not in _SEE_NUMBERS."""
    names = _FAST_SEEN_NAMES
    moving = _FAST_SEEN_MOVING
    players = _PLAYER_NAMES
    num = _SEE_NUMBERS
    number = num.__getitem__
    objects = list(map(_new_object, repeat(SeenObject, len(parts) // 2)))
    it = iter(parts)
    for obj, name, vals in zip(objects, it, it):  # noqa: B905 (lengths match)
        # Fill the frozen instance's __dict__ directly (no __init__, see _seen); unset
        # fields keep the dataclass defaults, which live on the class.
        o = obj.__dict__
        known = names.get(name)
        if known is not None:
            o["kind"], o["name"], o["close"] = known
            first, sep, more = vals.partition(" ")
            if not sep:
                o["direction"] = num[vals]
            elif " " not in more:
                o["distance"] = num[first]
                o["direction"] = num[more]
            elif name in moving:
                direction, dist_chg, dir_chg = more.split(" ")
                o["distance"] = num[first]
                o["direction"] = num[direction]
                o["dist_change"] = num[dist_chg]
                o["dir_change"] = num[dir_chg]
            else:
                return None
        else:
            player = players.get(name) or _player_name(name)
            if player is None:
                return None
            o["kind"] = "player"
            o["name"] = "p"
            o["close"] = False
            o["team"], o["unum"], o["goalie"] = player
            v = vals.split(" ")
            last = v[-1]
            if last == "t":
                o["tackling"] = True
                del v[-1]
            elif last == "k":
                o["kicking"] = True
                del v[-1]
            if len(v) == 2:  # the usual case, assigned directly: the fast path's point
                o["distance"] = num[v[0]]
                o["direction"] = num[v[1]]
                continue
            fields = _PLAYER_FIELDS_BY_COUNT.get(len(v))
            if fields is None:
                return None
            o.update(zip(fields, map(number, v)))  # noqa: B905 (the count picked the fields)
    return _make_see(time, tuple(objects))


_CARD_MARKS_FAST = {"y": "yellow", "r": "red"}
_MARKERS_FAST = frozenset(_MARKERS)


def _fast_global(text: str, start: int, look: bool) -> GlobalView | None:
    """``(see_global TIME ...)`` / ``(ok look TIME ...)`` (TIME at ``start``)."""
    if _has_float_space(text):
        return None
    split = _split_objects(text, start)
    if split is None:
        return None
    time, parts = split
    if parts and "_" in text and "_" in " ".join(parts[1::2]):
        return None  # float() takes "1_0"
    make_player = _make_player
    ball: BallState | None = None
    players: list[PlayerState] = []
    goals: list[tuple[str, float, float]] = []
    total = 0.0
    it = iter(parts)
    for name, vals in zip(it, it):  # noqa: B905 (even length checked)
        v = vals.split(" ")
        if name.startswith("((p"):
            player = _player_name(name)
            if player is None or player[1] is None:
                return None
            card = _CARD_MARKS_FAST.get(v[-1])
            if card is not None:
                del v[-1]
            marker: str | None = v[-1]
            if marker in _MARKERS_FAST:
                del v[-1]
            else:
                marker = None
            nums = list(map(float, v))
            total += sum(nums)
            n = len(nums)
            if n == 6:
                point_dir = None
            elif n == 7:
                point_dir = nums[6]
            else:
                return None
            players.append(
                make_player(
                    nums[0],
                    nums[1],
                    nums[2],
                    nums[3],
                    nums[4],
                    nums[5],
                    player[1],  # unum
                    player[2],  # goalie
                    None,  # side
                    player[0],  # team
                    None,  # type_id
                    None,  # point_dist
                    point_dir,
                    None,  # focus_dist
                    None,  # focus_dir
                    None,  # stamina
                    None,  # effort
                    None,  # recovery
                    None,  # stamina_capacity
                    marker,
                    card,
                )
            )
        elif name == "((b" and ball is None and len(v) == 4:
            bx, by, bvx, bvy = map(float, v)
            total += bx + by + bvx + bvy
            ball = _make_ball(bx, by, bvx, bvy)
        elif name in _FAST_GOALS and len(v) == 2:
            gx, gy = map(float, v)
            total += gx + gy
            goals.append((_FAST_GOALS[name], gx, gy))
        else:
            return None
    if total - total != 0.0:
        return None
    return _make_global(time, ball, tuple(players), tuple(goals), look)


_NUM = r"(-?[0-9]+(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?)"
_INT = r"(-?[0-9]+)"
#: The v18 sense_body (serializerplayerstdv8/v13/v14/v18.cpp), every field in order.
_SENSE_BODY_V18 = re.compile(
    (
        r"\(sense_body INT \(view_mode (high|low) (narrow|normal|wide)\)"
        r" \(stamina NUM NUM NUM\) \(speed NUM NUM\) \(head_angle NUM\)"
        r" \(kick INT\) \(dash INT\) \(turn INT\) \(say INT\) \(turn_neck INT\)"
        r" \(catch INT\) \(move INT\) \(change_view INT\) \(change_focus INT\)"
        r" \(arm \(movable INT\) \(expires INT\) \(target NUM NUM\) \(count INT\)\)"
        r" \(focus \(target (?:none|([lr]) INT)\) \(count INT\)\)"
        r" \(tackle \(expires INT\) \(count INT\)\)"
        r" \(collision (none|\((?:ball|player|post)\)(?: \((?:ball|player|post)\))*)\)"
        r" \(foul \(charged INT\) \(card (none|yellow|red)\)\)"
        r" \(focus_point NUM NUM\)\)"
    )
    .replace("NUM", _NUM)
    .replace("INT", _INT)
)


def _fast_sense_body(text: str) -> SenseBody | None:
    """The v18 ``(sense_body ...)`` with all parts in server order, or None."""
    m = _SENSE_BODY_V18.fullmatch(text)
    if m is None:
        return None
    (
        time, quality, width, stamina, effort, capacity, speed, speed_dir, head,
        kick, dash, turn, say, turn_neck, catch, move, change_view, change_focus,
        movable, expires, target_dist, target_dir, arm_count,
        focus_side, focus_unum, focus_count, tackle_expires, tackle_count,
        collision, charged, card, focus_dist, focus_dir,
    ) = m.groups()  # fmt: skip
    floats = (
        float(stamina),
        float(effort),
        float(capacity),
        float(speed),
        float(speed_dir),
        float(head),
        float(target_dist),
        float(target_dir),
        float(focus_dist),
        float(focus_dir),
    )
    total = sum(floats)
    if total - total != 0.0:  # an overflow to inf, e.g. 1e999
        return None
    return _make_sense_body(
        int(time), quality, width, floats[0], floats[1], floats[2], floats[3], floats[4],
        floats[5],
        _make_counts(
            int(kick), int(dash), int(turn), int(say), int(turn_neck), int(catch),
            int(move), int(change_view), int(change_focus),
        ),
        _make_arm(int(movable), int(expires), floats[6], floats[7], int(arm_count)),
        None if focus_side is None else (focus_side, int(focus_unum)),
        int(focus_count), int(tackle_expires), int(tackle_count),
        () if collision == "none" else tuple(collision[1:-1].split(") (")),
        int(charged), card, (floats[8], floats[9]),
    )  # fmt: skip


_THINK = Think()  # no fields, immutable: one instance serves all

# Player forms (hear TIME SENDER MSG) for the referee/self/coaches and the said
# messages of other players; the trainer form (hear SENDER TIME MSG). MSG is a bare
# word or a quoted string of printable ASCII.
_HEAR_WORD = r'([-+_.a-zA-Z0-9]+|"[ !#-~]*")'
_HEAR_SENDER = r"(referee|self|online_coach_left|online_coach_right)"
_HEAR_PLAYER = re.compile(rf"\(hear ([0-9]+) {_HEAR_SENDER} {_HEAR_WORD}\)")
_HEAR_TRAINER = re.compile(rf"\(hear {_HEAR_SENDER} ([0-9]+) {_HEAR_WORD}\)")
_HEAR_SAID = re.compile(
    r'\(hear ([0-9]+) (-?[0-9]{1,3}(?:\.[0-9]{1,6})?) (?:our ([0-9]+)|(opp)) ("[ !#-~]*")\)'
)
_HEAR_SENDERS = frozenset(("referee", "self", "online_coach_left", "online_coach_right"))


def _fast_hear(text: str) -> Hear | None:
    """The usual ``(hear ...)`` forms (see _HEAR_PLAYER and co.), or None."""
    words = text[6:-1].split(" ")
    if len(words) == 3 and text[-1] == ")":
        # Referee announcements, by far the most frequent: a bare identifier message.
        first, second, msg = words
        if msg.isidentifier():  # ASCII here: [A-Za-z_][A-Za-z0-9_]*
            if first.isdigit() and second in _HEAR_SENDERS:
                return _make_hear(int(first), second, msg, None, None)
            if second.isdigit() and first in _HEAR_SENDERS:
                return _make_hear(int(second), first, msg, None, None)
    m = _HEAR_PLAYER.fullmatch(text)
    if m is not None:
        time, sender, msg = m.groups()
    else:
        m = _HEAR_TRAINER.fullmatch(text)
        if m is not None:
            sender, time, msg = m.groups()
        else:
            m = _HEAR_SAID.fullmatch(text)
            if m is None:
                return None
            time, direction, unum, opp, msg = m.groups()
            if opp is None:
                return _make_hear(int(time), "our", msg[1:-1], float(direction), int(unum))
            return _make_hear(int(time), "opp", msg[1:-1], float(direction), None)
    if msg[0] == '"':
        msg = msg[1:-1]
    return _make_hear(int(time), sender, msg, None, None)


def _fast_decode(text: str) -> Message | None:
    """Decode a hot message kind in its canonical layout; None means "use the generic
    path" (anything else, anything unusual and every malformed message)."""
    if len(text) > MAX_MESSAGE_CHARS or not text.isascii():
        return None
    try:
        if text.startswith("(se"):
            if text.startswith("(sense_body "):
                return _fast_sense_body(text)
            if text.startswith("(see "):
                return _fast_see(text)
            if text.startswith("(see_global "):
                return _fast_global(text, 12, False)
        elif text == "(think)":
            return _THINK
        elif text.startswith("(hear "):
            return _fast_hear(text)
        elif text.startswith("(ok look "):
            return _fast_global(text, 9, True)
    except (ValueError, IndexError, KeyError, TypeError, OverflowError):
        # float()/int() on a bad token, a piece without ") ", an empty name or value
        # list: not the canonical layout.
        return None
    return None


# --------------------------------------------------------------------------------------
# Dispatch
# --------------------------------------------------------------------------------------

Message: TypeAlias = (
    Init
    | CoachInit
    | Reconnect
    | Think
    | OkReply
    | TeamNames
    | ErrorReply
    | WarningReply
    | Score
    | ChangePlayerType
    | ServerParams
    | PlayerParams
    | PlayerType
    | SeeMessage
    | SenseBody
    | Hear
    | GlobalView
    | FullState
)
"""Every type :func:`parse_message` can return."""


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


# --------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------

# Sanity bound for arguments without a server range (positions, velocities): keeps
# datagrams short and catches unit mistakes.
_MAX_ABS = 1.0e4


def _fmt(x: float) -> str:
    """Format a number the way the server's lexer accepts it (no exponent)."""
    if float(x).is_integer():
        return str(int(x))
    text = f"{x:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "", "-") else text


def _finite(value: object, what: str) -> float:
    # numbers.Real covers int, float and numpy scalars; bools and strings are refused.
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{what} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{what} must be finite, got {value!r}")
    if abs(v) > _MAX_ABS:
        raise ValueError(f"{what}={v!r} is implausibly large (|value| > {_MAX_ABS:g})")
    return v


def _set(obj: object, name: str, value: object) -> None:
    # Frozen dataclasses: store the normalised (plain float) value once, at build time.
    object.__setattr__(obj, name, value)


def _in_range(value: float, lo: float, hi: float, what: str, names: str) -> str:
    if not lo <= value <= hi:
        raise ValueError(
            f"{what}={value!r} is outside the server range [{_fmt(lo)}, {_fmt(hi)}] "
            f"(server_param {names})"
        )
    return _fmt(value)


_TEAM_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_+-")
# Characters the server accepts inside a quoted say message (src/player_command_tok.lpp).
_SAY_CHARS = frozenset("0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz().+-*/?<>_ ")


def _team(name: object) -> str:
    if not isinstance(name, str) or not 1 <= len(name) <= 15 or not set(name) <= _TEAM_CHARS:
        raise ValueError(
            f"team name {name!r} must be 1-15 characters of A-Z a-z 0-9 _ + - "
            "(server sscanf %15[+-_a-zA-Z0-9] in src/stadium.cpp)"
        )
    return name


def _unum(unum: object) -> int:
    if isinstance(unum, bool) or not isinstance(unum, int) or not 1 <= unum <= 11:
        raise ValueError(f"uniform number {unum!r} must be an int in [1, 11]")
    return unum


def _version(version: object) -> int:
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= 19:
        raise ValueError(f"protocol version {version!r} must be an int in [1, 19]")
    return version


class Command(abc.ABC):
    """A client command. ``encode()`` returns the NUL-free ASCII text as bytes;
    :func:`datagram` frames one or more commands for sending.

    Numbers are checked for finiteness when the command is built; ranges that depend
    on server parameters are checked in ``encode(params)`` against ``params`` or,
    if None, the rcssserver 19 defaults (:meth:`ServerParams.defaults`).
    """

    __slots__ = ()

    @abc.abstractmethod
    def to_text(self, params: ServerParams | None = None) -> str:
        """Return the command text, validating ranges against ``params``."""

    def encode(self, params: ServerParams | None = None) -> bytes:
        """Return the command as ASCII bytes without a NUL terminator."""
        return self.to_text(params).encode("ascii")


def _params(params: ServerParams | None) -> ServerParams:
    return params if params is not None else _DEFAULT_PARAMS


@dataclass(frozen=True, slots=True)
class InitPlayer(Command):
    """``(init TEAM (version V))`` or, for a goalie, ``(init TEAM (version V) (goalie))``."""

    team: str
    version: int = 18
    goalie: bool = False

    def __post_init__(self) -> None:
        _team(self.team)
        _version(self.version)

    def to_text(self, params: ServerParams | None = None) -> str:
        goalie = " (goalie)" if self.goalie else ""
        return f"(init {self.team} (version {self.version}){goalie})"


@dataclass(frozen=True, slots=True)
class ReconnectPlayer(Command):
    """``(reconnect TEAM UNUM)`` (refused by the server during play_on)."""

    team: str
    unum: int

    def __post_init__(self) -> None:
        _team(self.team)
        _unum(self.unum)

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"(reconnect {self.team} {self.unum})"


@dataclass(frozen=True, slots=True)
class _Bare(Command):
    WORD: ClassVar[str] = ""

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"({self.WORD})"


@dataclass(frozen=True, slots=True)
class Bye(_Bare):
    """``(bye)``: disconnect the player (or trainer)."""

    WORD: ClassVar[str] = "bye"


@dataclass(frozen=True, slots=True)
class Done(_Bare):
    """``(done)``: end of this client's commands for the cycle (synch mode). Send
    exactly one per ``(think)``; an extra one shifts later actions by a cycle."""

    WORD: ClassVar[str] = "done"


@dataclass(frozen=True, slots=True)
class SynchSee(_Bare):
    """``(synch_see)``: see messages at cycle start (automatic for v18+)."""

    WORD: ClassVar[str] = "synch_see"


@dataclass(frozen=True, slots=True)
class NoOp(Command):
    """The "no move" action: encodes to no bytes, so only ``(done)`` is sent and the
    player coasts while its stamina recovers."""

    def to_text(self, params: ServerParams | None = None) -> str:
        return ""


@dataclass(frozen=True, slots=True)
class Dash(Command):
    """``(dash POWER [DIR])``: POWER in [min_dash_power, max_dash_power] ([0, 100]
    since v17), DIR in degrees relative to the body within [min_dash_angle,
    max_dash_angle]."""

    power: float
    direction: float | None = None

    def __post_init__(self) -> None:
        _set(self, "power", _finite(self.power, "dash power"))
        if self.direction is not None:
            _set(self, "direction", _finite(self.direction, "dash direction"))

    def to_text(self, params: ServerParams | None = None) -> str:
        p = _params(params)
        power = _in_range(
            float(self.power),
            p.min_dash_power,
            p.max_dash_power,
            "dash power",
            "min_dash_power/max_dash_power",
        )
        if self.direction is None:
            return f"(dash {power})"
        direction = _in_range(
            float(self.direction),
            p.min_dash_angle,
            p.max_dash_angle,
            "dash direction",
            "min_dash_angle/max_dash_angle",
        )
        return f"(dash {power} {direction})"


@dataclass(frozen=True, slots=True)
class Turn(Command):
    """``(turn MOMENT)``: MOMENT in degrees within [minmoment, maxmoment]; the actual
    turn shrinks with speed (inertia)."""

    moment: float

    def __post_init__(self) -> None:
        _set(self, "moment", _finite(self.moment, "turn moment"))

    def to_text(self, params: ServerParams | None = None) -> str:
        p = _params(params)
        return (
            "(turn "
            + _in_range(
                float(self.moment), p.min_moment, p.max_moment, "turn moment", "minmoment/maxmoment"
            )
            + ")"
        )


@dataclass(frozen=True, slots=True)
class TurnNeck(Command):
    """``(turn_neck MOMENT)``: within [minneckmoment, maxneckmoment]; the neck itself
    stays within [minneckang, maxneckang]."""

    moment: float

    def __post_init__(self) -> None:
        _set(self, "moment", _finite(self.moment, "turn_neck moment"))

    def to_text(self, params: ServerParams | None = None) -> str:
        p = _params(params)
        return (
            "(turn_neck "
            + _in_range(
                float(self.moment),
                p.min_neck_moment,
                p.max_neck_moment,
                "turn_neck moment",
                "minneckmoment/maxneckmoment",
            )
            + ")"
        )


@dataclass(frozen=True, slots=True)
class Kick(Command):
    """``(kick POWER DIR)``: POWER in [minpower, maxpower], DIR relative to the body in
    [minmoment, maxmoment]."""

    power: float
    direction: float

    def __post_init__(self) -> None:
        _set(self, "power", _finite(self.power, "kick power"))
        _set(self, "direction", _finite(self.direction, "kick direction"))

    def to_text(self, params: ServerParams | None = None) -> str:
        p = _params(params)
        power = _in_range(
            float(self.power), p.min_power, p.max_power, "kick power", "minpower/maxpower"
        )
        direction = _in_range(
            float(self.direction),
            p.min_moment,
            p.max_moment,
            "kick direction",
            "minmoment/maxmoment",
        )
        return f"(kick {power} {direction})"


@dataclass(frozen=True, slots=True)
class Tackle(Command):
    """``(tackle DIR [on|off])``: DIR relative to the body in [minmoment, maxmoment]
    (v12+ meaning); ``foul`` True sends ``on`` (intentional foul), False ``off``, None
    omits the flag."""

    direction: float
    foul: bool | None = None

    def __post_init__(self) -> None:
        _set(self, "direction", _finite(self.direction, "tackle direction"))
        if self.foul is not None and not isinstance(self.foul, bool):
            raise ValueError(f"tackle foul must be a bool or None, got {self.foul!r}")

    def to_text(self, params: ServerParams | None = None) -> str:
        p = _params(params)
        direction = _in_range(
            float(self.direction),
            p.min_moment,
            p.max_moment,
            "tackle direction",
            "minmoment/maxmoment",
        )
        if self.foul is None:
            return f"(tackle {direction})"
        return f"(tackle {direction} {'on' if self.foul else 'off'})"


@dataclass(frozen=True, slots=True)
class Catch(Command):
    """``(catch DIR)`` (goalie only): DIR in [min_catch_angle, max_catch_angle]."""

    direction: float

    def __post_init__(self) -> None:
        _set(self, "direction", _finite(self.direction, "catch direction"))

    def to_text(self, params: ServerParams | None = None) -> str:
        p = _params(params)
        return (
            "(catch "
            + _in_range(
                float(self.direction),
                p.min_catch_angle,
                p.max_catch_angle,
                "catch direction",
                "min_catch_angle/max_catch_angle",
            )
            + ")"
        )


@dataclass(frozen=True, slots=True)
class Move(Command):
    """Player ``(move X Y)`` in the team's own frame (right team mirrored); only
    honoured before kick-off, after a goal, or by a goalie after a catch."""

    x: float
    y: float

    def __post_init__(self) -> None:
        _set(self, "x", _finite(self.x, "move x"))
        _set(self, "y", _finite(self.y, "move y"))

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"(move {_fmt(self.x)} {_fmt(self.y)})"


@dataclass(frozen=True, slots=True)
class ChangeView(Command):
    """``(change_view WIDTH [QUALITY])``; WIDTH narrow|normal|wide, QUALITY high|low
    (low is silently refused in synch-see mode)."""

    width: str
    quality: str | None = None

    def __post_init__(self) -> None:
        if self.width not in _VIEW_WIDTHS:
            raise ValueError(f"view width {self.width!r} must be one of {_VIEW_WIDTHS}")
        if self.quality is not None and self.quality not in _VIEW_QUALITIES:
            raise ValueError(f"view quality {self.quality!r} must be one of {_VIEW_QUALITIES}")

    def to_text(self, params: ServerParams | None = None) -> str:
        if self.quality is None:
            return f"(change_view {self.width})"
        return f"(change_view {self.width} {self.quality})"


@dataclass(frozen=True, slots=True)
class Say(Command):
    """``(say "MSG")``: MSG of at most ``say_msg_size`` (10) characters from
    ``0-9A-Za-z().+-*/?<>_`` and space."""

    message: str

    def __post_init__(self) -> None:
        if not isinstance(self.message, str) or not self.message:
            raise ValueError(f"say message must be a non-empty str, got {self.message!r}")
        bad = set(self.message) - _SAY_CHARS
        if bad:
            raise ValueError(
                f"say message {self.message!r} contains {''.join(sorted(bad))!r}; "
                "allowed: 0-9 A-Z a-z ( ) . + - * / ? < > _ and space"
            )

    def to_text(self, params: ServerParams | None = None) -> str:
        limit = _params(params).say_msg_size
        if len(self.message) > limit:
            raise ValueError(
                f"say message {self.message!r} has {len(self.message)} characters; "
                f"the server allows at most {limit} (server_param say_msg_size)"
            )
        return f'(say "{self.message}")'


_EAR_TEAMS = ("our", "opp", "left", "right")
_EAR_MODES = ("partial", "complete")


@dataclass(frozen=True, slots=True)
class Ear(Command):
    """Player ``(ear (on|off [TEAM] [partial|complete]))``; TEAM is our, opp, left,
    right or a team name."""

    on: bool
    team: str | None = None
    mode: str | None = None

    def __post_init__(self) -> None:
        if self.team is not None and self.team not in _EAR_TEAMS:
            _team(self.team)
        if self.mode is not None and self.mode not in _EAR_MODES:
            raise ValueError(f"ear mode {self.mode!r} must be one of {_EAR_MODES}")

    def to_text(self, params: ServerParams | None = None) -> str:
        words = ["on" if self.on else "off"]
        if self.team is not None:
            words.append(self.team)
        if self.mode is not None:
            words.append(self.mode)
        return f"(ear ({' '.join(words)}))"


# Trainer (offline coach) commands, src/coach.cpp Coach::parse_command.


@dataclass(frozen=True, slots=True)
class InitTrainer(Command):
    """Trainer ``(init (version V))`` on the coach port (6001)."""

    version: int = 18

    def __post_init__(self) -> None:
        _version(self.version)

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"(init (version {self.version}))"


@dataclass(frozen=True, slots=True)
class ChangeMode(Command):
    """Trainer ``(change_mode MODE)`` with MODE one of :data:`PLAY_MODES`."""

    mode: str

    def __post_init__(self) -> None:
        if self.mode not in PLAY_MODES:
            raise ValueError(f"play mode {self.mode!r} is not one of the server's play modes")

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"(change_mode {self.mode})"


@dataclass(frozen=True, slots=True)
class MoveBall(Command):
    """Trainer ``(move (ball) X Y)`` (velocity zeroed) or, with a velocity,
    ``(move (ball) X Y 0 VX VY)``: the server's parser reads an angle before the
    velocity (ignored for the ball) and rejects a five-number form."""

    x: float
    y: float
    vx: float | None = None
    vy: float | None = None

    def __post_init__(self) -> None:
        _set(self, "x", _finite(self.x, "ball x"))
        _set(self, "y", _finite(self.y, "ball y"))
        if (self.vx is None) != (self.vy is None):
            raise ValueError("give both ball vx and vy or neither")
        if self.vx is not None:
            _set(self, "vx", _finite(self.vx, "ball vx"))
            _set(self, "vy", _finite(self.vy, "ball vy"))

    def to_text(self, params: ServerParams | None = None) -> str:
        if self.vx is None or self.vy is None:
            return f"(move (ball) {_fmt(self.x)} {_fmt(self.y)})"
        return f"(move (ball) {_fmt(self.x)} {_fmt(self.y)} 0 {_fmt(self.vx)} {_fmt(self.vy)})"


@dataclass(frozen=True, slots=True)
class MovePlayer(Command):
    """Trainer ``(move (player TEAM UNUM) X Y [DIR [VX VY]])`` in the global frame.
    Without VX VY the player keeps its old velocity (src/coach.cpp parse_move); DIR in
    degrees within [minmoment, maxmoment]."""

    team: str
    unum: int
    x: float
    y: float
    direction: float | None = None
    vx: float | None = None
    vy: float | None = None

    def __post_init__(self) -> None:
        _team(self.team)
        _unum(self.unum)
        _set(self, "x", _finite(self.x, "player x"))
        _set(self, "y", _finite(self.y, "player y"))
        if (self.vx is None) != (self.vy is None):
            raise ValueError("give both player vx and vy or neither")
        if self.vx is not None and self.direction is None:
            raise ValueError("a player velocity needs a direction too (server syntax)")
        if self.direction is not None:
            _set(self, "direction", _finite(self.direction, "player direction"))
        if self.vx is not None:
            _set(self, "vx", _finite(self.vx, "player vx"))
            _set(self, "vy", _finite(self.vy, "player vy"))

    def to_text(self, params: ServerParams | None = None) -> str:
        text = f"(move (player {self.team} {self.unum}) {_fmt(self.x)} {_fmt(self.y)}"
        if self.direction is not None:
            p = _params(params)
            text += " " + _in_range(
                float(self.direction),
                p.min_moment,
                p.max_moment,
                "player direction",
                "minmoment/maxmoment",
            )
            if self.vx is not None and self.vy is not None:
                text += f" {_fmt(self.vx)} {_fmt(self.vy)}"
        return text + ")"


@dataclass(frozen=True, slots=True)
class Recover(_Bare):
    """Trainer ``(recover)``: refill stamina, recovery, effort of all players."""

    WORD: ClassVar[str] = "recover"


@dataclass(frozen=True, slots=True)
class Start(_Bare):
    """Trainer ``(start)``: kick off."""

    WORD: ClassVar[str] = "start"


@dataclass(frozen=True, slots=True)
class Look(_Bare):
    """Trainer ``(look)``: one ``(ok look TIME ...)`` snapshot."""

    WORD: ClassVar[str] = "look"


@dataclass(frozen=True, slots=True)
class RequestTeamNames(_Bare):
    """Trainer ``(team_names)`` -> ``(ok team_names ...)``."""

    WORD: ClassVar[str] = "team_names"


@dataclass(frozen=True, slots=True)
class Eye(Command):
    """Trainer ``(eye on|off)``: a ``see_global`` every cycle; with eye on the server
    also sends the trainer ``(think)`` and waits for its ``(done)``."""

    on: bool

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"(eye {'on' if self.on else 'off'})"


@dataclass(frozen=True, slots=True)
class TrainerEar(Command):
    """Trainer ``(ear on|off)``: hear players' and referee messages."""

    on: bool

    def to_text(self, params: ServerParams | None = None) -> str:
        return f"(ear {'on' if self.on else 'off'})"


_DEFAULT_PARAMS = ServerParams.defaults()


def datagram(*commands: Command, params: ServerParams | None = None) -> bytes:
    """Join commands into one datagram terminated by the NUL byte the server expects.

    ``datagram(Dash(60, 0), Done())`` -> ``b"(dash 60 0)(done)\\x00"``. :class:`NoOp`
    contributes nothing.
    """
    return b"".join(c.encode(params) for c in commands) + b"\x00"
