"""rcssserver 19 protocol: parsing real transcripts, commands, malformed input, fuzzing."""

from __future__ import annotations

import contextlib
import logging
import math
import random
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from elevens.robocup import protocol as proto
from elevens.robocup.protocol import (
    MAX_DEPTH,
    Bye,
    Catch,
    ChangeMode,
    ChangePlayerType,
    ChangeView,
    CoachInit,
    Dash,
    Done,
    Ear,
    ErrorReply,
    Eye,
    FullState,
    GlobalView,
    Hear,
    Init,
    InitPlayer,
    InitTrainer,
    Kick,
    Look,
    Move,
    MoveBall,
    MovePlayer,
    NoOp,
    OkReply,
    PlayerParams,
    PlayerType,
    ProtocolError,
    Reconnect,
    ReconnectPlayer,
    Recover,
    RequestTeamNames,
    SafeParser,
    Say,
    Score,
    SeeMessage,
    SenseBody,
    ServerParams,
    Start,
    SynchSee,
    Tackle,
    TeamNames,
    Think,
    TrainerEar,
    Turn,
    TurnNeck,
    WarningReply,
    datagram,
    parse_message,
    parse_sexp,
    parse_sexps,
    sexp_to_text,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "rcss"

# Expected message type of every line, per transcript file.
FILE_TYPES: dict[str, tuple[type, ...]] = {
    "fullstate.txt": (FullState,),
    "fullstate_midgame.txt": (FullState,),
    "hear.txt": (Hear,),
    "hear_referee.txt": (Hear,),
    "init.txt": (Init, CoachInit),
    "ok_look.txt": (GlobalView,),
    "player_param.txt": (PlayerParams,),
    "player_type.txt": (PlayerType,),
    "replies.txt": (OkReply, TeamNames, ErrorReply, WarningReply, Score, CoachInit),
    "see.txt": (SeeMessage,),
    "see_midgame.txt": (SeeMessage,),
    "see_global.txt": (GlobalView,),
    "see_global_midgame.txt": (GlobalView,),
    "sense_body.txt": (SenseBody,),
    "server_param.txt": (ServerParams,),
    "think.txt": (Think,),
}


def _lines(name: str) -> list[tuple[str, str]]:
    out = []
    for line in (DATA / name).read_text().splitlines():
        if line:
            who, msg = line.split("\t", 1)
            out.append((who, msg))
    return out


def _first(name: str, who: str | None = None, startswith: str = "") -> str:
    for w, msg in _lines(name):
        if (who is None or w == who) and msg.startswith(startswith):
            return msg
    raise LookupError(name)


ALL_MESSAGES = [msg for name in FILE_TYPES for _, msg in _lines(name)]


# --------------------------------------------------------------------------------------
# Every transcript line
# --------------------------------------------------------------------------------------


def test_every_transcript_file_is_covered() -> None:
    assert {p.name for p in DATA.glob("*.txt")} == set(FILE_TYPES)
    assert (DATA / "README.md").exists() and (DATA / "see_at_known_pose.json").exists()


@pytest.mark.parametrize("name", sorted(FILE_TYPES))
def test_every_line_parses_to_the_expected_type(name: str) -> None:
    lines = _lines(name)
    assert lines
    for who, msg in lines:
        parsed = parse_message(msg)
        assert isinstance(parsed, FILE_TYPES[name]), (who, msg[:80], type(parsed))
        # With the NUL terminator the server sends, as bytes, the result is the same.
        assert parse_message(msg.encode() + b"\x00") == parsed


def test_replies_file_line_by_line() -> None:
    got = [parse_message(msg) for _, msg in _lines("replies.txt")]
    assert got == [
        OkReply("change_mode"),
        OkReply("change_mode"),
        OkReply("ear", ("on",)),
        OkReply("gaussian_see"),
        OkReply("move"),
        OkReply("move"),
        OkReply("recover"),
        OkReply("synch_see"),
        OkReply("synch_see"),
        TeamNames("LeftTeam", "RightTeam"),
        ErrorReply("illegal_command_form"),
        ErrorReply("illegal_mode"),
        WarningReply("message_not_null_terminated"),
        Score(751, 1, 0),
        ErrorReply("no_more_player_or_goalie_or_illegal_client_version"),
        ErrorReply("no_more_team"),
        ErrorReply("no_more_player_or_goalie_or_illegal_client_version"),
        ErrorReply("cannot_reconnect_while_playon"),
        ErrorReply("already_have_offline_coach"),
        CoachInit("l"),
        OkReply("eye", ("on",)),
    ]


def test_init_replies() -> None:
    assert parse_message(_first("init.txt", "L1")) == Init("l", 1, "before_kick_off")
    assert parse_message(_first("init.txt", "R11")) == Init("r", 11, "before_kick_off")
    assert parse_message(_first("init.txt", "trainer")) == CoachInit(None)
    assert parse_message("(reconnect r play_on)") == Reconnect("r", "play_on")


def test_server_param_values() -> None:
    params = parse_message(_first("server_param.txt"))
    assert isinstance(params, ServerParams)
    assert len(params) > 150
    assert params["max_dash_power"] == 100 and isinstance(params["max_dash_power"], int)
    assert params["ball_decay"] == pytest.approx(0.94)
    assert params["landmark_file"] == "~/.rcssserver-landmark.xml"
    assert params["log_date_format"] == "%Y%m%d%H%M%S-"
    assert params["fixed_teamname_l"] == ""
    assert params.min_dash_power == 0.0 and params.max_dash_power == 100.0
    assert params.min_moment == -180.0 and params.max_power == 100.0
    assert params.synch_mode is True
    assert params.half_time == -1
    assert params.get_float("goal_width") == pytest.approx(14.02)
    assert params.get_str("game_log_dir") == "./"
    with pytest.raises(ValueError, match="not a number"):
        params.get_float("landmark_file")
    with pytest.raises(KeyError, match="no_such"):
        params.get_float("no_such_param")


def test_builtin_defaults_match_the_recorded_server() -> None:
    # Everything in our default table equals what rcssserver 19.0.0 sent, except the
    # options the transcript run set on the command line (README.md).
    recorded = parse_message(_first("server_param.txt"))
    assert isinstance(recorded, ServerParams)
    defaults = ServerParams.defaults()
    for name in defaults:
        if name in ("synch_mode", "half_time"):
            continue
        assert recorded[name] == defaults[name], name
    assert ServerParams({}).max_dash_power == 100.0  # missing -> default


def test_player_param_and_types() -> None:
    pp = parse_message(_first("player_param.txt"))
    assert isinstance(pp, PlayerParams)
    assert pp.player_types == 18 and pp["random_seed"] == 1795305189
    types = [parse_message(m) for w, m in _lines("player_type.txt") if w == "L1"]
    assert [t.id for t in types if isinstance(t, PlayerType)] == list(range(18))
    t1 = types[1]
    assert isinstance(t1, PlayerType)
    assert t1.kickable_margin == pytest.approx(0.697043)
    assert t1["inertia_moment"] == pytest.approx(2.94117)


def test_see_flags_players_and_lines() -> None:
    see = parse_message(_first("see.txt", "L1"))
    assert isinstance(see, SeeMessage) and see.time == 1
    fct = see.objects[0]
    assert (fct.kind, fct.name, fct.distance, fct.direction) == ("flag", "f c t", 13.5, -48.0)
    assert (fct.dist_change, fct.dir_change) == (0.0, 0.0)
    frt = see.objects[1]
    assert (frt.name, frt.distance, frt.direction, frt.dist_change) == ("f r t", 62.2, -9.0, None)
    goal = next(o for o in see.objects if o.kind == "goal")
    assert (goal.name, goal.distance, goal.direction) == ("g r", 66.0, 21.0)
    keeper = see.players[0]
    assert (keeper.team, keeper.unum, keeper.goalie) == ("RightTeam", 1, True)
    assert (keeper.distance, keeper.direction, keeper.body_dir, keeper.head_dir) == (
        18.2,
        0.0,
        180.0,
        180.0,
    )
    assert keeper.point_dir is None and not keeper.tackling and not keeper.kicking
    far = see.players[2]
    assert (far.team, far.unum, far.goalie, far.distance, far.direction) == (
        "RightTeam",
        None,
        False,
        30.0,
        25.0,
    )
    assert far.body_dir is None
    (line,) = see.lines
    assert (line.kind, line.name, line.distance, line.direction) == ("line", "l r", 61.6, 90.0)
    assert see.ball is None
    assert len(see.landmarks) == 25


def test_see_kick_and_tackle_markers_and_close_objects() -> None:
    see = parse_message(_first("see.txt", "L4"))
    assert isinstance(see, SeeMessage)
    p6 = next(p for p in see.players if p.unum == 6)
    assert p6.kicking and not p6.tackling and p6.body_dir == -150.0
    far_k = [p for p in see.players if p.unum is None and p.kicking]
    assert len(far_k) == 2
    mid = parse_message(_first("see_midgame.txt", "R2"))
    assert isinstance(mid, SeeMessage)
    tackling = [p for p in mid.players if p.tackling]
    assert tackling[0].team == "LeftTeam" and tackling[0].distance == 36.6
    assert mid.ball is not None and mid.ball.distance == 54.6 and not mid.ball.close
    # Close unidentified objects: (F) and (B) next to the player.
    import json

    pose_see = json.loads((DATA / "see_at_known_pose.json").read_text())[0][2]
    close = parse_message(pose_see)
    assert isinstance(close, SeeMessage)
    flag = close.objects[0]
    assert (flag.kind, flag.name, flag.close, flag.distance, flag.direction) == (
        "flag",
        "F",
        True,
        0.2,
        177.0,
    )
    ball = close.ball
    assert ball is not None and ball.close and ball.name == "B"
    assert (ball.distance, ball.direction) == (0.4, 177.0)
    assert flag not in close.landmarks
    dist_chg = next(p for p in close.players if p.unum == 4)
    assert dist_chg.dir_change == -0.1


def test_see_forms_not_in_the_transcripts() -> None:
    see = parse_message(
        '(see 7 ((p "A" 3) 10 20 0.5 -1 30 40 -60 t) ((p "A" 4 goalie) 5 -5 45) ((p) 50 3)'
        " ((f c) 12) ((b) 3 4 -0.2 0.1) ((P) 1.5 -120) ((G) 2 100) ((B) 150) ((l b) 20)"
        ' ((p "A") 40 10 k))'
    )
    assert isinstance(see, SeeMessage)
    o = see.objects
    assert (o[0].point_dir, o[0].body_dir, o[0].head_dir, o[0].tackling) == (
        -60.0,
        30.0,
        40.0,
        True,
    )
    assert (o[1].goalie, o[1].point_dir, o[1].dist_change) == (True, 45.0, None)
    assert (o[2].team, o[2].unum, o[2].distance) == (None, None, 50.0)
    assert (o[3].distance, o[3].direction) == (None, 12.0)  # low quality
    assert (o[4].kind, o[4].dist_change, o[4].dir_change) == ("ball", -0.2, 0.1)
    assert (o[5].kind, o[5].close, o[5].name) == ("player", True, "P")
    assert (o[6].kind, o[6].close) == ("goal", True)
    assert (o[7].kind, o[7].distance, o[7].direction) == ("ball", None, 150.0)
    assert (o[8].kind, o[8].distance) == ("line", None)
    assert o[9].kicking and o[9].unum is None


def test_sense_body_values() -> None:
    sb = parse_message(_first("sense_body.txt", "R8"))
    assert isinstance(sb, SenseBody)
    assert (sb.time, sb.view_quality, sb.view_width) == (1, "high", "normal")
    assert (sb.stamina, sb.effort, sb.stamina_capacity) == (8000.0, 1.0, 130600.0)
    assert (sb.speed, sb.speed_dir, sb.head_angle) == (0.0, -180.0, 0.0)
    assert sb.counts.dash == 0 and sb.counts.change_focus == 0
    assert sb.collisions == () and sb.card == "none" and sb.focus_target is None
    assert sb.arm is not None and sb.arm.count == 0
    assert sb.focus_point == (0.0, 0.0)
    full = parse_message(
        "(sense_body 9 (view_mode low wide) (stamina 7000.5 0.9 120000) (speed 0.4 -30)"
        " (head_angle 45) (kick 3) (dash 4) (turn 5) (say 0) (turn_neck 1) (catch 0)"
        " (move 1) (change_view 2) (change_focus 0) (arm (movable 2) (expires 5)"
        " (target 10.5 -20) (count 1)) (focus (target r 5) (count 2))"
        " (tackle (expires 7) (count 1)) (collision (ball) (post))"
        " (foul (charged 3) (card yellow)) (focus_point 2.5 -10))"
    )
    assert isinstance(full, SenseBody)
    assert full.stamina == 7000.5 and full.head_angle == 45.0
    assert full.counts.kick == 3 and full.counts.change_view == 2
    assert full.arm == proto.ArmState(2, 5, 10.5, -20.0, 1)
    assert full.focus_target == ("r", 5) and full.focus_count == 2
    assert (full.tackle_expires, full.tackle_count) == (7, 1)
    assert full.collisions == ("ball", "post")
    assert (full.foul_charged, full.card, full.focus_point) == (3, "yellow", (2.5, -10.0))
    old = parse_message(
        "(sense_body 3 (view_mode high normal) (stamina 4000 1) (speed 0.1)"
        " (head_angle 0) (kick 0))"
    )
    assert isinstance(old, SenseBody)
    assert old.stamina_capacity is None and old.speed_dir is None and old.counts.dash is None


def test_hear_referee_and_trainer_forms() -> None:
    goal = parse_message("(hear 102 referee goal_l_1)")
    assert goal == Hear(102, "referee", "goal_l_1")
    assert isinstance(goal, Hear) and goal.goal == ("l", 1) and goal.play_mode is None
    ko = parse_message(_first("hear_referee.txt", "L1", "(hear 102 referee kick_off_r"))
    assert isinstance(ko, Hear) and ko.play_mode == "kick_off_r" and ko.goal is None
    trainer = parse_message(_first("hear_referee.txt", "trainer", "(hear referee 102 goal"))
    assert trainer == Hear(102, "referee", "goal_l_1")
    goals = [
        m
        for name in ("hear.txt", "hear_referee.txt")
        for _, m in _lines(name)
        if "goal_" in m and "kick" not in m
    ]
    assert goals and all(parse_message(m).goal == ("l", 1) for m in goals)  # type: ignore[union-attr]
    assert Hear(5, "referee", "goal_r_12").goal == ("r", 12)
    assert Hear(5, "referee", "goal_kick_r").goal is None
    assert Hear(5, "self", "goal_l_1").goal is None


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('(hear 12 -30 our 5 "pass me")', Hear(12, "our", "pass me", -30.0, 5)),
        ('(hear 12 45.5 opp "(x y)")', Hear(12, "opp", "(x y)", 45.5)),
        ("(hear 12 our 5)", Hear(12, "our", None, None, 5)),
        ("(hear 12 opp)", Hear(12, "opp", None)),
        ('(hear 12 self "hi")', Hear(12, "self", "hi")),
        ('(hear 12 -3 "old")', Hear(12, "player", "old", -3.0)),
        ('(hear 12 online_coach_left "go")', Hear(12, "online_coach_left", "go")),
        (
            "(hear 12 online_coach_right (info (6000 (true) (do our {1} (pos (pt ball))))))",
            Hear(12, "online_coach_right", "(info (6000 (true) (do our {1} (pos (pt ball)))))"),
        ),
        ('(hear LeftTeam_5 30 "x")', Hear(30, "LeftTeam_5", "x")),
        # A helios-base player's say, as the trainer hears it (seen in training against it).
        ('(hear 87 (p "HELIOS_base" 8) "Ob7")', Hear(87, "player", "Ob7", unum=8)),
        ('(hear 87 (p "HELIOS_base" 1 goalie) "g")', Hear(87, "player", "g", unum=1)),
    ],
)
def test_hear_player_and_coach_forms(text: str, expected: Hear) -> None:
    assert parse_message(text) == expected


def test_see_global_and_look() -> None:
    sg = parse_message(_first("see_global_midgame.txt"))
    assert isinstance(sg, GlobalView) and sg.time == 451 and not sg.look
    assert sg.ball == proto.BallState(-0.0145666, 34.0, 0.0, 0.0)
    assert sg.goals == (("g r", 52.5, 0.0), ("g l", -52.5, 0.0))
    assert len(sg.players) == 22
    keeper = sg.players[0]
    assert (keeper.team, keeper.unum, keeper.goalie, keeper.marker) == ("LeftTeam", 1, True, "t")
    assert (keeper.x, keeper.y, keeper.body, keeper.neck) == (-8.81284, -21.7232, -1.0, 0.0)
    assert sg.players[4].marker == "k" and sg.players[1].marker is None
    look = parse_message(_first("ok_look.txt"))
    assert isinstance(look, GlobalView) and look.look and look.time == 0
    assert [(p.team, p.unum) for p in look.players][10:13] == [
        ("LeftTeam", 11),
        ("RightTeam", 1),
        ("RightTeam", 2),
    ]
    assert look.players[11].body == 180.0 and look.players[11].goalie
    extra = parse_message(
        '(see_global 3 ((b) 1 2 3 4) ((p "A" 2) 1 2 0 0 90 -10 45 f y) ((p "B" 7) 1 2 0 0 0 0 r))'
    )
    assert isinstance(extra, GlobalView)
    assert (extra.players[0].point_dir, extra.players[0].marker, extra.players[0].card) == (
        45.0,
        "f",
        "yellow",
    )
    assert (extra.players[1].marker, extra.players[1].card) == (None, "red")


def test_fullstate_values() -> None:
    fs = parse_message(_first("fullstate_midgame.txt", "R4"))
    assert isinstance(fs, FullState)
    assert (fs.time, fs.play_mode, fs.view_quality, fs.view_width) == (
        451,
        "play_on",
        "high",
        "normal",
    )
    assert fs.counts == (0, 128, 97, 0, 0, 0, 0, 0, 0)
    assert (fs.score_our, fs.score_their) == (0, 1)  # side r: swapped
    assert fs.ball == proto.BallState(-0.0145666, 34.0, 0.0, 0.0)
    assert len(fs.players) == 22
    keeper = fs.players[0]
    assert (keeper.side, keeper.unum, keeper.goalie, keeper.type_id) == ("l", 1, True, 0)
    assert keeper.marker == "t" and keeper.stamina_capacity == 126376.0
    assert (keeper.focus_dist, keeper.focus_dir) == (0.0, 0.0)
    assert fs.players[4].marker == "k"
    r1 = next(p for p in fs.players if p.side == "r" and p.unum == 1)
    assert r1.goalie and r1.x == pytest.approx(10.0886)
    pointing = parse_message(
        "(fullstate 5 (pmode goalie_catch_ball_l) (vmode low wide) (count 1 2 3 4 5 6 7 8)"
        " (arm (movable 0) (expires 3) (target 4 5) (count 1)) (score 2 3) ((b) 1 2 3 4)"
        " ((p r 9 17) 1 2 3 4 5 6 7.5 -8 (stamina 100 0.5 0.6) f y))"
    )
    assert isinstance(pointing, FullState)
    p9 = pointing.players[0]
    assert (p9.type_id, p9.point_dist, p9.point_dir, p9.focus_dist) == (17, 7.5, -8.0, None)
    assert (p9.stamina, p9.stamina_capacity, p9.marker, p9.card) == (100.0, None, "f", "yellow")


def test_other_messages() -> None:
    assert parse_message("(think)") == Think()
    assert parse_message("(change_player_type 3 5)") == ChangePlayerType(3, 5)
    assert parse_message("(change_player_type 3)") == ChangePlayerType(3, None)
    assert parse_message("(ok clang (ver 7 19))") == OkReply("clang", (("ver", "7", "19"),))
    assert parse_message("(ok team_names (team l Solo))") == TeamNames("Solo", None)
    assert parse_message("(error no team with name X)") == ErrorReply("no team with name X")
    assert parse_message("(ok check_ball 10 in_field)") == OkReply("check_ball", ("10", "in_field"))


def test_nul_and_newline_are_stripped() -> None:
    assert parse_message(b"(ok recover)\n\x00") == OkReply("recover")
    assert parse_message("(think)\x00") == Think()
    assert parse_message(bytearray(b"  (think)  \x00\x00")) == Think()
    with pytest.raises(TypeError):
        parse_message(42)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------
# Malformed input
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ("(see 1 ((f c) 1 2)", ["truncated", "never closed", "(f c) 1 2)<HERE>"]),
        ("(think))", ["without a matching", "(think)<HERE>)"]),
        ("(foo 1)", ["unknown message head", "'foo'", "expected one of"]),
        ("(init l 1)", ["expected 4 elements", "(init l 1)"]),
        ("(init l x before_kick_off)", ["integer for the uniform number", "'x'"]),
        ("(init x 1 before_kick_off)", ["a side", "'x'"]),
        ("(init l 1 not_a_mode)", ["a play mode", "'not_a_mode'"]),
        ("(see 1 ((f c) abc 2))", ["finite number", "'abc'"]),
        ("(see 1 ((f c) nan 2))", ["finite number", "'nan'"]),
        ("(see 1 ((f c) 1 inf))", ["finite number", "'inf'"]),
        ("(see 1 ((f c) 1_0 2))", ["finite number", "'1_0'"]),
        ("(see 1 ((f c) 1 2 3))", ["DIST DIR", "((f c) 1 2 3)"]),
        ("(see 1 ((zz) 1 2))", ["seen object name", "'(zz)'"]),
        ("(see 1 ((f q) 1 2))", ["seen object name", "'(f q)'"]),
        ('(see 1 ((p "A" 1 captain) 1 2))', ['(p "TEAM" UNUM [goalie])']),
        ('(see 1 ((p "A" 1) 1 2 3 4 5))', ["after a player"]),
        ("(see 1 ((p A 1) 1 2))", ["quoted string for the team name", "'A'"]),
        ("(see x)", ["integer for the time", "'x'"]),
        ("(see 1 (f c) 1 2)", ["seen object", "'(f c)'"]),
        ('(hear 1 self "unterminated)', ["never closed", '<HERE>"unterminated']),
        ("(sense_body 1 (view_mode high normal) (speed 0 0) (head_angle 0))", ["(stamina ...)"]),
        (
            "(sense_body 1 (view_mode high huge) (stamina 1 1) (speed 0) (head_angle 0))",
            ["view width", "'huge'"],
        ),
        ("(sense_body 1 (bogus 1))", ["known sense_body entry", "'(bogus 1)'"]),
        ("(sense_body 1 (kick 1) (kick 2))", ["once", "'(kick 2)'"]),
        ("(server_param (a 1 2))", ["(name value) pair", "'(a 1 2)'"]),
        ("(server_param (a 1) (a 2))", ["repeats"]),
        ("(player_type (speed 1))", ["(id N)"]),
        ("(fullstate 1 (pmode play_on))", ["(vmode ...)"]),
        ('(see_global 1 ((p "A" 1) 1 2 3))', ["X Y VX VY BODY NECK"]),
        ("(hear 1 our)", ["(hear TIME our UNUM)"]),
        ("(think 1)", ["expected 1 elements"]),
        ("", ["empty message"]),
        ("\x00", ["empty message"]),
        ("   ", ["empty message"]),
        ("(think)(think)", ["2 expressions"]),
        ("see 1", ["stray atom", "'see'"]),
        ("()", ["unknown message head", "'()'"]),
        ("((see) 1)", ["unknown message head", "'(see)'"]),
        ("(think)\x01", ["character '\\x01'", "printable ASCII"]),
        ('(hear 1 self "caf\u00e9")', ["character '\u00e9'"]),
        ("(see 1 ((f c) 1 2)\x00 junk)", ["character '\\x00'"]),
        ("(error)", ["a reason"]),
        ("(error (x))", ["bare word"]),
    ],
)
def test_malformed_messages_raise_with_excerpt(text: str, fragments: list[str]) -> None:
    with pytest.raises(ProtocolError) as info:
        parse_message(text)
    msg = str(info.value)
    assert "expected" in msg or "expected" in msg.lower(), msg
    for fragment in fragments:
        assert fragment in msg, (fragment, msg)
    assert isinstance(info.value, ValueError)


def test_bytes_that_are_not_ascii_raise() -> None:
    with pytest.raises(ProtocolError, match="printable ASCII"):
        parse_message(b"(think)\xff\x00")


def test_depth_bomb_is_rejected_at_the_limit() -> None:
    # Refused by the length and depth checks (what keeps them cheap), not parsed to the end.
    with pytest.raises(ProtocolError, match="longer than"):
        parse_message("(" * 100_000)  # over the length limit and far too deep
    for bomb in (
        "(" * 60_000,
        "(" * 30_000 + ")" * 30_000,
        "(a " * 15_000 + ")" * 15_000,
        "(x" * 20_000,
    ):
        deeper = f"nesting deeper than the limit of {MAX_DEPTH} levels"
        with pytest.raises(ProtocolError, match=deeper):
            parse_message(bomb)
    # Exactly at the limit is fine structurally (and then an unknown head).
    ok = "(" * MAX_DEPTH + ")" * MAX_DEPTH
    assert len(parse_sexp(ok)) == 1


def test_oversized_input_is_rejected() -> None:
    with pytest.raises(ProtocolError, match="longer than the limit"):
        parse_message("(think " + "x " * 40_000 + ")")


# --------------------------------------------------------------------------------------
# Tokenizer round trip
# --------------------------------------------------------------------------------------


def test_sexp_round_trip_on_all_transcripts() -> None:
    for msg in ALL_MESSAGES:
        tree = parse_sexp(msg)
        text = sexp_to_text(tree)
        assert parse_sexp(text) == tree
    tree = parse_sexp('(a "b c" (d (e)) "" f)')
    assert tree == ("a", '"b c"', ("d", ("e",)), '""', "f")
    assert sexp_to_text(tree) == '(a "b c" (d (e)) "" f)'
    assert parse_sexps("(dash 60 0)(turn_neck 10)(done)") == (
        ("dash", "60", "0"),
        ("turn_neck", "10"),
        ("done",),
    )


# --------------------------------------------------------------------------------------
# SafeParser
# --------------------------------------------------------------------------------------


def test_safe_parser_counts_logs_and_returns_none(caplog: pytest.LogCaptureFixture) -> None:
    parser = SafeParser(log_limit=2)
    with caplog.at_level(logging.DEBUG, logger="elevens.robocup.protocol"):
        assert parser.parse("(think)\x00") == Think()
        assert parser.parse(b"(see 1 ((f c) x 2))\x00") is None
        assert parser.parse("(see 1 ((f c) 1 2)") is None
        assert parser.parse("(see 2 ((f c) nan 2))") is None
        assert parser.parse("(garbage 1)") is None
        assert parser.parse(b"\xff\xfe") is None
        assert parser.parse("(" * 50_000) is None
    assert parser.stats.parsed == {"Think": 1}
    assert parser.stats.errors == {"see": 3, "unknown": 3}
    assert parser.stats.total_errors == 6 and parser.stats.total_parsed == 1
    assert parser.stats.last_error is not None and "nesting" in parser.stats.last_error
    records = [r for r in caplog.records if "dropped malformed" in r.getMessage()]
    assert len(records) == 6
    see_levels = [r.levelno for r in records if "malformed see" in r.getMessage()]
    assert see_levels == [logging.WARNING, logging.WARNING, logging.DEBUG]
    assert "'x'" in records[0].getMessage()


# --------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------

COMMANDS: list[tuple[proto.Command, str]] = [
    (InitPlayer("LeftTeam"), "(init LeftTeam (version 18))"),
    (InitPlayer("LeftTeam", goalie=True), "(init LeftTeam (version 18) (goalie))"),
    (InitPlayer("R-2_x+", version=19), "(init R-2_x+ (version 19))"),
    (ReconnectPlayer("LeftTeam", 3), "(reconnect LeftTeam 3)"),
    (Bye(), "(bye)"),
    (Dash(60), "(dash 60)"),
    (Dash(60.5, -45.25), "(dash 60.5 -45.25)"),
    (Dash(np.float32(50.5), np.float64(180.0)), "(dash 50.5 180)"),  # type: ignore[arg-type]
    (Dash(1e-9), "(dash 0)"),
    (Dash(100 / 3), "(dash 33.333333)"),
    (Turn(-180), "(turn -180)"),
    (Turn(-1e-9), "(turn 0)"),
    (Kick(100, -30), "(kick 100 -30)"),
    (Tackle(45), "(tackle 45)"),
    (Tackle(-45, True), "(tackle -45 on)"),
    (Tackle(0, False), "(tackle 0 off)"),
    (Catch(-20), "(catch -20)"),
    (Move(-10, 5.25), "(move -10 5.25)"),
    (TurnNeck(-90), "(turn_neck -90)"),
    (ChangeView("wide"), "(change_view wide)"),
    (ChangeView("narrow", "high"), "(change_view narrow high)"),
    (Say("pass 2 (x)"), '(say "pass 2 (x)")'),
    (Done(), "(done)"),
    (SynchSee(), "(synch_see)"),
    (proto.Ear(True), "(ear (on))"),
    (Ear(False, "opp", "partial"), "(ear (off opp partial))"),
    (Ear(True, "LeftTeam"), "(ear (on LeftTeam))"),
    (InitTrainer(), "(init (version 18))"),
    (ChangeMode("play_on"), "(change_mode play_on)"),
    (ChangeMode("before_kick_off"), "(change_mode before_kick_off)"),
    (MoveBall(0, 0), "(move (ball) 0 0)"),
    (MoveBall(50, 0, 3, 0), "(move (ball) 50 0 0 3 0)"),
    (MovePlayer("LeftTeam", 3, -10, 5), "(move (player LeftTeam 3) -10 5)"),
    (MovePlayer("RightTeam", 11, 10.5, -5, 180), "(move (player RightTeam 11) 10.5 -5 180)"),
    (MovePlayer("LeftTeam", 1, -50, 0, -90, 0, 0), "(move (player LeftTeam 1) -50 0 -90 0 0)"),
    (Recover(), "(recover)"),
    (Start(), "(start)"),
    (Eye(True), "(eye on)"),
    (Eye(False), "(eye off)"),
    (Look(), "(look)"),
    (RequestTeamNames(), "(team_names)"),
    (TrainerEar(True), "(ear on)"),
]


@pytest.mark.parametrize(("command", "text"), COMMANDS, ids=[t for _, t in COMMANDS])
def test_command_encoding_and_round_trip(command: proto.Command, text: str) -> None:
    data = command.encode()
    assert data == text.encode("ascii")
    assert b"\x00" not in data and data.isascii()
    tree = parse_sexp(data.decode())
    assert sexp_to_text(tree) == text
    assert parse_sexp(sexp_to_text(tree)) == tree


def test_command_trees() -> None:
    assert parse_sexp(MovePlayer("A", 2, 1, 2, 3, 4, 5).encode().decode()) == (
        "move",
        ("player", "A", "2"),
        "1",
        "2",
        "3",
        "4",
        "5",
    )
    assert parse_sexp(InitPlayer("T", goalie=True).encode().decode()) == (
        "init",
        "T",
        ("version", "18"),
        ("goalie",),
    )
    assert parse_sexp(Say("a b").encode().decode()) == ("say", '"a b"')


def test_datagram_joins_and_terminates() -> None:
    assert datagram(Dash(60, 0), TurnNeck(10), Done()) == b"(dash 60 0)(turn_neck 10)(done)\x00"
    assert datagram(NoOp(), Done()) == b"(done)\x00"
    assert NoOp().encode() == b""


def test_ranges_follow_server_params() -> None:
    with pytest.raises(
        ValueError,
        match=r"dash power=-50.0 is outside the server range "
        r"\[0, 100\] \(server_param min_dash_power",
    ):
        Dash(-50).encode()
    wide = ServerParams({"min_dash_power": -100})
    assert Dash(-50).encode(wide) == b"(dash -50)"
    assert datagram(Dash(-50), Done(), params=wide) == b"(dash -50)(done)\x00"
    with pytest.raises(ValueError, match=r"dash direction=190.0 .*\[-180, 180\]"):
        Dash(50, 190).encode()
    with pytest.raises(ValueError, match=r"kick power=101.0 .*maxpower"):
        Kick(101, 0).encode()
    with pytest.raises(ValueError, match=r"kick direction=-181.0 .*minmoment"):
        Kick(10, -181).encode()
    with pytest.raises(ValueError, match=r"turn moment=200.0"):
        Turn(200).encode()
    with pytest.raises(ValueError, match=r"catch direction=100.0 .*\[-90, 90\]"):
        Catch(100).encode()
    with pytest.raises(ValueError, match=r"turn_neck moment"):
        TurnNeck(181).encode()
    with pytest.raises(ValueError, match=r"tackle direction"):
        Tackle(999).encode()
    with pytest.raises(ValueError, match=r"player direction"):
        MovePlayer("A", 1, 0, 0, 270).encode()
    with pytest.raises(ValueError, match="say_msg_size"):
        Say("x" * 11).encode()
    assert Say("x" * 11).encode(ServerParams({"say_msg_size": 20})) == b'(say "xxxxxxxxxxx")'


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: Dash(math.nan), "dash power must be finite"),
        (lambda: Dash(50, math.inf), "dash direction must be finite"),
        (lambda: Kick("10", 0), "kick power must be a number"),  # type: ignore[arg-type]
        (lambda: Turn(True), "turn moment must be a number"),
        (lambda: Move(1e9, 0), "implausibly large"),
        (lambda: MoveBall(0, 0, 1, None), "both ball vx and vy"),
        (lambda: MovePlayer("A", 1, 0, 0, None, 1, 1), "needs a direction"),
        (lambda: MovePlayer("A", 12, 0, 0), r"uniform number 12 .*\[1, 11\]"),
        (lambda: ReconnectPlayer("A", 0), "uniform number 0"),
        (lambda: InitPlayer("bad name"), "team name 'bad name'"),
        (lambda: InitPlayer("x" * 16), "1-15 characters"),
        (lambda: InitPlayer(""), "1-15 characters"),
        (lambda: InitPlayer("A", version=25), "protocol version 25"),
        (lambda: ChangeMode("not_a_mode"), "play mode 'not_a_mode'"),
        (lambda: ChangeView("huge"), "view width 'huge'"),
        (lambda: ChangeView("wide", "ultra"), "view quality 'ultra'"),
        (lambda: Say('he said "hi"'), "contains"),
        (lambda: Say(""), "non-empty"),
        (lambda: Tackle(0, "on"), "foul must be a bool"),  # type: ignore[arg-type]
        (lambda: Ear(True, "our team"), "team name"),
        (lambda: Ear(True, None, "half"), "ear mode"),
    ],
)
def test_invalid_command_arguments(build: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        build()  # type: ignore[operator]


# --------------------------------------------------------------------------------------
# Fuzzing
# --------------------------------------------------------------------------------------

FUZZ = settings(
    max_examples=250, deadline=2000, database=None, suppress_health_check=[HealthCheck.too_slow]
)
SAMPLE = sorted(set(ALL_MESSAGES), key=len)[::7]  # a spread of real messages


def _parses_or_protocol_error(data: str | bytes) -> None:
    with contextlib.suppress(ProtocolError):
        parse_message(data)


@FUZZ
@given(st.binary(max_size=400))
def test_fuzz_random_bytes(data: bytes) -> None:
    _parses_or_protocol_error(data)
    SafeParser().parse(data)


@FUZZ
@given(st.text(alphabet=st.sampled_from('()" abcfglprt0123456789.-_\x00\n'), max_size=200))
def test_fuzz_random_protocol_alphabet(text: str) -> None:
    _parses_or_protocol_error(text)


@FUZZ
@given(st.sampled_from(SAMPLE), st.data())
def test_fuzz_truncations(msg: str, data: st.DataObject) -> None:
    cut = data.draw(st.integers(0, len(msg)))
    _parses_or_protocol_error(msg[:cut])
    _parses_or_protocol_error(msg[cut:])


@FUZZ
@given(st.sampled_from(SAMPLE), st.data())
def test_fuzz_deleted_parens(msg: str, data: st.DataObject) -> None:
    positions = [i for i, ch in enumerate(msg) if ch in "()"]
    drop = set(data.draw(st.lists(st.sampled_from(positions), max_size=4)))
    _parses_or_protocol_error("".join(ch for i, ch in enumerate(msg) if i not in drop))


@FUZZ
@given(st.sampled_from(SAMPLE), st.data())
def test_fuzz_mutations(msg: str, data: st.DataObject) -> None:
    chars = list(msg)
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(chars) - 1))
        chars[i] = data.draw(st.sampled_from('()" x0-._\x00\t\xe9'))
    _parses_or_protocol_error("".join(chars))


def _mutate_tree(node: proto.Sexp, rnd: random.Random) -> proto.Sexp:
    """Randomly drop, duplicate, replace or wrap parts of a parsed message."""
    if isinstance(node, str):
        r = rnd.random()
        if r < 0.1:
            return rnd.choice(_ATOMS)
        if r < 0.13:
            return (node,)
        return node
    out: list[proto.Sexp] = []
    for child in node:
        r = rnd.random()
        if r < 0.05:
            continue
        if r < 0.08:
            out.append(child)
        out.append(_mutate_tree(child, rnd))
    if rnd.random() < 0.05:
        out.append(rnd.choice(_ATOMS))
    return tuple(out)


_ATOMS = [
    "0",
    "-1",
    "1.5",
    "nan",
    "x",
    '"q"',
    "t",
    "k",
    "goalie",
    "l",
    "r",
    "f",
    "p",
    "b",
    "g",
    "none",
    "ok",
    "1e400",
    "-0",
    "ball",
    "on",
    "play_on",
]


@FUZZ
@given(st.sampled_from(sorted(set(ALL_MESSAGES))), st.randoms(use_true_random=False))
def test_fuzz_tree_mutations(msg: str, rnd: random.Random) -> None:
    # Structurally valid but semantically damaged messages exercise the typed decoders.
    tree = _mutate_tree(parse_sexp(msg), rnd)
    text = sexp_to_text(tree) if isinstance(tree, tuple) and tree else "()"
    _parses_or_protocol_error(text)
