"""skills_naive's choices in scenes where the right one is clear, and the decision space's
mapping to the proxy's skills."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from elevens.robocup.skills.naive import (
    ATTACK_PUSH,
    DEEPEST,
    DEFEND_DROP,
    FORMATION,
    SkillsNaive,
    skills_naive_decisions,
    slot_targets,
)
from elevens.robocup.skills.observe import Observation, observe
from elevens.robocup.skills.set_plays import TAKER_CYCLES
from elevens.robocup.skills.space import (
    DRIBBLE_DIRECTIONS,
    DRIBBLE_LENGTH,
    Decisions,
    Kind,
    pass_speed,
    to_player_actions,
)
from tests.robocup.fake_proxy import OURS, THEIRS, Scene, state

FAR_OPPONENTS = np.array([[50.0, 0.0]] + [[40.0, -30.0 + 6.0 * k] for k in range(10)],
                         np.float32)


def _holder_scene(holder_at: tuple[float, float], theirs: np.ndarray,
                  forward: dict[int, tuple[float, float]] | None = None) -> Scene:
    """Player 6 has the ball at ``holder_at``; every teammate not in ``forward`` stays well
    behind it."""
    ours = np.stack([np.array([-40.0, -25.0 + 5.0 * k]) for k in range(11)]).astype(np.float32)
    ours[5] = holder_at
    for unum, xy in (forward or {}).items():
        ours[unum - 1] = xy
    ball = (holder_at[0] + 0.5, holder_at[1])
    return Scene(ours=ours, theirs=theirs.astype(np.float32), ball=ball, kickable=6)


def _decide(scene: Scene, *unums: int) -> tuple[Observation, Decisions]:
    obs = observe([state(scene, u) for u in unums])
    return obs, skills_naive_decisions(obs)


def test_passes_forward_to_the_open_teammate_not_the_covered_one() -> None:
    theirs = FAR_OPPONENTS.copy()
    theirs[1] = (8.0, 4.0)  # on the lane to player 11
    scene = _holder_scene((0.0, 0.0), theirs, forward={10: (15.0, -8.0), 11: (15.0, 8.0)})
    obs, dec = _decide(scene, 6)
    assert (dec.kind[0], dec.index[0]) == (Kind.PASS, 10)
    kick = to_player_actions(dec, obs)[0].actions[0].body_smart_kick
    assert (kick.target_point.x, kick.target_point.y) == (15.0, -8.0)
    assert kick.first_speed == pytest.approx(float(pass_speed(np.hypot(15.0, 8.0))))
    assert 1.0 < kick.first_speed < 3.0


def test_dribbles_at_goal_with_no_one_to_pass_to() -> None:
    obs, dec = _decide(_holder_scene((0.0, 0.0), FAR_OPPONENTS), 6)
    assert (dec.kind[0], dec.index[0]) == (Kind.DRIBBLE, 0)  # straight at their goal
    dribble = to_player_actions(dec, obs)[0].actions[0].body_dribble
    assert (dribble.target_point.x, dribble.target_point.y) == (8.0, 0.0)


def test_holds_when_every_forward_path_is_blocked() -> None:
    theirs = FAR_OPPONENTS.copy()
    for k, angle in enumerate((0, 45, 90, -90, -45)):
        a = np.radians(angle)
        theirs[1 + k] = (1.6 * np.cos(a), 1.6 * np.sin(a))
    obs, dec = _decide(_holder_scene((0.0, 0.0), theirs), 6)
    assert dec.kind[0] == Kind.HOLD
    hold = to_player_actions(dec, obs)[0].actions[0].body_hold_ball
    assert (hold.kick_target_point.x, hold.kick_target_point.y) == pytest.approx((1.6, 0.0))


def test_clears_at_their_goal_when_blocked_and_an_opponent_can_kick_the_ball_too() -> None:
    # Two holders of one ball kick it to either side of it: it stays between them.
    theirs = FAR_OPPONENTS.copy()
    for k, angle in enumerate((0, 45, 90, -90, -45)):
        a = np.radians(angle)
        theirs[1 + k] = (1.6 * np.cos(a), 1.6 * np.sin(a))
    scene = dataclasses.replace(_holder_scene((0.0, 0.0), theirs), kickable_opponent=True)
    obs, dec = _decide(scene, 6)
    assert dec.kind[0] == Kind.SHOOT
    assert dec.point[0][0] == pytest.approx(52.5)


def test_shoots_near_goal_away_from_the_goalie() -> None:
    theirs = FAR_OPPONENTS.copy()
    theirs[0] = (50.0, 3.0)
    obs, dec = _decide(_holder_scene((40.0, 0.0), theirs), 6)
    assert dec.kind[0] == Kind.SHOOT
    assert dec.point[0, 0] == 52.5 and -7.0 < dec.point[0, 1] < 0.0


def test_slots_slide_with_the_ball_and_stay_onside() -> None:
    unum = np.arange(1, 12)
    ahead = slot_targets(unum, np.tile([30.0, 10.0], (11, 1)), np.full(11, 20.0, np.float32))
    behind = slot_targets(unum, np.tile([-30.0, -10.0], (11, 1)), np.full(11, 0.0, np.float32))
    assert (ahead[:, 0] <= 19.0).all() and (ahead[:, 0] > behind[:, 0]).all()
    assert (ahead[1:, 1] > behind[1:, 1]).all()
    slid = FORMATION + [[-18.0, -3.0]]
    slid[:, 0] = np.maximum(slid[:, 0], -48.0)  # never behind the goal line
    assert np.allclose(behind, slid)


def test_tackles_an_opponent_on_the_ball_when_likely_to_win_it() -> None:
    obs, _ = _decide(Scene(ball=(-20.0, 0.0)), 3, 4)
    obs = dataclasses.replace(obs, kickable_opp=np.array([True, True]),
                              tackle_probability=np.array([0.9, 0.2], np.float32))
    kinds = skills_naive_decisions(obs).kind
    assert kinds[0] == Kind.TACKLE and kinds[1] != Kind.TACKLE


def test_set_pieces_and_the_goalie_use_the_ready_behaviours() -> None:
    obs, dec = _decide(Scene(mode=6, ball=(52.0, 34.0)), 1, 5, 10)  # a corner kick
    assert list(dec.kind) == [Kind.GOALIE, Kind.SET_PLAY, Kind.SET_PLAY]
    answers = to_player_actions(dec, obs)
    assert answers[1].actions[0].helios_set_play is not None
    assert not answers[1].ignore_doIntention  # set plays keep the proxy's reflexes


def _kick_off(cycle: int = 1, **changes: object) -> Scene:
    """Our kick-off: player 10 at the ball on the centre spot, the rest in our half."""
    ours = OURS.copy()
    ours[9] = (-0.6, 0.0)
    scene = Scene(ours=ours, ball=(0.0, 0.0), mode=3, our_set_play=True, kickable=10,
                  cycle=cycle)
    return dataclasses.replace(scene, **changes)


def test_a_team_deciding_its_set_plays_takes_the_kick_off_and_keeps_the_free_kick_rule() -> None:
    team = SkillsNaive()
    unums = (1, 9, 10)
    states = [state(_kick_off(), u) for u in unums]
    obs = observe(states)
    routine = skills_naive_decisions(obs)
    assert list(routine.kind) == [Kind.GOALIE, Kind.SET_PLAY, Kind.SET_PLAY]
    # Decided: the goalie keeps its routine; no teammate is ahead of the ball, so the taker
    # passes back (open play passes forward only), as a kick-off is taken.
    decided = skills_naive_decisions(obs, "decided")
    assert decided.kind[0] == Kind.GOALIE and decided.kind[1] not in (Kind.SET_PLAY, Kind.KICK)
    assert decided.kind[2] == Kind.PASS
    assert OURS[decided.index[2] - 1, 0] < obs.pos[2, 0] and decided.index[2] != 1
    answers = team(states)
    assert answers[2].actions[0].body_smart_kick is not None
    assert answers[2].ignore_doIntention and answers[1].ignore_doIntention
    # A taker's dribble (here the guard's input) is kicks alone: a KICK to the dribble's end.
    dribble = Decisions.of(np.array([Kind.DRIBBLE]), np.array([2]))
    taking = observe([state(_kick_off(), 10)])
    kicked, changed = team.guard.apply(taking, dribble)
    end = taking.pos[0] + DRIBBLE_LENGTH * DRIBBLE_DIRECTIONS[2]
    assert kicked.kind.tolist() == [Kind.KICK] and changed.tolist() == [True]
    np.testing.assert_allclose(kicked.point[0], end, atol=1e-5)
    kick = to_player_actions(kicked, taking)[0]
    assert kick.actions[0].body_smart_kick.first_speed == pytest.approx(
        float(pass_speed(DRIBBLE_LENGTH)), rel=1e-5)
    assert kick.ignore_doIntention
    # Play on, the ball 8 m ahead and player 10 the last kicker: it may not run at the ball
    # (an intercept becomes a run to its slot); once another player kicks, it may.
    ours = OURS.copy()
    ours[9] = (0.0, 0.0)
    after = Scene(ours=ours, ball=(8.0, 0.0), mode=2, last_kicker=10, cycle=2)
    took = observe([state(after, 10)])
    assert skills_naive_decisions(took).kind[0] == Kind.INTERCEPT
    answer = team([state(after, 10)])[0]
    assert answer.actions[0].body_go_to_point is not None
    assert team([state(dataclasses.replace(after, cycle=3), 10)])[0] == answer
    touched = dataclasses.replace(after, last_kicker=9, cycle=4)
    assert team([state(touched, 10)])[0].actions[0].body_intercept is not None
    assert team([state(dataclasses.replace(after, cycle=5), 10)])[0].actions[0].body_intercept \
        is not None  # the memory ended with the other kick


def test_the_free_kick_rule_ends_at_another_stoppage_and_after_its_cycles() -> None:
    team = SkillsNaive()
    team([state(_kick_off(cycle=10), 10)])
    ours = OURS.copy()
    ours[9] = (0.0, 0.0)
    after = Scene(ours=ours, ball=(8.0, 0.0), mode=2, last_kicker=10)
    bound = dataclasses.replace(after, cycle=10 + TAKER_CYCLES)
    assert team([state(bound, 10)])[0].actions[0].body_go_to_point is not None
    late = dataclasses.replace(after, cycle=11 + TAKER_CYCLES)
    assert team([state(late, 10)])[0].actions[0].body_intercept is not None
    team([state(_kick_off(cycle=20), 10)])
    team([state(dataclasses.replace(after, mode=5, our_set_play=False, cycle=21), 10)])
    assert team([state(dataclasses.replace(after, cycle=22), 10)])[0].actions[0] \
        .body_intercept is not None
    team.reset()
    assert not team.guard.takers(observe([state(dataclasses.replace(after, cycle=23), 10)])).any()


def test_their_set_plays_goal_kicks_and_the_goalies_catch_stay_routines_when_deciding() -> None:
    for mode, ours in ((5, False), (4, False), (7, True), (30, True)):
        scene = Scene(mode=mode, our_set_play=ours, ball=(30.0, 10.0))
        obs = observe([state(scene, u) for u in (1, 5)])
        kinds = skills_naive_decisions(obs, "decided").kind
        assert list(kinds) == [Kind.GOALIE, Kind.SET_PLAY], mode


def test_bad_decisions_are_refused_in_one_line() -> None:
    obs = observe([state(Scene(), 2)])
    with pytest.raises(ValueError, match=r"PASS index 12 \(allowed: 1..11\)"):
        to_player_actions(Decisions.of(np.array([Kind.PASS]), np.array([12])), obs)
    with pytest.raises(ValueError, match=r"kind 42 \(allowed: 0..14\)"):
        to_player_actions(Decisions.of(np.array([42])), obs)
    with pytest.raises(ValueError, match=r"shapes kind \(2,\)"):
        to_player_actions(Decisions.of(np.array([0, 0])), obs)


def test_observation_slots_by_shirt_number() -> None:
    obs = observe([state(Scene(), u) for u in (1, 7)])
    assert list(obs.unum) == [1, 7] and list(obs.goalie) == [True, False]
    assert obs.mates_valid.all() and obs.opps_valid.all()
    assert np.allclose(obs.mates[1], OURS) and np.allclose(obs.opps[0], THEIRS)


def test_while_they_have_the_ball_the_next_nearest_covers_goal_side() -> None:
    ours, theirs = OURS.copy(), THEIRS.copy()
    ours[7] = (-17.0, -5.0)  # player 8 is nearest the ball, player 7 next
    theirs[9] = (-20.0, 0.0)
    held = Scene(ours=ours, theirs=theirs, ball=(-20.5, 0.0), kickable_opponent=True)
    _, dec = _decide(held, 3, 7, 8)
    assert list(dec.kind) == [Kind.GO_TO, Kind.GO_TO, Kind.INTERCEPT]
    assert dec.point[1] == pytest.approx((-23.5, 0.0))  # 3 m towards our goal
    assert dec.point[0, 0] < -25.0  # player 3 keeps its slot
    theirs[9] = THEIRS[9]  # a loose ball we reach first: no cover, the slot steps up
    obs, loose = _decide(Scene(ours=ours, theirs=theirs, ball=(-20.5, 0.0)), 7)
    slot = slot_targets(obs.unum, obs.ball, obs.offside_x)[0]
    assert loose.kind[0] == Kind.GO_TO
    assert loose.point[0] == pytest.approx(slot + (ATTACK_PUSH, 0.0))


def test_while_they_have_the_ball_the_block_is_deeper_and_narrower() -> None:
    theirs = THEIRS.copy()
    theirs[9] = (0.0, 15.0)  # on the ball at the centre line, on our left
    unums = (2, 5, 7, 9)  # none of them near the ball
    held = Scene(theirs=theirs, ball=(0.5, 15.0), kickable_opponent=True)
    obs, dec = _decide(held, *unums)
    assert (dec.kind == Kind.GO_TO).all()
    slots = slot_targets(obs.unum, obs.ball, obs.offside_x)
    assert np.allclose(dec.point[:, 0], slots[:, 0] - DEFEND_DROP)
    assert np.ptp(dec.point[:, 1]) < np.ptp(slots[:, 1]) - 10.0  # narrower
    # drawn to the ball's side: every slot nearer the ball's y
    assert (np.abs(dec.point[:, 1] - 15.0) < np.abs(slots[:, 1] - 15.0) - 4.0).all()
    theirs[9] = (-40.5, 15.0)
    _, dec = _decide(Scene(theirs=theirs, ball=(-40.0, 15.0), kickable_opponent=True), 3)
    assert dec.point[0, 0] == pytest.approx(DEEPEST)  # not on the goal line


def test_free_defenders_mark_the_attackers_in_our_third() -> None:
    ours, theirs = OURS.copy(), THEIRS.copy()
    theirs[9] = (-25.0, -20.0)  # on the ball
    theirs[10] = (-30.0, -5.0)  # free in our third, nearest player 4 (-32, -7)
    theirs[6] = (-10.0, 5.0)  # in the middle: not marked
    ours[5] = (-24.0, -18.0)  # player 6 intercepts, player 2 covers
    ours[1] = (-27.0, -18.0)
    held = Scene(ours=ours, theirs=theirs, ball=(-25.5, -20.0), kickable_opponent=True)
    obs, dec = _decide(held, 2, 3, 4, 7, 10)
    assert dec.kind[2] == Kind.MARK and dec.index[2] == 11
    assert (np.delete(dec.kind, 2) != Kind.MARK).all()  # one marker; the forward never marks
    go = to_player_actions(dec, obs)[2].actions[0].body_go_to_point
    assert go.target_point.x < -30.0  # goal-side of the attacker
    _, ours_now = _decide(dataclasses.replace(held, kickable=6, kickable_opponent=False), 4)
    assert ours_now.kind[0] == Kind.GO_TO  # with the ball ours, nobody marks


def test_passes_from_our_third_need_a_wider_lane_and_never_go_across_it() -> None:
    theirs = FAR_OPPONENTS.copy()
    holder = (-35.0, -10.0)
    across = _holder_scene(holder, theirs, forward={3: (-32.0, 10.0)})
    _, dec = _decide(across, 6)
    assert dec.kind[0] != Kind.PASS  # 20 m across our box, 3 m forward
    theirs[1] = (-25.0, -6.0)  # 4 m from the lane to player 7
    tight = _holder_scene(holder, theirs, forward={7: (-15.0, -4.0)})
    _, dec = _decide(tight, 6)
    assert dec.kind[0] != Kind.PASS
    theirs[1] = FAR_OPPONENTS[1]
    _, dec = _decide(_holder_scene(holder, theirs, forward={7: (-15.0, -4.0)}), 6)
    assert (dec.kind[0], dec.index[0]) == (Kind.PASS, 7)


def test_runs_to_a_point_are_paced_by_stamina() -> None:
    obs, _ = _decide(Scene(ball=(-20.0, 0.0)), 3, 4, 5)
    obs = dataclasses.replace(obs, stamina=np.array([8000.0, 4000.0, 2500.0], np.float32))
    dec = Decisions.of(np.full(3, Kind.GO_TO), point=np.zeros((3, 2), np.float32))
    powers = [a.actions[0].body_go_to_point.max_dash_power for a in to_player_actions(dec, obs)]
    assert powers == pytest.approx([100.0, 65.0, 30.0])
