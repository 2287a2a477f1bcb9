"""rcss_naive: the RoboCup naive team in the simulator with rcssserver's bodies (12 values)."""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.eval.match import play_match, summary
from elevens.robocup.bodies import (
    DASH,
    KICK,
    TURN,
    Commands,
    RcssSoccer,
    decode_thesis12,
    encode_thesis12,
)
from elevens.robocup.rcss_naive import RcssNaiveTeam
from elevens.runs.teams import load_team, team_on_field
from elevens.teams.registry import resolve_team


def test_encoded_commands_decode_to_themselves() -> None:
    rng = np.random.default_rng(0)
    count = 200
    commands = Commands(
        kind=jnp.asarray(rng.integers(0, 5, count)),
        dash_power=jnp.asarray(rng.uniform(0, 100, count), jnp.float32),
        dash_direction=jnp.asarray(rng.uniform(-180, 180, count), jnp.float32),
        kick_power=jnp.asarray(rng.uniform(0, 100, count), jnp.float32),
        kick_direction=jnp.asarray(rng.uniform(-180, 180, count), jnp.float32),
        turn_moment=jnp.asarray(rng.uniform(-180, 180, count), jnp.float32),
    )
    actions = encode_thesis12(commands)
    assert actions.shape == (count, 12)
    assert float(jnp.max(jnp.abs(actions))) <= 1.0
    back = decode_thesis12(actions)
    np.testing.assert_array_equal(back.kind, commands.kind)
    for field in ("dash_power", "dash_direction", "kick_power", "kick_direction", "turn_moment"):
        np.testing.assert_allclose(
            getattr(back, field), getattr(commands, field), atol=1e-3, err_msg=field
        )


@functools.cache
def _game(n: int):
    env = RcssSoccer(n)
    params = env.default_params()
    return env, params, jax.jit(env.reset), jax.jit(env.observe)


def _team_obs(n: int, player: tuple[float, float], heading: float, ball: tuple[float, float]):
    """Team 0's observation with its player 0 at ``player`` facing ``heading`` (world frame,
    team 0 attacks +x) and the ball at ``ball``; the others far off."""
    env, params, reset, observe = _game(n)
    state, _ = reset(jax.random.key(0), params)
    positions = np.array(state.positions)
    positions[0] = player
    headings = np.array(state.headings)
    headings[0] = heading
    state = dataclasses.replace(
        state,
        positions=jnp.asarray(positions),
        headings=jnp.asarray(headings),
        ball_position=jnp.asarray(ball, jnp.float32),
        ball_velocity=jnp.zeros(2),
    )
    obs = observe(state, params)
    return jax.tree.map(lambda leaf: leaf[0], obs), params


def _command(team: RcssNaiveTeam, obs) -> Commands:
    _, actions = jax.jit(team.act)(None, team.init_carry(1), obs, jax.random.key(0))
    assert actions.shape == (1, 12)
    return jax.tree.map(lambda leaf: leaf[0], decode_thesis12(actions))


def test_a_player_beside_the_ball_kicks_it_at_the_goal_centre() -> None:
    # Facing the side line (+y), ball 0.8 m ahead: kick at the goal (52.5, 0) to its right.
    obs, _ = _team_obs(1, (30.0, -10.0), math.pi / 2, (30.0, -9.2))
    command = _command(RcssNaiveTeam(), obs)
    assert int(command.kind) == KICK
    to_goal = math.degrees(math.atan2(10.0, 22.5))  # counter-clockwise from +x
    expected = -(to_goal - 90.0)  # the server's clockwise angle from the body
    assert float(command.kick_direction) == pytest.approx(expected, abs=0.5)
    assert float(command.kick_power) == pytest.approx(100.0)


def test_a_player_turns_to_a_ball_off_its_body_and_dashes_at_one_ahead() -> None:
    team = RcssNaiveTeam()
    unseen, _ = _team_obs(1, (0.0, 0.0), 0.0, (-10.0, 0.0))  # behind: out of view
    aside, _ = _team_obs(1, (0.0, 0.0), 0.0, (10.0, 10.0))  # 45 degrees to the left
    ahead, _ = _team_obs(1, (0.0, 0.0), 0.0, (10.0, 1.0))
    search = _command(team, unseen)
    assert int(search.kind) == TURN and float(search.turn_moment) == pytest.approx(60.0)
    turn = _command(team, aside)
    assert int(turn.kind) == TURN and float(turn.turn_moment) == pytest.approx(-45.0, abs=0.5)
    dash = _command(team, ahead)
    assert int(dash.kind) == DASH
    assert float(dash.dash_power) == pytest.approx(100.0)
    # The ball is a little to the left: the server's direction is a little anticlockwise (-).
    assert float(dash.dash_direction) == pytest.approx(-math.degrees(math.atan2(1, 10)), abs=0.5)


@dataclasses.dataclass(frozen=True)
class StandStill:
    """A 12-value team whose players do nothing (the no-op command) every cycle."""

    name: str = "idle"

    def init_carry(self, n: int) -> tuple[()]:
        return ()

    def act(self, params, carry, obs, key):
        return carry, jnp.zeros((obs.self_features.shape[0], 12)).at[:, 4].set(1.0)


def test_rcss_naive_scores_against_a_team_that_stands_still_and_eager_agrees_with_jit() -> None:
    env, params, _, _ = _game(2)
    params = params.replace(episode_length=120)
    naive = resolve_team("rcss_naive", params)
    result = summary(play_match(env, params, naive, StandStill(), jax.random.key(0), 2))
    assert result["goals_for"] >= 1.0 and result["goals_against"] == 0.0
    obs, _ = _team_obs(2, (5.0, 3.0), 1.0, (7.0, 2.0))
    carry = naive.init_carry(2)
    eager = naive.act(None, carry, obs, jax.random.key(0))
    jitted = jax.jit(naive.act)(None, carry, obs, jax.random.key(0))
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)


def test_meeting_points_lie_on_the_balls_course_where_the_player_can_reach_it() -> None:
    team = RcssNaiveTeam()
    ball = jnp.array([[0.0, 0.0], [0.0, 0.0]])
    velocity = jnp.array([[2.0, 0.0], [2.0, 0.0]])
    # One player waits on the course 10 m ahead, one stands 30 m to the side of it.
    position = jnp.array([[10.0, 0.0], [10.0, 30.0]])
    points = np.asarray(team.meeting_points(ball, velocity, position))
    assert points[:, 1] == pytest.approx([0.0, 0.0])
    assert 0.0 < points[0, 0] < 10.0  # meets it on the way
    assert points[1, 0] > points[0, 0]  # the far player meets it later, further down


def test_the_handcrafted_rcss_naive_is_a_12_value_team_told_the_field() -> None:
    team = load_team("rcss_naive")
    assert team.actions == 12
    team.check_size(11, actions=12)
    with pytest.raises(ValueError, match="gives the thesis's 12-value action, not the simulator's"):
        team.check_size(11)
    with pytest.raises(ValueError, match="gives 2 action values; this game takes 12"):
        load_team("naive").check_size(11, actions=12)
    _, params, _, _ = _game(1)
    small = params.replace(field_length=30.0, field_width=21.0, goal_width=14.0)
    told = team_on_field("rcss_naive", small, "run.eval_teams").policy
    assert told.field.half_length == 15.0 and told.field.goal_half_width == 7.0
