"""The possession term of the reward (elevens.env.reward.ball_holder)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env.reward import ball_holder, next_last_touch, reward_terms


def _positions(team0, team1):
    return jnp.asarray(np.array(team0 + team1, np.float32))


@pytest.mark.parametrize(
    "team0,team1,ball,expected",
    [
        # Team 0's nearest is 1 m away, team 1's 5 m: team 0 has it.
        ([(1.0, 0.0), (-20.0, 0.0)], [(5.0, 0.0), (30.0, 0.0)], (0.0, 0.0), (1.0, -1.0)),
        # The same mirrored between the teams.
        ([(5.0, 0.0), (30.0, 0.0)], [(0.0, 1.0), (-20.0, 0.0)], (0.0, 0.0), (-1.0, 1.0)),
        # A free ball: both nearest players beyond the radius (2 m).
        ([(3.0, 0.0), (-20.0, 0.0)], [(0.0, 4.0), (30.0, 0.0)], (0.0, 0.0), (0.0, 0.0)),
        # Both within the radius: the nearer team has it, however close the other is.
        ([(0.5, 0.0), (-20.0, 0.0)], [(0.0, 0.6), (30.0, 0.0)], (0.0, 0.0), (1.0, -1.0)),
        # Exactly as near: neither has it.
        ([(1.0, 0.0), (-20.0, 0.0)], [(-1.0, 0.0), (30.0, 0.0)], (0.0, 0.0), (0.0, 0.0)),
    ],
)
def test_ball_holder_is_the_nearer_team_within_the_radius(team0, team1, ball, expected):
    _, params = elevens.make("2v2", possession_by="near")
    holder = ball_holder(jnp.asarray(ball), _positions(team0, team1), params)
    np.testing.assert_array_equal(np.asarray(holder), np.asarray(expected, np.float32))


def test_possession_term_is_zero_sum_weighted_and_off_by_default():
    _, params = elevens.make("2v2", possession_by="near")
    positions = _positions([(1.0, 0.0), (-20.0, 0.0)], [(5.0, 0.0), (30.0, 0.0)])
    zeros2, zeros4 = jnp.zeros(2), jnp.zeros((4, 2))
    ball = jnp.asarray([0.0, 0.0])
    args = (jnp.zeros(2, jnp.int32), ball, zeros2, zeros4, ball, positions)
    off = reward_terms(*args, params)
    np.testing.assert_array_equal(np.asarray(off.possession), 0.0)
    np.testing.assert_array_equal(np.asarray(off.holder), [1.0, -1.0])
    on = reward_terms(*args, params.replace(possession_shaping_weight=0.01))
    np.testing.assert_allclose(np.asarray(on.possession), [[0.01, 0.01], [-0.01, -0.01]])
    np.testing.assert_allclose(np.asarray(on.total - off.total), np.asarray(on.possession))


def test_possession_in_played_games_matches_ball_holder_under_jit_and_vmap():
    env, params = elevens.make("3v3", episode_length=50, possession_by="near")
    params = params.replace(possession_shaping_weight=0.02, possession_radius=5.0)
    games = 16
    keys = jax.random.split(jax.random.key(3), games)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    one_game = jax.jit(env.step)  # (eager against jit: tests/env/test_soccer.py)
    held = []
    for t in range(50):
        actions = jax.random.uniform(jax.random.key(t), (games, 2, 3, 2), minval=-1, maxval=1)
        step_keys = jax.random.split(jax.random.key(100 + t), games)
        if t < 3:  # one game alone agrees with the batch
            alone = one_game(step_keys[0], jax.tree.map(lambda x: x[0], states), actions[0], params)
        states, _, rewards, _, info = step(step_keys, states, actions, params)
        if t < 3:
            np.testing.assert_allclose(np.asarray(alone[2]), np.asarray(rewards[0]), atol=1e-6)
        holder = np.asarray(info.holder)  # [G, 2]
        np.testing.assert_array_equal(holder[:, 0], -holder[:, 1])
        expected = np.repeat(0.02 * holder[:, :, None], 3, axis=2)
        np.testing.assert_allclose(np.asarray(info.possession_shaping), expected, rtol=1e-6)
        positions, ball = np.asarray(states.positions), np.asarray(states.ball_position)
        for g in range(games):
            if not np.asarray(info.goals)[g].any():  # a goal respawns: the term saw the old state
                direct = ball_holder(jnp.asarray(ball[g]), jnp.asarray(positions[g]), params)
                np.testing.assert_array_equal(np.asarray(direct), holder[g])
        held.extend(holder[:, 0].tolist())
    assert {-1.0, 0.0, 1.0} <= set(held), "not every case came up: the test proves nothing"


def test_last_touch_follows_touches_and_contests():
    none = jnp.asarray(-1, jnp.int32)
    touches = np.zeros(6, bool)
    assert int(next_last_touch(none, jnp.asarray(touches))) == -1
    touches[4] = True  # a team-1 player
    assert int(next_last_touch(none, jnp.asarray(touches))) == 1
    assert int(next_last_touch(jnp.asarray(0, jnp.int32), jnp.asarray(touches))) == 1
    touches[0] = True  # and a team-0 player in the same step: contested
    assert int(next_last_touch(jnp.asarray(1, jnp.int32), jnp.asarray(touches))) == -1
    assert int(next_last_touch(jnp.asarray(0, jnp.int32), jnp.zeros(6, bool))) == 0  # kept


def test_possession_by_touch_is_the_last_touching_team_in_played_games():
    """By touch: the holder is the team whose player last kicked or pushed the
    ball; nobody at the start and after a goal; a hand-built State without last_touch gets 0."""
    env, params = elevens.make(
        "2v2", episode_length=200, ball_spawn="centre", possession_by="touch"
    )
    params = params.replace(
        field_length=30.0, field_width=20.0, goal_width=14.0, possession_shaping_weight=0.01
    )
    games = 8
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(
        jax.random.split(jax.random.key(5), games), params
    )
    assert (np.asarray(states.last_touch) == -1).all()
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    last = np.full(games, -1)
    seen = set()
    for t in range(200):
        actions = jax.random.uniform(jax.random.key(t), (games, 2, 2, 2), minval=-1, maxval=1)
        states, _, rewards, _, info = step(
            jax.random.split(jax.random.key(1000 + t), games), states, actions, params
        )
        touches = np.asarray(info.kicks | info.pushes)  # [G, 4]
        team0, team1 = touches[:, :2].any(-1), touches[:, 2:].any(-1)
        last = np.where(team0 & team1, -1, np.where(team0, 0, np.where(team1, 1, last)))
        expected = np.stack([last == 0, last == 1], -1).astype(np.float32)
        expected = expected - expected[:, ::-1]
        np.testing.assert_array_equal(np.asarray(info.holder), expected)  # the step's holder
        scored = np.asarray(info.goals).any(-1)
        last = np.where(scored, -1, last)
        np.testing.assert_array_equal(np.asarray(states.last_touch), last)
        seen.update(expected[:, 0].tolist())
    assert seen == {-1.0, 0.0, 1.0}, "not every holder came up: the test proves nothing"
    hand_built = dataclasses.replace(jax.tree.map(lambda x: x[0], states), last_touch=None)
    after, _, _, _, info = jax.jit(env.step)(jax.random.key(0), hand_built, actions[0], params)
    assert after.last_touch is None
    np.testing.assert_array_equal(np.asarray(info.holder), [0.0, 0.0])
