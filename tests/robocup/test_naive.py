"""RoboCupNaiveTeam (thesis 6.7): hand-built observations, and a short game on a real server."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from elevens.env.state import NUM_ENTITY_FEATURES, NUM_SELF_FEATURES, SELF_FEATURES, Observation
from elevens.robocup.actions import ActionIndex, actions_to_commands
from elevens.robocup.env import RoboCupConfig, RoboCupEnv, sim_actions_to_commands
from elevens.robocup.naive import RoboCupNaiveTeam
from elevens.robocup.protocol import Dash, Kick, Turn
from tests.robocup.conftest import needs_rcssserver

S = {name: i for i, name in enumerate(SELF_FEATURES)}
EXTENT = np.array([52.5, 34.0])


def team_obs(players: list[dict[str, Any]]) -> Observation:
    """One team's Observation [n]: each player at ``pos`` (metres, team frame) facing
    ``heading`` (radians), seeing the ball at ``ball`` = (distance m, bearing rad) or not."""
    n = len(players)
    features = np.zeros((n, NUM_SELF_FEATURES), np.float32)
    for i, p in enumerate(players):
        features[i, S["time_left"]] = 1.0
        features[i, S["x"] : S["y"] + 1] = np.asarray(p["pos"]) / EXTENT
        features[i, S["cos_heading"]] = math.cos(p.get("heading", 0.0))
        features[i, S["sin_heading"]] = math.sin(p.get("heading", 0.0))
        if p.get("ball") is not None:
            distance, bearing = p["ball"]
            features[i, S["ball_visible"]] = 1.0
            features[i, S["ball_distance"]] = distance / 105.0
            features[i, S["ball_cos_bearing"]] = math.cos(bearing)
            features[i, S["ball_sin_bearing"]] = math.sin(bearing)
    leaves: dict[str, Any] = dict(
        self_features=features,
        entities=np.zeros((n, 2 * n, NUM_ENTITY_FEATURES), np.float32),
        entity_mask=np.zeros((n, 2 * n), bool),
    )
    return Observation(**leaves)


def act(team: RoboCupNaiveTeam, players: list[dict[str, Any]]) -> np.ndarray:
    _, actions = team.act(None, team.init_carry(len(players)), team_obs(players), None)
    return actions


def test_kicks_a_kickable_ball_at_the_goal_centre() -> None:
    team = RoboCupNaiveTeam()
    actions = act(team, [{"pos": (40.0, 10.0), "ball": (0.6, 0.0)}])
    assert actions.shape == (1, 12) and actions.dtype == np.float32
    (command,) = actions_to_commands(actions)
    # Goal centre (52.5, 0) from (40, 10) facing +x: 38.7 deg to the right = server +38.7.
    assert isinstance(command, Kick)
    assert command.power == pytest.approx(100.0)
    assert command.direction == pytest.approx(math.degrees(math.atan2(10.0, 12.5)), abs=1e-3)


def test_sim_actions_turn_to_the_goal_then_kick_along_the_body() -> None:
    team = RoboCupNaiveTeam(action="sim", turn_scale=180.0)
    aside = act(team, [{"pos": (40.0, 10.0), "ball": (0.6, 0.0)}])
    (turn,) = sim_actions_to_commands(aside, np.array([0.6]), kickable=1.085)
    assert isinstance(turn, Turn)
    assert turn.moment == pytest.approx(math.degrees(math.atan2(10.0, 12.5)), abs=1e-3)
    heading = -math.atan2(10.0, 12.5)
    facing = act(team, [{"pos": (40.0, 10.0), "heading": heading, "ball": (0.6, 0.0)}])
    assert sim_actions_to_commands(facing, np.array([0.6]), kickable=1.085) == [Kick(100.0, 0.0)]


def test_chases_the_ball_turning_first_when_it_is_off_to_the_side() -> None:
    team = RoboCupNaiveTeam()
    left = act(team, [{"pos": (0.0, 0.0), "ball": (20.0, math.radians(40.0))}])
    (turn,) = actions_to_commands(left)
    assert isinstance(turn, Turn) and turn.moment == pytest.approx(-40.0, abs=1e-3)  # server CCW
    ahead = act(team, [{"pos": (0.0, 0.0), "ball": (20.0, math.radians(-5.0))}])
    (dash,) = actions_to_commands(ahead)
    assert isinstance(dash, Dash) and dash.power == pytest.approx(100.0)
    assert dash.direction == pytest.approx(5.0, abs=1e-3)  # server clockwise: to the right
    sim = RoboCupNaiveTeam(action="sim")
    np.testing.assert_allclose(
        act(sim, [{"pos": (0.0, 0.0), "ball": (20.0, math.radians(-5.0))}]), [[1.0, 0.0]]
    )


def test_searches_when_nobody_knows_the_ball_and_shares_sightings() -> None:
    team = RoboCupNaiveTeam()
    blind = act(team, [{"pos": (0.0, 0.0)}])
    assert blind[0, ActionIndex.TURN_SCORE] == 1.0
    assert blind[0, ActionIndex.TURN_MOMENT] == pytest.approx(60.0 / 180.0)
    # Player 2 does not see the ball but player 1 does (at (10, 0)): player 2, at (10, -20)
    # facing +x, turns left (counter-clockwise) towards it.
    shared = act(
        team,
        [{"pos": (0.0, 0.0), "ball": (10.0, 0.0)}, {"pos": (10.0, -20.0)}],
    )
    (_, turn) = actions_to_commands(shared)
    assert isinstance(turn, Turn) and turn.moment == pytest.approx(-90.0, abs=1e-3)


def test_does_not_turn_again_on_a_stale_observation() -> None:
    """A repeated snapshot (no new see yet) still shows the old bearing: the team takes off the
    turn it already commanded and dashes instead of turning twice."""
    team = RoboCupNaiveTeam()
    obs = team_obs([{"pos": (0.0, 0.0), "ball": (20.0, math.radians(40.0))}])
    carry = team.init_carry(1)
    carry, first = team.act(None, carry, obs, None)
    carry, second = team.act(None, carry, obs, None)
    assert first[0, ActionIndex.TURN_SCORE] == 1.0
    assert second[0, ActionIndex.DASH_SCORE] == 1.0
    moved = team_obs([{"pos": (0.0, 0.0), "ball": (19.0, math.radians(40.0))}])
    _, third = team.act(None, carry, moved, None)  # a fresh see: the bearing counts again
    assert third[0, ActionIndex.TURN_SCORE] == 1.0


def test_rejects_an_unknown_action_mode() -> None:
    with pytest.raises(ValueError, match="action"):
        RoboCupNaiveTeam(action="discrete")


# ------------------------------------------------------------------------ integration
@needs_rcssserver
def test_naive_team_plays_the_ball_against_random_in_1v1() -> None:
    """300 steps of 1 v 1: the naive player reaches the ball and kicks it (the ball speeds up
    next to it) or scores."""
    naive = RoboCupNaiveTeam()
    rng = np.random.default_rng(0)
    config = RoboCupConfig(players_per_team=1, action="thesis12", episode_length=300)
    kicks = goals = 0
    closest = math.inf
    with RoboCupEnv(config) as env:
        state, obs = env.reset(seed=0)
        carry = naive.init_carry(1)
        for _ in range(300):
            carry, mine = naive.act(None, carry, obs.team(0), None)
            theirs = rng.uniform(-1.0, 1.0, (1, 12)).astype(np.float32)
            before = state
            state, obs, _, done, info = env.step(np.stack([mine, theirs]))
            goals += int(info["goals"][0])
            if info["goals"].any():
                continue
            gap = float(np.linalg.norm(before.ball_position - before.positions[0]))
            closest = min(closest, gap)
            speed_before = float(np.linalg.norm(before.ball_velocity))
            speed = float(np.linalg.norm(state.ball_velocity))
            if gap < 1.5 and speed > 0.94 * speed_before + 0.3:
                kicks += 1
            if done:
                break
    assert closest < 1.5, f"the naive player never reached the ball (closest {closest:.1f} m)"
    assert kicks + goals >= 1


def test_slows_down_next_to_the_ball() -> None:
    """Sees come every few steps: close to the ball the dash softens so the player does not run
    past it before the next one."""
    team = RoboCupNaiveTeam()
    near = act(team, [{"pos": (0.0, 0.0), "ball": (2.0, 0.0)}])
    far = act(team, [{"pos": (0.0, 0.0), "ball": (9.0, 0.0)}])
    assert near[0, ActionIndex.DASH_SCORE] == far[0, ActionIndex.DASH_SCORE] == 1.0
    assert 0.3 <= near[0, ActionIndex.DASH_POWER] < 0.5 and far[0, ActionIndex.DASH_POWER] == 1.0
    carry = team.init_carry(1)
    obs = team_obs([{"pos": (0.0, 0.0), "ball": (0.5, 0.0)}])
    carry, first = team.act(None, carry, obs, None)
    _, second = team.act(None, carry, obs, None)  # stale: the ball has gone since the kick
    assert first[0, ActionIndex.KICK_SCORE] == 1.0 and second[0, ActionIndex.KICK_SCORE] < 1.0


def test_intercept_runs_for_the_rolling_balls_course() -> None:
    # The ball 10 m ahead rolls to the player's left at 1.5 m a cycle: the plain chaser dashes
    # straight at it, the interceptor turns left to meet it on its course.
    obs = team_obs([{"pos": (0.0, 0.0), "ball": (10.0, 0.0)}])
    obs.self_features[0, S["ball_vel_left"]] = 1.5
    chaser, interceptor = RoboCupNaiveTeam(), RoboCupNaiveTeam(intercept=True)
    (dash,) = actions_to_commands(chaser.act(None, chaser.init_carry(1), obs, None)[1])
    assert isinstance(dash, Dash) and dash.direction == pytest.approx(0.0, abs=1e-3)
    (turn,) = actions_to_commands(interceptor.act(None, interceptor.init_carry(1), obs, None)[1])
    assert isinstance(turn, Turn) and -80.0 < turn.moment < -20.0  # server: counter-clockwise
    # Where it aims: the first point of the course it can reach at 0.85 m a cycle.
    course = np.array([10.0, 0.0])
    velocity = np.array([0.0, 1.5])
    for cycle in range(1, 41):
        course, velocity = course + velocity, velocity * 0.94
        if np.hypot(*course) <= 0.85 * cycle + 1.085:
            break
    assert -turn.moment == pytest.approx(math.degrees(math.atan2(course[1], course[0])), abs=1e-3)
    # A ball at rest: both chase it alike.
    still = team_obs([{"pos": (0.0, 0.0), "ball": (10.0, math.radians(-5.0))}])
    np.testing.assert_allclose(
        chaser.act(None, chaser.init_carry(1), still, None)[1],
        interceptor.act(None, interceptor.init_carry(1), still, None)[1], atol=1e-6,
    )
