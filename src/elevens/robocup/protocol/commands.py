"""The commands a player or the offline trainer sends, each a frozen dataclass with encode()."""

from __future__ import annotations

import abc
import math
import numbers
from dataclasses import dataclass
from typing import ClassVar

from elevens.robocup.protocol.messages import (
    _VIEW_QUALITIES,
    _VIEW_WIDTHS,
    PLAY_MODES,
    ServerParams,
)

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
