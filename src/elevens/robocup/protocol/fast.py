"""Fast paths for the hot messages (see, sense_body, see_global, hear, think): the server's
canonical layout read directly, or None for the generic path."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import fields
from itertools import repeat
from typing import TypeAlias, TypeVar

from elevens.robocup.protocol.messages import (
    _MARKERS,
    _SEEN_NAMES,
    ArmState,
    BallState,
    CommandCounts,
    GlobalView,
    Hear,
    Message,
    PlayerState,
    SeeMessage,
    SeenObject,
    SenseBody,
    Think,
    _new_object,
)
from elevens.robocup.protocol.sexp import (
    MAX_MESSAGE_CHARS,
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


