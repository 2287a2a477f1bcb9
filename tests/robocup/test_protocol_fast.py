"""The fast paths of :func:`elevens.robocup.protocol.parse_message` against the generic one.

``parse_message`` first tries a fast decoder for the hot message kinds (see, sense_body,
see_global, ok look, hear, think); it returns a message only when the text is in the
server's canonical layout and otherwise hands over to the generic path (tokenizer, tree
builder, typed decoders), which is the original parser, unchanged, and which produces
every error message. So the contract tested here is:

* for every real message the fast path answers, and equals the generic path exactly
  (``==`` and ``repr``, so also int/float and -0.0 agree);
* for any text, the fast path either declines (None) or returns exactly what the
  generic path returns; it never accepts what the generic path rejects, never raises,
  never hangs; ``parse_message`` raises nothing but :class:`ProtocolError`.
"""

from __future__ import annotations

import dataclasses
import json
import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from elevens.robocup import protocol as proto
from elevens.robocup.protocol import (
    ArmState,
    BallState,
    CommandCounts,
    GlobalView,
    Hear,
    PlayerState,
    ProtocolError,
    SafeParser,
    SeeMessage,
    SenseBody,
    Think,
    parse_message,
)
from elevens.robocup.protocol import fast as proto_fast
from elevens.robocup.protocol import parse as proto_parse

DATA = Path(__file__).resolve().parents[1] / "data" / "rcss"
FILES = sorted(p.name for p in DATA.glob("*.txt"))


def _lines(name: str) -> list[str]:
    return [line.split("\t", 1)[1] for line in (DATA / name).read_text().splitlines() if line]


ALL = [(name, msg) for name in FILES for msg in _lines(name)]
KNOWN_POSE = [see for _, _, see in json.loads((DATA / "see_at_known_pose.json").read_text())]
#: Message kinds that have a fast path, and the transcripts holding them.
FAST_FILES = {
    "see.txt",
    "see_midgame.txt",
    "sense_body.txt",
    "see_global.txt",
    "see_global_midgame.txt",
    "ok_look.txt",
    "hear.txt",
    "hear_referee.txt",
    "think.txt",
}
HOT = [msg for name, msg in ALL if name in FAST_FILES] + KNOWN_POSE

_REJECTED = object()


def _generic(text: str) -> object:
    try:
        return proto_parse._parse_generic(proto_parse._clean(text))
    except ProtocolError:
        return _REJECTED


def _check(text: str | bytes) -> None:
    """The contract for one input (see the module docstring)."""
    clean = proto_parse._clean(text)
    fast = proto_fast._fast_decode(clean)  # must not raise
    generic = _generic(clean)
    if fast is not None:
        assert generic is not _REJECTED, f"fast path accepted what the generic rejects: {clean!r}"
        assert type(fast) is type(generic)
        assert fast == generic, clean
        assert repr(fast) == repr(generic), clean
    try:
        parsed = parse_message(text)
    except ProtocolError:
        assert generic is _REJECTED
    else:
        assert parsed == generic and repr(parsed) == repr(generic)


# --------------------------------------------------------------------------------------
# Every transcript line
# --------------------------------------------------------------------------------------


def test_transcripts_are_all_covered() -> None:
    assert FILES and set(FILES) >= FAST_FILES
    assert len(HOT) > 250


@pytest.mark.parametrize("name", FILES)
def test_every_transcript_line_equals_the_generic_parser(name: str) -> None:
    for msg in _lines(name):
        generic = proto_parse._parse_generic(msg)
        for data in (msg, msg.encode() + b"\x00", bytearray(msg.encode()), "  " + msg + "\x00"):
            parsed = parse_message(data)
            assert parsed == generic and repr(parsed) == repr(generic), msg[:80]
        fast = proto_fast._fast_decode(msg)
        if name in FAST_FILES:
            # The hot kinds really take the fast path (else this compares nothing).
            assert fast is not None, msg[:80]
            assert type(fast) is type(generic) and fast == generic and repr(fast) == repr(generic)
        else:
            assert fast is None


def test_known_pose_sees_equal_the_generic_parser() -> None:
    for msg in KNOWN_POSE:
        fast = proto_fast._fast_decode(msg)
        assert fast is not None and fast == proto_parse._parse_generic(msg)
        assert repr(fast) == repr(proto_parse._parse_generic(msg))


def test_fast_objects_behave_like_generic_ones() -> None:
    # Same classes, hashable alike, usable with dataclasses.replace / asdict, picklable.
    import pickle

    for msg in HOT[::7]:
        fast = proto_fast._fast_decode(msg)
        generic = proto_parse._parse_generic(msg)
        assert hash(fast) == hash(generic)
        assert pickle.loads(pickle.dumps(fast)) == generic
        if dataclasses.is_dataclass(fast):
            assert dataclasses.asdict(fast) == dataclasses.asdict(generic)  # type: ignore[arg-type]
            assert dataclasses.replace(fast) == generic
    see = proto_fast._fast_decode(KNOWN_POSE[0])
    assert isinstance(see, SeeMessage)
    with pytest.raises(dataclasses.FrozenInstanceError):
        see.objects[0].distance = 1.0  # type: ignore[misc]


def test_think_and_hear_forms() -> None:
    assert parse_message("(think)") == Think()
    forms = [
        ("(hear 0 referee play_on)", Hear(0, "referee", "play_on")),
        ("(hear referee 102 goal_l_1)", Hear(102, "referee", "goal_l_1")),
        ('(hear 12 self "pass (x) 3")', Hear(12, "self", "pass (x) 3")),
        ('(hear 12 -30 our 5 "go")', Hear(12, "our", "go", -30.0, 5)),
        ('(hear 12 45.5 opp "(x y)")', Hear(12, "opp", "(x y)", 45.5)),
        ("(hear 12 online_coach_left hi)", Hear(12, "online_coach_left", "hi")),
    ]
    for text, expected in forms:
        assert proto_fast._fast_decode(text) == expected == proto_parse._parse_generic(text)
    # Forms left to the generic path.
    for text in ("(hear 12 our 5)", "(hear 12 opp)", '(hear 12 -3 "old")', "(hear 1 nan x)"):
        assert proto_fast._fast_decode(text) is None
        _check(text)


def test_sense_body_fast_path_needs_the_v18_layout() -> None:
    sb = _lines("sense_body.txt")[0]
    assert isinstance(proto_fast._fast_decode(sb), SenseBody)
    for text in (
        sb.replace("(collision none)", "(collision (ball) (post))"),
        sb.replace("(focus (target none)", "(focus (target r 7)"),
        sb.replace("(card none)", "(card yellow)"),
        sb.replace("(stamina 8000 1 130600)", "(stamina 7.5e+03 1 1.306e+05)"),
    ):
        fast = proto_fast._fast_decode(text)
        assert isinstance(fast, SenseBody) and fast == proto_parse._parse_generic(text)
    # Other layouts and bad values: generic path (parses or rejects).
    for text in (
        sb.replace("(head_angle 0)", "(head_angle 1e999)"),
        sb.replace("(head_angle 0)", "(head_angle nan)"),
        sb.replace("(kick 0) (dash 0)", "(dash 0) (kick 0)"),
        sb.replace("(focus_point 0 0)", ""),
        sb.replace(" (view_mode", "  (view_mode"),
        sb.replace("(speed 0 0)", "(speed 0 0 0)"),
    ):
        assert proto_fast._fast_decode(text) is None
        _check(text)


def test_see_and_see_global_fast_path_declines_the_unusual() -> None:
    see = _lines("see_midgame.txt")[1]
    sg = _lines("see_global_midgame.txt")[0]
    declined = [
        see.replace(" ((", "\t((", 1),  # tab: valid, generic path
        see.replace(") ", ")  ", 1),  # double space: valid, generic path
        see.replace("((f c) ", "((f c l) ", 1),  # custom flag: valid, generic path
        see.replace("20.9", "2.09e1", 1),  # exponent: valid, generic path
        see.replace("20.9", "1_0", 1),
        see.replace("20.9", "nan", 1),
        see.replace("20.9", "\u0661", 1),  # Arabic-Indic digit one
        see.replace('"LeftTeam"', '"Left Team"', 1),
        see[:-1],
        see + ")",
        sg.replace("-0.0145666", "inf", 1),
        sg.replace("-0.0145666", "1e999", 1),
        sg.replace("-0.0145666", "1_0", 1),
        sg.replace("((b)", "((b) 1 2 3 4) ((b)", 1),  # two balls: rejected
        sg.replace(" t)", " q)", 1),
        sg.replace("-0.0145666", "-0.0145666\x0b", 1),
    ]
    for text in declined:
        assert proto_fast._fast_decode(text) is None, text[:120]
        _check(text)


def test_see_number_cache_learns_only_canonical_decimals(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(proto_fast, "_SEE_NUMBERS", {})
    see = _lines("see_midgame.txt")[1]
    assert proto_fast._fast_decode(see) == proto_parse._parse_generic(see)
    numbers = proto_fast._SEE_NUMBERS
    assert numbers and all(proto_fast._SEE_DECIMAL.fullmatch(tok) for tok in numbers)
    assert all(numbers[tok] == float(tok) for tok in numbers)
    assert "t" not in numbers and "k" not in numbers
    # A full cache is cleared, not grown; results stay exact.
    monkeypatch.setattr(proto_fast, "_SEE_NUMBERS_MAX", 40)
    for msg in _lines("see.txt") + _lines("see_midgame.txt"):
        assert proto_fast._fast_decode(msg) == proto_parse._parse_generic(msg)
        assert len(proto_fast._SEE_NUMBERS) <= 40 + msg.count(" ")
    for tok in ("1e5", "+1", ".5", "5.", "1_0", "nan", "0x1", "1234567890"):
        proto_fast._SEE_NUMBERS.clear()
        proto_fast._fast_decode(f"(see 1 ((f c) {tok} 2))")
        assert tok not in proto_fast._SEE_NUMBERS


def test_player_name_cache_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(proto_fast, "_PLAYER_NAMES", {})
    monkeypatch.setattr(proto_fast, "_PLAYER_NAMES_MAX", 5)
    for k in range(20):
        text = f'(see 1 ((p "T{k}" 3) 1 2) ((p "T{k}" 4 goalie) 1 2 0 0 3 4 k))'
        assert proto_fast._fast_decode(text) == proto_parse._parse_generic(text)
    assert len(proto_fast._PLAYER_NAMES) == 5


def test_slot_builder_matches_the_dataclass_init() -> None:
    for cls, values in (
        (BallState, (1.0, 2.0, 3.0, 4.0)),
        (ArmState, (1, 2, 3.0, 4.0, 5)),
        (CommandCounts, tuple(range(9))),
        (PlayerState, tuple(range(21))),
        (GlobalView, (1, None, (), (), True)),
    ):
        make = proto_fast._slot_builder(cls)
        built = make(*values)
        assert type(built) is cls
        assert built == cls(*values) and repr(built) == repr(cls(*values))
        assert hash(built) == hash(cls(*values))
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(built, dataclasses.fields(cls)[0].name, 0)
    with pytest.raises(TypeError, match="plain slots dataclass"):
        proto_fast._slot_builder(proto.SeenObject)


def test_safe_parser_uses_the_fast_path_and_counts() -> None:
    parser = SafeParser()
    for msg in HOT:
        assert parser.parse(msg.encode() + b"\x00") is not None
    assert parser.stats.total_errors == 0 and parser.stats.total_parsed == len(HOT)


# --------------------------------------------------------------------------------------
# Properties: random damage to real messages
# --------------------------------------------------------------------------------------

FUZZ = settings(
    max_examples=300, deadline=2000, database=None, suppress_health_check=[HealthCheck.too_slow]
)
SAMPLE = sorted(set(HOT), key=len)

#: Replacement words: numbers in every format float() takes or rejects, names,
#: markers, quotes and whitespace that the fast paths must treat exactly as the
#: generic path does.
WORDS = [
    "0",
    "-0",
    "7",
    "-12.5",
    "0.1",
    "1e5",
    "1E-05",
    "2.5e+03",
    "+3",
    ".5",
    "5.",
    "-.5",
    "1_0",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "1e999",
    "9" * 400,
    "0x10",
    "",
    "\u0663",
    "\u00b2",
    "t",
    "k",
    "f",
    "y",
    "r",
    "goalie",
    "none",
    "ball",
    "p",
    "b",
    "g",
    "l",
    "F",
    "P",
    '"A"',
    '"A B"',
    '""',
    '"',
    "(",
    ")",
    "()",
    "((f c)",
    "\t",
    "\n",
    "\x0b",
    "\x0c",
    "\x1c",
    "\x00",
    "\x7f",
    "\xa0",
    "  ",
    "high",
    "wide",
    "play_on",
    "referee",
    "our",
    "opp",
]


@FUZZ
@given(st.sampled_from(SAMPLE), st.data())
def test_truncations(msg: str, data: st.DataObject) -> None:
    cut = data.draw(st.integers(0, len(msg)))
    _check(msg[:cut])
    _check(msg[cut:])
    _check(msg[:cut] + ")")
    _check(msg[:cut] + "))")


@FUZZ
@given(st.sampled_from(SAMPLE), st.data())
def test_word_replacements(msg: str, data: st.DataObject) -> None:
    words = msg.split(" ")
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(words) - 1))
        word = words[i]
        new = data.draw(st.sampled_from(WORDS))
        # Keep the parentheses around the word half of the time.
        if data.draw(st.booleans()):
            head = len(word) - len(word.lstrip("("))
            tail = len(word) - len(word.rstrip(")"))
            new = word[:head] + new + word[len(word) - tail :]
        words[i] = new
    _check(" ".join(words))


@FUZZ
@given(st.sampled_from(SAMPLE), st.data())
def test_character_mutations(msg: str, data: st.DataObject) -> None:
    chars = list(msg)
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(chars) - 1))
        op = data.draw(st.integers(0, 2))
        ch = data.draw(st.sampled_from('() "x0-._\t\n\x0b\x00\xe9e5tk'))
        if op == 0:
            chars[i] = ch
        elif op == 1:
            chars.insert(i, ch)
        else:
            del chars[i]
    _check("".join(chars))


@FUZZ
@given(st.sampled_from(SAMPLE), st.randoms(use_true_random=False))
def test_object_shuffles_drops_and_duplicates(msg: str, rnd: random.Random) -> None:
    tree = proto.parse_sexp(msg)
    items = list(tree[2:]) if len(tree) > 2 else []
    if items:
        for _ in range(rnd.randint(1, 3)):
            op = rnd.random()
            i = rnd.randrange(len(items))
            if op < 0.3:
                items.insert(rnd.randrange(len(items) + 1), items[i])
            elif op < 0.5 and len(items) > 1:
                del items[i]
            elif op < 0.8:
                rnd.shuffle(items)
            elif isinstance(items[i], tuple) and len(items[i]) > 1:
                # Drop or duplicate a value inside an object.
                obj = list(items[i])
                j = rnd.randrange(1, len(obj))
                if rnd.random() < 0.5:
                    del obj[j]
                else:
                    obj.insert(j, obj[j])
                items[i] = tuple(obj)
    _check(proto.sexp_to_text((*tree[:2], *items)))


_NUMBER = st.one_of(
    st.integers(-200, 200).map(str),
    st.floats(-200, 200, allow_nan=False).map(lambda v: f"{v:.1f}"),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["-0", "0", "1e-05", "+1", "1_0", "nan"]),
)
_SEE_NAME = st.sampled_from(
    ["f c", "f r t 10", "g l", "l b", "b", "B", "F", "G", "P", "p", 'p "A"', 'p "A" 3']
    + ['p "A" 1 goalie', "f q", 'p "A" x', "f c l", 'p "A_B" 9', "l x", 'p "A" 3 captain']
)


@FUZZ
@given(
    st.integers(0, 6000),
    st.lists(
        st.tuples(
            _SEE_NAME, st.lists(_NUMBER, min_size=0, max_size=8), st.sampled_from(["", " t", " k"])
        ),
        max_size=12,
    ),
)
def test_generated_see_messages(time_: int, objects: list[tuple[str, list[str], str]]) -> None:
    body = "".join(f" (({name}) {' '.join(values)}{mark})" for name, values, mark in objects)
    _check(f"(see {time_}{body})")


_GLOBAL_NAME = st.sampled_from(
    ["b", "g l", "g r", 'p "A" 1', 'p "B" 11 goalie', "p", 'p "A"', "g x", "f c"]
)


@FUZZ
@given(
    st.integers(0, 6000),
    st.booleans(),
    st.lists(
        st.tuples(
            _GLOBAL_NAME,
            st.lists(_NUMBER, min_size=0, max_size=8),
            st.sampled_from(["", " t", " k", " f", " y", " r", " t y", " k r", " y t"]),
        ),
        max_size=12,
    ),
)
def test_generated_global_views(
    time_: int, look: bool, objects: list[tuple[str, list[str], str]]
) -> None:
    body = "".join(f" (({name}) {' '.join(values)}{mark})" for name, values, mark in objects)
    head = "ok look" if look else "see_global"
    _check(f"({head} {time_}{body})")


def test_pathological_inputs_are_parsed_or_refused() -> None:
    see = _lines("see_midgame.txt")[1]
    bombs = [
        "(see 1" + " ((f c) 1 2)" * 6000 + ")",
        "(see 1 " + "((" * 30000,
        "(see 1 ((f c) " + "1 " * 30000 + "2))",
        "(sense_body 1 " + "(kick 0) " * 7000 + ")",
        "(see_global 1" + ' ((p "A" 1) 1 2 3 4 5 6 t)' * 2000 + ")",
        see * 60,
        "(hear 1 referee " + "x" * 60000 + ")",
    ]
    for text in bombs:  # each parses, or is refused by a limit (length, depth), never crashes
        _check(text)
