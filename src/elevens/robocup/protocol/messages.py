"""The rcssserver messages as frozen dataclasses, and the generic decoders that build them from
s-expression trees."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import ClassVar, TypeAlias, TypeVar

from elevens.robocup.protocol.sexp import (
    _SIDES,
    ProtocolError,
    Sexp,
    _arity,
    _atom,
    _bad,
    _choice,
    _excerpt,
    _f,
    _i,
    _list,
    _quoted,
    sexp_to_text,
)

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
# server sent in tests/data/rcss/server_param.txt) for the values we use.
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

