"""elevens.robocup.rules: which routine each play mode calls for, and the commands it gives."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from elevens.robocup.client import Cycle, PlayerCycle
from elevens.robocup.env import RoboCupConfig, robocup_env_params
from elevens.robocup.observe import PerceptMemory
from elevens.robocup.protocol import Catch, Dash, Kick, Move, NoOp, Tackle, Turn, parse_message
from elevens.robocup.rules import (
    CATCH_REACH,
    GUARD_DEPTH,
    RECOVERING_DASH,
    SEARCH_TURN,
    STAMINA_RESERVE,
    LastKick,
    MatchRoutines,
    SecondTouch,
    TeamView,
    apply_rules,
    guard_goal,
    kick_off_positions,
    kick_off_taker,
    kicks_off_next,
    mode_kind,
    near_ball,
    no_second_touch,
    pace_dashes,
    set_piece_taker,
    touched_by_another,
)


def _view(n: int = 3, **changes: object) -> TeamView:
    fields: dict[str, np.ndarray] = {
        "position": np.array([[-50.0, 0.0], [-20.0, 5.0], [10.0, -5.0]])[:n],
        "heading": np.zeros(n),
        "ball_seen": np.ones(n, bool),
        "ball_distance": np.array([40.0, 20.0, 30.0])[:n],
        "ball_bearing": np.zeros(n),
        "stale": np.zeros(n, np.int32),
    }
    for name, value in changes.items():
        fields[name] = np.asarray(value)
    return TeamView(**fields)


POLICY = [Dash(10.0), Dash(20.0), Dash(30.0)]


@pytest.mark.parametrize(
    ("mode", "side", "kind"),
    [
        ("before_kick_off", 0, "move"),
        ("goal_l", 1, "move"),
        ("kick_off_l", 0, "ours"),
        ("kick_off_l", 1, "theirs"),
        ("corner_kick_r", 1, "ours"),
        ("indirect_free_kick_r", 0, "theirs"),
        ("goal_kick_l", 0, "ours"),
        ("play_on", 0, "play"),
        ("drop_ball", 1, "play"),
        ("offside_l", 0, "theirs"),  # left was offside: a free kick to the right follows
        ("offside_l", 1, "play"),
        ("free_kick_fault_l", 0, "theirs"),  # a fault, not the left team's free kick
        ("free_kick_fault_l", 1, "play"),
        ("back_pass_r", 1, "theirs"),
        ("foul_charge_l", 1, "play"),
        ("time_over", 0, "over"),
    ],
)
def test_mode_kind(mode: str, side: int, kind: str) -> None:
    assert mode_kind(mode, side) == kind


def test_kick_off_goes_to_the_side_that_conceded_else_alternates_by_half() -> None:
    assert kicks_off_next("goal_l", 1, 1) and not kicks_off_next("goal_l", 0, 1)
    assert kicks_off_next("before_kick_off", 0, 1) and not kicks_off_next("before_kick_off", 1, 1)
    assert kicks_off_next("before_kick_off", 1, 2)  # the second half: right kicks off


@pytest.mark.parametrize("n", [1, 2, 5, 11])
def test_kick_off_formation_is_in_the_own_half_with_the_taker_at_the_ball(n: int) -> None:
    away = kick_off_positions(n, taker=False)
    home = kick_off_positions(n, taker=True)
    assert away.shape == (n, 2) and np.all(away[:, 0] <= -1.0)
    assert np.all(np.abs(away[:, 1]) <= 34.0) and np.all(away[:, 0] >= -52.5)
    taker = kick_off_taker(n)
    assert np.hypot(*home[taker]) < 1.0  # within kicking distance of the centre spot
    assert np.array_equal(np.delete(home, taker, 0), np.delete(away, taker, 0))


def test_move_modes_move_everyone_to_the_formation_in_the_servers_frame() -> None:
    commands, what = apply_rules(POLICY, _view(), "before_kick_off", 1, halves_played=1)
    assert what == "move"
    slots = kick_off_positions(3, taker=False)  # right does not kick off the first half
    moved = [(c.x, c.y) for c in commands if isinstance(c, Move)]
    assert moved == [(x, -y) for x, y in slots]


def test_their_set_piece_and_play_on_leave_the_policy_alone() -> None:
    for mode in ("kick_in_r", "play_on", "drop_ball"):
        commands, what = apply_rules(POLICY, _view(), mode, 0)
        assert commands == POLICY and what == "policy"


def test_our_set_piece_sends_the_nearest_player_to_the_ball() -> None:
    # Player 1 is nearest (20 m), the ball 30 degrees to its left: it turns first.
    view = _view(ball_bearing=[0.0, math.radians(30.0), 0.0])
    commands, what = apply_rules(POLICY, view, "free_kick_l", 0)
    assert what == "set_piece" and commands[0] == POLICY[0] and commands[2] == POLICY[2]
    turn = commands[1]
    assert isinstance(turn, Turn) and turn.moment == pytest.approx(-30.0)  # + = clockwise
    commands, _ = apply_rules(POLICY, _view(), "free_kick_l", 0)
    assert commands[1] == Dash(100.0)


def test_in_our_set_piece_only_the_taker_touches_the_ball() -> None:
    """Read from rcss-gpu's matches against helios-base: at a kick-off the policy of the player
    in the kick-off slot kicked while a teammate was the routine's taker; the server made it the
    taker, the ban followed the other, and it ran into its own kick 45 cycles later."""
    view = _view(ball_distance=[40.0, 0.5, 0.9])  # 1 is nearest: the taker; 2 is in reach too
    policy = [Catch(0.0), Dash(20.0), Kick(100.0, -78.0)]
    commands, what = apply_rules(policy, view, "kick_off_l", 0, goalie=None)
    assert what == "set_piece" and isinstance(commands[1], Kick) and commands[2] is None
    assert commands[0] is None  # a catch is a touch too
    # Nobody sees the ball: the outfield look for it, and the goalie's policy may not catch.
    commands, _ = apply_rules(policy, _view(ball_seen=[False] * 3), "kick_in_l", 0)
    assert commands == [None, Turn(SEARCH_TURN), Turn(SEARCH_TURN)]
    commands, _ = apply_rules([NoOp(), Tackle(50.0), Dash(30.0)], view, "free_kick_l", 0)
    assert commands[2] == Dash(30.0)  # dashes and the rest go out
    # Play on and their set pieces leave the policy's kicks alone.
    for mode in ("play_on", "kick_in_r"):
        assert apply_rules(policy, view, mode, 0, goalie=None)[0] == policy


def test_a_kickable_taker_shoots_near_the_goal_and_clears_up_the_wing_far_from_it() -> None:
    near = _view(position=[[-50.0, 0.0], [40.0, 0.0], [0.0, 0.0]],
                 ball_distance=[50.0, 0.5, 40.0], ball_bearing=[0.0, 0.0, 0.0])
    commands, _ = apply_rules(POLICY, near, "kick_in_l", 0)
    kick = commands[1]
    assert isinstance(kick, Kick) and kick.power == 100.0
    aim = math.degrees(math.atan2(3.5, 52.5 - 40.5))  # at the post on the ball's far side
    assert kick.direction == pytest.approx(-aim, abs=1.0)
    far = _view(position=[[-50.0, 0.0], [-30.0, 10.0], [0.0, 0.0]],
                ball_distance=[50.0, 0.5, 40.0])
    commands, _ = apply_rules(POLICY, far, "goal_kick_l", 0)
    kick = commands[1]
    assert isinstance(kick, Kick) and kick.direction < 0  # up the left wing (+y = clockwise -)


def test_the_goalie_takes_the_free_kick_after_its_catch() -> None:
    view = _view(position=[[-48.0, 0.0], [-40.0, 0.0], [0.0, 0.0]],
                 ball_distance=[0.8, 8.0, 40.0])
    commands, what = apply_rules(POLICY, view, "free_kick_l", 0, goalie=0)
    assert what == "set_piece" and isinstance(commands[0], Kick) and commands[1] == POLICY[1]


def test_the_goalie_catches_a_fresh_ball_in_reach_inside_its_penalty_area() -> None:
    reach = dict(position=[[-50.0, 2.0], [-20.0, 5.0], [10.0, -5.0]],
                 ball_distance=[CATCH_REACH - 0.1, 20.0, 30.0],
                 ball_bearing=[math.radians(40.0), 0.0, 0.0])
    commands, what = apply_rules(POLICY, _view(**reach), "play_on", 0)
    catch = commands[0]
    assert what == "catch" and isinstance(catch, Catch)
    assert catch.direction == pytest.approx(-40.0)
    assert commands[1:] == POLICY[1:]
    refused = [
        dict(reach, stale=[1, 0, 0]),  # the see is a cycle old: the ball has moved
        dict(reach, ball_distance=[CATCH_REACH + 0.2, 20.0, 30.0]),
        dict(reach, position=[[-30.0, 2.0], [-20.0, 5.0], [10.0, -5.0]]),  # out of its area
        dict(reach, ball_bearing=[math.radians(120.0), 0.0, 0.0]),  # beyond the +-90 range
    ]
    for changes in refused:
        assert apply_rules(POLICY, _view(**changes), "play_on", 0)[1] == "policy"
    assert apply_rules(POLICY, _view(**reach), "play_on", 0, catch_allowed=False)[1] == "policy"
    assert apply_rules(POLICY, _view(**reach), "play_on", 0, goalie=None)[1] == "policy"
    # At the edge of the range, as a match's float32 percepts give it: a catch the server takes
    # (this one stopped a match: 90.0000025 degrees is outside [-90, 90]).
    for edge in (math.pi / 2, -math.pi / 2):
        bearing = np.array([edge, 0.0, 0.0], np.float32)
        commands, what = apply_rules(POLICY, _view(**dict(reach, ball_bearing=bearing)),
                                     "play_on", 0)
        assert what == "catch" and commands[0].to_text() in ("(catch -90)", "(catch 90)")


def test_when_nobody_sees_the_ball_in_our_set_piece_the_outfield_looks_for_it() -> None:
    # Left to the policy, a set piece nobody sees may never be taken (training servers have
    # no drop ball): a policy that never turns to the ball stalled a kick-in for good.
    commands, what = apply_rules(POLICY, _view(ball_seen=[False] * 3), "corner_kick_l", 0)
    assert what == "set_piece" and commands[0] == POLICY[0]
    assert commands[1:] == [Turn(SEARCH_TURN)] * 2


def test_time_over_sends_nothing() -> None:
    commands, _ = apply_rules(POLICY, _view(), "time_over", 0)
    assert commands == [None, None, None]
    assert NoOp() not in commands


def test_dashes_are_paced_to_keep_the_stamina_reserve() -> None:
    commands = [Dash(100.0, 0.0), Dash(100.0, 0.0), Dash(-80.0, 0.0), Kick(50.0, 0.0), None,
                Dash(100.0, 0.0)]
    stamina = [8000.0, 3020.0, 2000.0, 100.0, 500.0, None]
    paced = pace_dashes(commands, stamina)
    assert paced[0] == Dash(100.0, 0.0)  # plenty left: as the policy asked
    assert paced[1] == Dash(20.0 + RECOVERING_DASH, 0.0)  # 20 above the reserve, + a walk
    assert paced[2] == Dash(-RECOVERING_DASH, 0.0)  # below it: walk, in the asked direction
    assert paced[3] == Kick(50.0, 0.0) and paced[4] is None  # only dashes are paced
    assert paced[5] == Dash(100.0, 0.0)  # stamina unknown: the dash stands
    assert pace_dashes([Dash(100.0, 0.0)], [STAMINA_RESERVE + 50.0]) == [Dash(80.0, 0.0)]
    # With the capacity known, the rest of the half's capacity is spread over its cycles left:
    # 60,000 over the 1,500 cycles left of the second half is 40 a cycle beyond the reserve.
    assert pace_dashes([Dash(100.0, 0.0)], [STAMINA_RESERVE], [60_000.0], 4_500) == [
        Dash(40.0, 0.0)
    ]
    assert pace_dashes([Dash(100.0, 0.0)], [STAMINA_RESERVE + 10.0], [0.0], 100) == [
        Dash(10.0, 0.0)
    ]  # an empty capacity: only the stamina above the reserve


def _ball_at(ball: tuple[float, float], goalie=(-51.0, 0.0), heading: float = 0.0) -> TeamView:
    """A view where every player sees the ball at ``ball`` (team frame)."""
    position = np.array([goalie, [-20.0, 5.0], [10.0, -5.0]])
    offset = np.asarray(ball) - position
    heading_all = np.array([heading, 0.0, 0.0])
    return _view(
        position=position,
        heading=heading_all,
        ball_distance=np.hypot(offset[:, 0], offset[:, 1]),
        ball_bearing=np.arctan2(offset[:, 1], offset[:, 0]) - heading_all,
    )


def test_the_goalie_steps_onto_the_line_from_its_goal_to_the_ball() -> None:
    # Ball far up the left wing: the goalie, facing it, steps to the left of its goal's centre.
    ball = (-10.0, 30.0)
    bearing = math.atan2(30.0, -10.0 + 51.0)
    commands, replaced = guard_goal(POLICY, _ball_at(ball, heading=bearing), "play_on", 0)
    dash = commands[0]
    assert replaced and isinstance(dash, Dash) and commands[1:] == POLICY[1:]
    target = np.array([-52.5, 0.0]) + GUARD_DEPTH[1] * np.array([42.5, 30.0]) / math.hypot(
        42.5, 30.0
    )  # a quarter of 52 m, capped at the further depth
    step = target - np.array([-51.0, 0.0])
    expected = -math.degrees(math.atan2(step[1], step[0]) - bearing)  # clockwise, off the body
    assert dash.direction == pytest.approx(expected, abs=1e-6)
    assert dash.power > 50.0
    # Standing on its point it only keeps facing the ball.
    seen_from_point = math.atan2(ball[1] - target[1], ball[0] - target[0])
    on_point = _ball_at(ball, goalie=tuple(target), heading=seen_from_point + 0.1)
    commands, _ = guard_goal(POLICY, on_point, "play_on", 0)
    assert isinstance(commands[0], Turn)
    assert commands[0].moment == pytest.approx(math.degrees(0.1), abs=1e-6)  # clockwise


def test_the_goalie_turns_to_the_ball_first_and_goes_for_it_in_its_area() -> None:
    behind = _ball_at((-20.0, 0.0), heading=math.pi)  # facing its own goal
    commands, _ = guard_goal(POLICY, behind, "play_on", 0)
    assert isinstance(commands[0], Turn) and abs(commands[0].moment) == pytest.approx(180.0)
    # A ball in the penalty area: straight at it.
    commands, _ = guard_goal(POLICY, _ball_at((-45.0, 6.0), heading=math.atan2(6.0, 6.0)),
                             "play_on", 0)
    assert isinstance(commands[0], Dash) and commands[0].direction == pytest.approx(0.0, abs=1e-6)


def test_the_goalie_guard_leaves_set_pieces_and_a_lost_ball_to_the_others() -> None:
    view = _ball_at((-10.0, 30.0))
    for mode in ("before_kick_off", "goal_r", "time_over"):
        assert guard_goal(POLICY, view, mode, 0) == (POLICY, False)
    # In set pieces it guards too (the policy would chase the ball: a naive goalie left its
    # goal at our kick-off), unless a routine gave it its command (it takes the set piece).
    assert guard_goal(POLICY, view, "corner_kick_r", 0)[1]
    assert guard_goal(POLICY, view, "kick_off_l", 0)[1]
    assert guard_goal(POLICY, view, "goal_kick_l", 0, goalie_busy=True) == (POLICY, False)
    # In the opponents' set pieces it does not go for a ball in its area.
    in_area = _ball_at((-45.0, 6.0), heading=math.atan2(6.0, 6.0))
    commands, _ = guard_goal(POLICY, in_area, "free_kick_r", 0)
    assert isinstance(commands[0], Dash) and commands[0].direction != pytest.approx(0.0)
    assert guard_goal(POLICY, _view(ball_seen=[False] * 3), "play_on", 0) == (POLICY, False)
    assert guard_goal(POLICY, view, "play_on", 0, goalie=None) == (POLICY, False)


def test_the_goalie_takes_only_goal_kicks_and_the_ball_it_holds() -> None:
    # The goalie is nearest the ball (a kick-in near its goal): a field player takes it.
    view = _view(ball_distance=[5.0, 20.0, 30.0])
    commands, what = apply_rules(POLICY, view, "kick_in_l", 0)
    assert what == "set_piece" and commands[0] == POLICY[0] and commands[1] != POLICY[1]
    commands, _ = apply_rules(POLICY, view, "goal_kick_l", 0)
    assert commands[0] != POLICY[0] and commands[1:] == POLICY[1:]
    commands, _ = apply_rules(POLICY, view, "kick_in_l", 0, goalie=None)
    assert commands[0] != POLICY[0]  # no goalie: the nearest player, whoever it is


def _banned(taker: int = 1, *, dashed: bool = False) -> SecondTouch:
    touch = SecondTouch()
    touch.start(taker, "kick_off_l")
    touch.observe("play_on", touched=False)
    touch.dashed = dashed
    return touch


def test_the_ban_on_the_set_piece_taker_lasts_as_the_servers_does() -> None:
    touch = SecondTouch()
    touch.start(1, "kick_in_l")
    touch.observe("kick_in_l", touched=False)  # the kick may not have reached the ball
    assert touch.taker == 1 and not touch.in_play
    touch.observe("play_on", touched=False)
    assert touch.taker == 1 and touch.in_play
    for _ in range(500):  # no time limit: the server has none
        touch.observe("play_on", touched=False)
    assert touch.taker == 1
    touch.observe("play_on", touched=True)  # another player touched the ball
    assert touch.taker is None
    # Any stoppage after the kick ends it, our own next set piece of the same kind included.
    for mode in ("kick_in_r", "kick_in_l", "drop_ball", "offside_r"):
        touch = _banned()
        touch.observe(mode, touched=False)
        assert touch.taker is None, mode
    # Before play_on was seen, another mode than the set piece's ends it too.
    touch = SecondTouch()
    touch.start(1, "kick_off_l")
    touch.observe("free_kick_r", touched=False)
    assert touch.taker is None
    # The taker's dash is noted; nobody else's.
    touch = _banned()
    touch.sent([Dash(50.0), Turn(10.0), None])
    assert not touch.dashed
    touch.sent([None, Dash(10.0), None])
    assert touch.dashed


def test_the_banned_taker_touches_nothing_after_a_dash_and_does_not_run_into_the_ball() -> None:
    near = _view(ball_distance=[40.0, 1.5, 30.0])
    far = _view(ball_distance=[40.0, 8.0, 30.0])
    kick, dash, turn = Kick(60.0, 0.0), Dash(100.0), Turn(30.0)
    others = [Dash(10.0), None, Dash(30.0)]

    def sent(command: object, view: TeamView, touch: SecondTouch) -> object:
        commands = list(others)
        commands[1] = command
        out = no_second_touch(commands, view, touch)
        assert out[0] is others[0] and out[2] is others[2]  # only the taker is held
        return out[1]

    # Not dashed since its kick: a touch is no fault (the server's compound kick)...
    assert sent(kick, near, _banned()) is kick
    # ... but a dash near the ball would run into it (a collision is a touch).
    assert sent(dash, near, _banned()) is None
    assert sent(dash, far, _banned()) is dash and sent(turn, near, _banned()) is turn
    # Once it has dashed, no kick, tackle or catch, wherever the ball is.
    for touch_command in (kick, Tackle(0.0), Catch(0.0)):
        assert sent(touch_command, near, _banned(dashed=True)) is None
    assert sent(turn, near, _banned(dashed=True)) is turn
    assert sent(dash, far, _banned(dashed=True)) is dash
    # No ban, or a ban before the ball is in play (the set piece's routine plays): unchanged.
    assert no_second_touch([kick, kick, dash], near, SecondTouch()) == [kick, kick, dash]
    pending = SecondTouch()
    pending.start(1, "kick_off_l")
    assert no_second_touch([kick, dash, dash], near, pending) == [kick, dash, dash]


def test_how_near_is_near_grows_with_the_age_of_the_see() -> None:
    # 0.385 m to touch plus 1.05 m a cycle over the see's age plus two cycles.
    fresh = _view(ball_distance=[40.0, 3.0, 30.0])
    assert not near_ball(fresh, 1)  # 3.0 > 0.385 + 2 x 1.05
    old = dataclasses.replace(fresh, stale=np.array([0, 1, 0], np.int32))
    assert near_ball(old, 1)  # 3.0 <= 0.385 + 3 x 1.05
    # The taker does not see the ball: the nearest teammate that does places it.
    behind = _view(
        position=np.array([[-50.0, 0.0], [0.0, 0.0], [3.0, 0.0]]),
        ball_seen=[False, False, True],
        ball_distance=[np.inf, np.inf, 2.0],
        ball_bearing=[0.0, 0.0, math.pi],  # player 2 faces away: the ball is at (1, 0)
    )
    assert near_ball(behind, 1)
    assert not near_ball(_view(ball_seen=[False] * 3), 1)  # nobody sees it: not held


def test_routines_turn_on_a_fresh_see_only() -> None:
    # Poses and bearings are the latest see's; after a turn they are out of date until the
    # next see. Turning again on a stale see overshoots: the set-piece taker and the goalie
    # spun in place.
    behind = _ball_at((-20.0, 0.0), heading=math.pi)
    stale = dataclasses.replace(behind, stale=np.array([1, 0, 0], np.int32))
    assert isinstance(guard_goal(POLICY, behind, "play_on", 0)[0][0], Turn)
    commands, guarded = guard_goal(POLICY, stale, "play_on", 0)
    assert guarded and commands[0] is None  # it waits for its next see
    side_on = _view(ball_bearing=[0.0, 1.0, 0.0], ball_distance=[40.0, 10.0, 30.0])
    commands, _ = apply_rules(POLICY, side_on, "kick_in_l", 0)
    assert isinstance(commands[1], Turn)
    side_on_stale = dataclasses.replace(side_on, stale=np.array([0, 2, 0], np.int32))
    commands, _ = apply_rules(POLICY, side_on_stale, "kick_in_l", 0)
    assert commands[1] is None
    # Facing the ball it runs on a stale see, but kicks (aimed from the see's heading) only
    # on a fresh one.
    ahead_stale = dataclasses.replace(side_on_stale, ball_bearing=np.zeros(3))
    assert isinstance(apply_rules(POLICY, ahead_stale, "kick_in_l", 0)[0][1], Dash)
    at_ball = _view(ball_distance=[40.0, 0.8, 30.0])
    assert isinstance(apply_rules(POLICY, at_ball, "kick_in_l", 0)[0][1], Kick)
    at_ball_stale = dataclasses.replace(at_ball, stale=np.array([0, 1, 0], np.int32))
    assert apply_rules(POLICY, at_ball_stale, "kick_in_l", 0)[0][1] is None


def test_the_set_piece_taker_stays_while_it_sees_the_ball() -> None:
    # Player 2 is nearer by this see, but player 1 is already on its way: it stays the taker
    # (nearest by each see, takers took turns and nobody reached the ball).
    view = _view(ball_distance=[40.0, 20.0, 15.0])
    assert set_piece_taker(view, exclude=0) == 2
    assert set_piece_taker(view, exclude=0, keep=1) == 1
    commands, _ = apply_rules(POLICY, view, "kick_in_l", 0, taker=1)
    assert commands[1] != POLICY[1] and commands[2] == POLICY[2]
    lost = _view(ball_distance=[40.0, 20.0, 15.0], ball_seen=[True, False, True])
    assert set_piece_taker(lost, exclude=0, keep=1) == 2  # it lost the ball: the nearest
    assert set_piece_taker(view, exclude=1, keep=1) == 2  # excluded (the goalie)


# -- the ban from the server's messages ----------------------------------------------------

NAMES = ("mine", "opp")


def _sense(time: int, kick: int = 0, dash: int = 0, collision: str = "none") -> object:
    """A v18 sense_body as rcssserver 19 sends it, with the counts and collisions given."""
    return parse_message(
        f"(sense_body {time} (view_mode high wide) (stamina 8000 1 130600) (speed 0 0) "
        f"(head_angle 0) (kick {kick}) (dash {dash}) (turn 0) (say 0) (turn_neck 0) (catch 0) "
        "(move 0) (change_view 1) (change_focus 0) (arm (movable 0) (expires 0) (target 0 0) "
        "(count 0)) (focus (target none) (count 0)) (tackle (expires 0) (count 0)) "
        f"(collision {collision}) (foul (charged 0) (card none)) (focus_point 0 0))"
    )


def _player(unum: int, sense: object, see: str | None = None) -> PlayerCycle:
    return PlayerCycle(0, unum, None if see is None else parse_message(see), sense, (), True)


def _cycle(*players: PlayerCycle, mode: str = "play_on", time: int = 30) -> Cycle:
    return Cycle(players, None, mode, (0, 0), (0, 0), time, 0, 0)


def _counts(time: int, kicks: tuple[int, int, int], collision: str = "none") -> list[PlayerCycle]:
    return [
        _player(i + 1, _sense(time, kick, collision=collision if i == 2 else "none"))
        for i, kick in enumerate(kicks)
    ]


def test_a_teammates_kick_count_or_its_collision_with_the_ball_is_a_touch() -> None:
    touch = _banned(taker=1)
    assert not touched_by_another(_cycle(*_counts(30, (0, 1, 0))), 0, 3, touch, NAMES)
    # The taker's own kick (a compound kick) is not another player's touch.
    assert not touched_by_another(_cycle(*_counts(31, (0, 2, 0))), 0, 3, touch, NAMES)
    # Player 3's count rose: the server counts kicks that reached the ball only.
    assert touched_by_another(_cycle(*_counts(32, (0, 2, 1))), 0, 3, touch, NAMES)
    assert touch.kicks == {0: 0, 1: 2, 2: 1}
    assert not touched_by_another(_cycle(*_counts(33, (0, 2, 1))), 0, 3, touch, NAMES)
    collided = _cycle(*_counts(34, (0, 2, 1), collision="(ball) (player)"))
    assert touched_by_another(collided, 0, 3, touch, NAMES)
    taker_collided = [_player(2, _sense(35, 2, collision="(ball)"))]
    assert not touched_by_another(_cycle(*taker_collided), 0, 3, touch, NAMES)


def test_an_opponent_seen_kicking_with_the_ball_in_its_reach_is_a_touch() -> None:
    touch = _banned(taker=1)
    sense = _sense(30)
    # The ball 5 m ahead; an opponent 0.9 m beyond it, kicking ("k").
    kicking = "(see 30 ((b) 5 0 0 0) ((p \"opp\" 9) 5.9 0 0 0 10 10 k))"
    assert touched_by_another(_cycle(_player(1, sense, kicking)), 0, 3, touch, NAMES)
    # "k" marks a kick attempt: 3 m from the ball it did not reach it.
    missed = "(see 30 ((b) 5 0 0 0) ((p \"opp\" 9) 8 0 0 0 10 10 k))"
    assert not touched_by_another(_cycle(_player(1, sense, missed)), 0, 3, touch, NAMES)
    # Not kicking, or a teammate (its own sense_body says for sure), or a team unknown.
    still = "(see 30 ((b) 5 0 0 0) ((p \"opp\" 9) 5.9 0 0 0 10 10))"
    mate = "(see 30 ((b) 5 0 0 0) ((p \"mine\" 3) 5.9 0 0 0 10 10 k))"
    unknown = "(see 30 ((b) 5 0 0 0) ((p) 5.9 0 k))"
    for see in (still, mate, unknown):
        assert not touched_by_another(_cycle(_player(1, sense, see)), 0, 3, touch, NAMES), see
    # An opponent team not named (a team told no opponent name): any other named team.
    assert touched_by_another(_cycle(_player(1, sense, kicking)), 0, 3, touch, ("mine", ""))


def _memory_seeing(ball: dict[int, float], stale: int = 0) -> PerceptMemory:
    """Three players of the left team at (-50, 0), (-1, 0), (-10, 5) facing the opponent goal,
    each seeing the ball dead ahead at ``ball[i]`` metres (none for others)."""
    memory = PerceptMemory(robocup_env_params(RoboCupConfig(players_per_team=3)), NAMES)
    positions = np.zeros((2, 3, 2))
    positions[0] = [[-50.0, 0.0], [-1.0, 0.0], [-10.0, 5.0]]
    memory.reset(positions, np.zeros((2, 3)))
    sees = [
        PlayerCycle(0, i + 1, parse_message(f"(see 30 ((b) {d} 0 0 0))"), None, (), True)
        for i, d in ball.items()
    ]
    memory.update(sees)
    memory.stale[:] += stale
    return memory


def test_match_routines_hold_the_kick_off_taker_until_a_teammate_plays_the_ball() -> None:
    """The defect read from 15 matches against helios-base: after the kick-off the taker
    dashed into its own ball (a second touch: free_kick_fault, then a goal against)."""
    routines = MatchRoutines(0, 3)
    dash = [Dash(100.0), Dash(100.0), Dash(100.0)]
    kick = [None, Kick(80.0, 0.0), None]
    cycle = 30

    def step(mode: str, ball: dict[int, float], policy: list, kicks=(0, 0, 0)) -> list:
        nonlocal cycle
        routines.observe_mode(mode)
        out, _ = routines.apply(policy, _memory_seeing(ball), _cycle(*_counts(cycle, kicks)))
        cycle += 1
        return out

    out = step("kick_off_l", {1: 0.7, 2: 9.0}, dash)  # the taker at the ball kicks off
    assert isinstance(out[1], Kick) and routines.touch.taker == 1
    out = step("play_on", {1: 1.5, 2: 8.0}, dash, kicks=(0, 1, 0))  # it runs after the ball
    assert out[1] is None and out[2] == dash[2] and routines.scripted[1]
    out = step("play_on", {1: 1.0, 2: 7.0}, kick, kicks=(0, 1, 0))  # no dash yet: no fault
    assert out[1] == kick[1]
    out = step("play_on", {1: 8.0, 2: 1.0}, dash, kicks=(0, 2, 0))  # the ball is away now
    assert isinstance(out[1], Dash) and routines.touch.dashed
    out = step("play_on", {1: 0.9, 2: 1.0}, kick, kicks=(0, 2, 0))  # back at the ball
    assert out[1] is None
    # Player 3 kicked the ball (its count rose): the ban is over.
    out = step("play_on", {1: 0.9, 2: 1.0}, kick, kicks=(0, 2, 1))
    assert out[1] == kick[1] and routines.touch.taker is None and not routines.scripted[1]


def test_the_last_kick_is_ours_after_a_teammates_count_rises_until_an_opponent_plays_it() -> None:
    last = LastKick()
    last.observe(_cycle(*_counts(30, (0, 0, 0))), "play_on", 0, 3, NAMES)
    assert not last.ours  # the first sense_body only sets the counts
    last.observe(_cycle(*_counts(31, (1, 0, 0))), "play_on", 0, 3, NAMES)
    assert not last.ours  # the goalie's own kick: after an opponent's it may catch
    last.observe(_cycle(*_counts(32, (1, 0, 1))), "play_on", 0, 3, NAMES)
    assert last.ours
    for see in ("(see 33 ((b) 5 0 0 0) ((p \"mine\" 3) 5.9 0 0 0 10 10 k))",  # a teammate
                "(see 33 ((b) 5 0 0 0) ((p \"opp\" 9) 8 0 0 0 10 10))"):  # 3 m from the ball
        last.observe(_cycle(_player(1, _sense(33, 1), see)), "play_on", 0, 3, NAMES)
        assert last.ours, see
    # An opponent seen with the ball in its reach (a see shows its kick once in three).
    near = "(see 34 ((b) 5 0 0 0) ((p \"opp\" 9) 5.9 0 0 0 10 10))"
    last.observe(_cycle(_player(1, _sense(34, 1), near)), "play_on", 0, 3, NAMES)
    assert not last.ours
    # Another kick of ours, then a stoppage: the server forgets the kicker.
    last.observe(_cycle(*_counts(35, (1, 1, 1))), "play_on", 0, 3, NAMES)
    assert last.ours
    last.observe(_cycle(*_counts(36, (1, 1, 1))), "kick_in_r", 0, 3, NAMES)
    assert not last.ours
    # Far away, tackling ("t") counts as kicking.
    last.observe(_cycle(*_counts(37, (1, 2, 1))), "play_on", 0, 3, NAMES)
    far = "(see 38 ((b) 5 0 0 0) ((p \"opp\" 9) 20 0 0 0 10 10 t))"
    last.observe(_cycle(_player(1, _sense(38, 1), far)), "play_on", 0, 3, NAMES)
    assert not last.ours


def test_match_routines_keep_the_goalie_from_catching_a_teammates_kick() -> None:
    """Read from naive's matches against helios-base: its goalie caught the kick-off taker's
    ball 28 times in 3 matches (back_pass: an indirect free kick in its area), 22 goals."""
    routines = MatchRoutines(0, 3)
    policy = [Dash(10.0), Dash(20.0), Dash(30.0)]
    opponent = "(see 33 ((b) 1 0 0 0) ((p \"opp\" 9) 1.5 0 0 0 10 10))"
    steps = [((0, 0, 0), None, "catch"), ((0, 1, 0), None, "policy"),
             ((0, 1, 0), None, "policy"), ((0, 1, 0), opponent, "catch")]
    for time, (kicks, see, what) in enumerate(steps, start=30):
        routines.observe_mode("play_on")
        players = _counts(time, kicks)
        if see is not None:
            players[0] = _player(1, _sense(time, kicks[0]), see)
        routines.cycles += 5  # out of the catch ban (a catch every 5 cycles at most)
        _, got = routines.apply(policy, _memory_seeing({0: 1.0}), _cycle(*players, time=time))
        assert got == what, (time, kicks)

