"""rcss_passer: the scripted team that keeps the ball, in the simulator with rcssserver's bodies."""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.env.rcss import DASH, KICK, TURN, RcssSoccer, decode_thesis12, kick_acceleration
from elevens.eval.match import play_match
from elevens.runs.teams import load_team
from elevens.teams.rcss_passer import RcssPasserTeam
from elevens.teams.registry import resolve_team
from tests.teams.test_rcss_naive import StandStill

N = 3  # keeper (player 0) and two outfield players a side


@functools.cache
def _game():
    env = RcssSoccer(N)
    params = env.default_params()
    return env, params, jax.jit(env.reset), jax.jit(env.observe)


def _team_obs(players, headings, ball):
    """Team 0's observation with all 2N players at ``players`` facing ``headings`` (world
    frame: team 0 attacks +x) and the ball at rest at ``ball``. Returns (obs, state, params)."""
    env, params, reset, observe = _game()
    state, _ = reset(jax.random.key(0), params)
    state = dataclasses.replace(
        state,
        positions=jnp.asarray(players, jnp.float32),
        headings=jnp.asarray(headings, jnp.float32),
        ball_position=jnp.asarray(ball, jnp.float32),
        ball_velocity=jnp.zeros(2),
    )
    obs = observe(state, params)
    return jax.tree.map(lambda leaf: leaf[0], obs), state, params


def _commands(team, obs):
    _, actions = jax.jit(team.act)(None, team.init_carry(N), obs, jax.random.key(0))
    assert actions.shape == (N, 12)
    return decode_thesis12(actions)


def _kicked_velocity(commands, state, player):
    """The ball's velocity after ``player``'s kick (world frame), from the simulator's model."""
    return np.asarray(
        kick_acceleration(
            commands.kick_power[player],
            commands.kick_direction[player],
            state.headings[player],
            state.positions[player],
            state.ball_position,
        )
    )


FAR = [(-52.0, 30.0), (-52.0, -30.0), (-50.0, 32.0)]  # opponents out of the way, out of view


def test_a_player_near_the_goal_shoots_at_the_far_post_at_full_power() -> None:
    players = [(-50.0, 0.0), (40.0, 5.0), (0.0, -20.0)] + FAR
    obs, state, _ = _team_obs(players, [0.0] * 6, (40.8, 5.0))
    commands = _commands(RcssPasserTeam(), obs)
    assert int(commands.kind[1]) == KICK
    assert float(commands.kick_power[1]) == pytest.approx(100.0)
    velocity = _kicked_velocity(commands, state, 1)
    # The far post from y = +5 is the one at y < 0, 1.5 m inside it.
    post = np.array([52.5, -(7.01 - 1.5)])
    direction = post - np.array([40.8, 5.0])
    cosine = velocity @ direction / np.linalg.norm(velocity) / np.linalg.norm(direction)
    assert cosine == pytest.approx(1.0, abs=1e-3)


def test_it_passes_to_an_open_teammate_upfield_so_the_ball_arrives_rolling() -> None:
    # Player 1 has the ball at the centre; player 2 stands 15 m ahead and 5 m to the side;
    # one opponent 4 m off its right side presses it.
    players = [(-50.0, 0.0), (0.0, 0.0), (15.0, 5.0), (1.5, -4.5), (-52.0, 30.0), (-50.0, 32.0)]
    obs, state, params = _team_obs(players, [0.0] * 6, (0.8, 0.0))
    team = RcssPasserTeam()
    commands = _commands(team, obs)
    assert int(commands.kind[1]) == KICK
    velocity = _kicked_velocity(commands, state, 1)
    target = np.array([15.0 + team.pass_lead, 5.0])
    offset = target - np.array([0.8, 0.0])
    cosine = velocity @ offset / np.linalg.norm(velocity) / np.linalg.norm(offset)
    assert cosine == pytest.approx(1.0, abs=1e-3)
    # Rolled on with the ball's decay, it stops just past the target: it arrives rolling.
    decay = float(params.ball_friction)
    rolls = np.linalg.norm(velocity) / (1.0 - decay)
    assert np.linalg.norm(offset) < rolls < np.linalg.norm(offset) + 15.0


def test_an_opponent_in_the_lane_stops_the_pass() -> None:
    # As above, with an opponent halfway along the pass: no open
    # pass, not deep in its own half, pressed: the player clears long instead.
    players = [(-50.0, 0.0), (0.0, 0.0), (15.0, 5.0), (1.5, -4.5), (8.0, 2.7), (-50.0, 32.0)]
    obs, state, _ = _team_obs(players, [0.0] * 6, (0.8, 0.0))
    commands = _commands(RcssPasserTeam(), obs)
    assert int(commands.kind[1]) == KICK
    velocity = _kicked_velocity(commands, state, 1)
    to_mate = np.array([16.5, 5.0]) - np.array([0.8, 0.0])
    cosine = velocity @ to_mate / np.linalg.norm(velocity) / np.linalg.norm(to_mate)
    assert cosine < 0.99
    assert float(commands.kick_power[1]) == pytest.approx(100.0)


def test_unpressed_without_a_pass_it_dribbles_a_short_kick_towards_the_goal() -> None:
    players = [(-50.0, 0.0), (0.0, 0.0), (-30.0, 20.0)] + FAR
    obs, state, params = _team_obs(players, [0.0] * 6, (0.8, 0.0))
    team = RcssPasserTeam()
    commands = _commands(team, obs)
    assert int(commands.kind[1]) == KICK
    velocity = _kicked_velocity(commands, state, 1)
    assert velocity[1] == pytest.approx(0.0, abs=1e-3) and velocity[0] > 0.0
    rolls = np.linalg.norm(velocity) / (1.0 - float(params.ball_friction))
    assert rolls == pytest.approx(team.dribble_distance, rel=0.05)


def test_the_nearest_players_chase_the_keeper_stays_and_the_rest_go_to_their_spots() -> None:
    # Ball at (20, 0): player 1 is near it, player 2 far behind it; the keeper in its goal.
    players = [(-50.0, 0.0), (15.0, 0.0), (-40.0, 10.0)] + FAR
    obs, _, _ = _team_obs(players, [0.0] * 6, (20.0, 0.0))
    team = dataclasses.replace(RcssPasserTeam(), chasers=1)
    commands = _commands(team, obs)
    assert int(commands.kind[1]) == DASH and float(commands.dash_power[1]) == pytest.approx(100.0)
    # Player 2 (slot at x = -11 of 50, y = 22 of 35) runs to its spot, moved towards the ball.
    spot = np.asarray(
        team.home(team.slots(N), jnp.full((N, 2), jnp.array([20.0, 0.0])), jnp.ones(N, bool))
    )[2]
    assert spot[0] > -11.0 * 52.5 / 50.0
    bearing = math.degrees(math.atan2(spot[1] - 10.0, spot[0] + 40.0))
    if int(commands.kind[2]) == TURN:
        assert float(commands.turn_moment[2]) == pytest.approx(-bearing, abs=1.0)
    else:
        assert int(commands.kind[2]) == DASH
        assert float(commands.dash_direction[2]) == pytest.approx(-bearing, abs=1.0)
    # The keeper, far from a ball 70 m away, holds its spot on the goal line.
    keeper_spot = np.asarray(
        team.home(team.slots(N), jnp.full((N, 2), jnp.array([20.0, 0.0])), jnp.ones(N, bool))
    )[0]
    assert keeper_spot[0] == pytest.approx(-52.5 + 2.0)
    assert int(commands.kind[0]) in (TURN, DASH)
    if int(commands.kind[0]) == DASH:
        assert float(commands.dash_power[0]) < 100.0


def test_eager_jit_and_vmap_agree_and_it_scores_in_whole_games() -> None:
    players = [(-50.0, 0.0), (0.0, 0.0), (15.0, 5.0), (1.5, -4.5), (8.0, 2.7), (-50.0, 32.0)]
    obs, _, _ = _team_obs(players, [0.0, 0.3, -0.2, 3.0, 2.0, 0.0], (0.8, 0.0))
    team = RcssPasserTeam()
    carry = team.init_carry(N)
    eager = team.act(None, carry, obs, jax.random.key(0))
    jitted = jax.jit(team.act)(None, carry, obs, jax.random.key(0))
    batched = jax.vmap(team.act, in_axes=(None, None, 0, None))(
        None, carry, jax.tree.map(lambda leaf: jnp.stack([leaf, leaf]), obs), jax.random.key(0)
    )
    for a, b, c in zip(
        jax.tree.leaves(eager), jax.tree.leaves(jitted), jax.tree.leaves(batched), strict=True
    ):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(a, c[1], rtol=1e-5, atol=1e-5)
    # Whole games against a team that stands still: it reaches the ball, moves it up and scores.
    env, params, _, _ = _game()
    params = params.replace(episode_length=150)
    passer = resolve_team("rcss_passer", params)
    result = play_match(env, params, passer, StandStill(), jax.random.key(0), 2)
    assert int(np.sum(result.goals_for)) >= 1 and int(np.sum(result.goals_against)) == 0


def test_the_handcrafted_rcss_passer_is_a_12_value_team_told_the_field() -> None:
    team = load_team("rcss_passer")
    assert team.actions == 12
    team.check_size(11, actions=12)
    env = RcssSoccer(2)
    params = env.default_params(field_length=100.0, field_width=70.0)
    assert resolve_team("rcss_passer", params).field.half_length == 50.0
