"""The env as a whole: jit/vmap agreement, compiling once, determinism, symmetry, errors."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env import EnvParams, State
from elevens.env.physics import wrap_angle


def random_actions(key, players, batch=()):  # type: ignore[no-untyped-def]
    return jax.random.uniform(key, (*batch, 2, players, 2), minval=-1.0, maxval=1.0)


@functools.partial(jax.jit, static_argnums=(0, 3, 4))
def rollout(env, params, key, steps, batch):  # type: ignore[no-untyped-def]
    """A scanned batch of games with random actions; returns per-step states, rewards, infos."""
    n = params.players_per_team
    reset_key, run_key = jax.random.split(key)
    state, _ = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(reset_key, batch), params)

    def body(state, step_key):
        action_key, env_key = jax.random.split(step_key)
        actions = random_actions(action_key, n, (batch,))
        state, rewards, done, info = jax.vmap(env.transition, in_axes=(0, 0, 0, None))(
            jax.random.split(env_key, batch), state, actions, params
        )
        return state, (state, rewards, info)

    _, history = jax.lax.scan(body, state, jax.random.split(run_key, steps))
    return history


def assert_trees_close(a, b, atol=0.0):  # type: ignore[no-untyped-def]
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), atol=atol, rtol=0)


def test_make_scenarios_and_errors():
    for n in (1, 2, 7, 11):
        env, params = elevens.make(f"{n}v{n}")
        assert env.players_per_team == n == params.players_per_team
    with pytest.raises(ValueError, match="scenario='3v4'"):
        elevens.make("3v4")
    with pytest.raises(ValueError, match="players_per_team=12"):
        elevens.make("12v12")
    with pytest.raises(ValueError, match="scenario='eleven'"):
        elevens.make("eleven")


@pytest.mark.parametrize(
    "overrides,field",
    [
        ({"players_per_team": 0}, "players_per_team"),
        ({"players_per_team": 12}, "players_per_team"),
        ({"field_length": -100.0}, "field_length"),
        ({"field_width": 0.0}, "field_width"),
        ({"goal_width": 80.0}, "goal_width"),
        ({"ball_friction": 1.5}, "ball_friction"),
        ({"episode_length": 0}, "episode_length"),
        ({"spawn": "anywhere"}, "spawn"),
        ({"ball_spawn": "corner"}, "ball_spawn"),
        ({"kick_impulse": float("nan")}, "kick_impulse"),
        ({"possession_radius": 0.0}, "possession_radius"),
        ({"possession_shaping_weight": -0.01}, "possession_shaping_weight"),
        ({"possession_by": "vibes"}, "possession_by"),
    ],
)
def test_impossible_params_name_the_field(overrides, field):
    with pytest.raises(ValueError, match=field):
        EnvParams(**overrides)


def test_replace_validates_too():
    params = EnvParams(players_per_team=2)
    with pytest.raises(ValueError, match="goal_width"):
        dataclasses.replace(params, goal_width=100.0)


def test_params_mismatch_is_an_error():
    env, _ = elevens.make("2v2")
    with pytest.raises(ValueError, match="players_per_team=3"):
        env.reset(jax.random.key(0), EnvParams(players_per_team=3))


def test_jit_equals_eager_over_steps():
    env, params = elevens.make("3v3")
    state, _ = env.reset(jax.random.key(1), params)
    eager_state, jit_state = state, state
    jit_step = jax.jit(env.step)
    for i in range(25):
        key = jax.random.key(100 + i)
        actions = random_actions(jax.random.key(i), 3)
        eager_state, eager_obs, eager_r, _, _ = env.step(key, eager_state, actions, params)
        jit_state, jit_obs, jit_r, _, _ = jit_step(key, jit_state, actions, params)
        assert_trees_close(eager_state, jit_state, atol=1e-5)
        assert_trees_close(eager_obs, jit_obs, atol=1e-5)
        np.testing.assert_allclose(eager_r, jit_r, atol=1e-5)


def test_step_compiles_once_per_shape():
    env, params = elevens.make("2v2")
    traces = []

    def counted(key, state, actions, params):  # type: ignore[no-untyped-def]
        traces.append(1)
        return env.step(key, state, actions, params)

    step = jax.jit(counted)
    state, _ = env.reset(jax.random.key(0), params)
    for i in range(5):
        # Changing numbers in params must not recompile either.
        tweaked = params.replace(kick_impulse=4.0 + i, ball_shaping_weight=0.1 * i)
        state, *_ = step(jax.random.key(i), state, random_actions(jax.random.key(i), 2), tweaked)
    assert len(traces) == 1


def test_vmap_over_64_games_equals_python_loop():
    env, params = elevens.make("2v2")
    keys = jax.random.split(jax.random.key(3), 64)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    actions = random_actions(jax.random.key(4), 2, (64,))
    step_keys = jax.random.split(jax.random.key(5), 64)
    batched = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))(
        step_keys, states, actions, params
    )
    single = jax.jit(env.step)
    # Games are sliced on the host: 64 eager slices of every leaf cost more than the steps.
    host_states, host_batched = jax.device_get((states, batched))
    host_actions = np.asarray(actions)
    for g in range(64):
        state_g = jax.tree.map(lambda x, g=g: x[g], host_states)
        out = single(step_keys[g], state_g, host_actions[g], params)
        assert_trees_close(jax.tree.map(lambda x, g=g: x[g], host_batched), out, atol=1e-6)


def test_same_key_same_game_and_different_key_differs():
    env, params = elevens.make("4v4")
    a = rollout(env, params, jax.random.key(7), 60, 4)
    b = rollout(env, params, jax.random.key(7), 60, 4)
    c = rollout(env, params, jax.random.key(8), 60, 4)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0].positions, c[0].positions)


def test_ten_thousand_random_steps_stay_finite_and_consistent():
    env, params = elevens.make("11v11", ball_spawn="centre", episode_length=400)
    # 25 games x 400 steps = 10,000 steps; a small field with a wide goal makes goals frequent.
    params = params.replace(field_length=60.0, field_width=40.0, goal_width=30.0)
    states, rewards, infos = rollout(env, params, jax.random.key(11), 400, 25)
    for leaf in jax.tree.leaves((states, rewards, infos)):
        if jnp.issubdtype(leaf.dtype, jnp.floating):
            assert np.all(np.isfinite(np.asarray(leaf)))
    positions = np.asarray(states.positions)
    assert np.all(np.abs(positions[..., 0]) <= 30.0) and np.all(np.abs(positions[..., 1]) <= 20.0)
    ball = np.asarray(states.ball_position)
    assert np.all(np.abs(ball[..., 0]) <= 30.0) and np.all(np.abs(ball[..., 1]) <= 20.0)
    assert np.all(np.linalg.norm(np.asarray(states.ball_velocity), axis=-1) <= 5.0 + 1e-5)
    headings = np.asarray(states.headings)
    assert np.all(headings >= -np.pi) and np.all(headings < np.pi)
    # The score and the goal rewards agree, step by step and in total.
    goals = np.asarray(infos.goals)  # [T, G, 2]
    assert goals.sum() > 0, "no goal in 10,000 steps: the test would prove nothing"
    np.testing.assert_array_equal(np.asarray(states.score)[-1], goals.sum(axis=0))
    goal_reward = np.asarray(infos.goal_reward)  # [T, G, 2, n]
    diff = goals[..., 0] - goals[..., 1]
    np.testing.assert_allclose(goal_reward[..., 0, :], np.repeat(diff[..., None], 11, -1))
    np.testing.assert_allclose(goal_reward[..., 1, :], -goal_reward[..., 0, :])
    total = np.asarray(
        infos.goal_reward + infos.ball_shaping + infos.approach_shaping + infos.possession_shaping
    )
    np.testing.assert_allclose(np.asarray(rewards), total, atol=1e-6)
    assert int(np.asarray(states.step)[-1, 0]) == 400


def reflect(state: State, n: int) -> State:
    """Point-reflect the world and swap the teams (team 1 becomes team 0)."""

    def swap(x):  # type: ignore[no-untyped-def]
        return jnp.concatenate([x[n:], x[:n]], axis=0)

    return State(
        positions=swap(-state.positions),
        headings=swap(wrap_angle(state.headings + jnp.pi)),
        velocities=swap(-state.velocities),
        last_actions=swap(state.last_actions),
        start_positions=swap(-state.start_positions),
        ball_position=-state.ball_position,
        ball_velocity=-state.ball_velocity,
        score=state.score[::-1],
        step=state.step,
    )


@pytest.mark.parametrize("players", [1, 3, 11])
def test_side_symmetry(players):
    # No respawn noise and a centred ball, so even respawns after goals are symmetric.
    env, params = elevens.make(
        f"{players}v{players}", spawn_noise=0.0, heading_noise=0.0, ball_spawn="centre"
    )
    params = params.replace(field_length=40.0, field_width=30.0, goal_width=20.0)
    state, _ = jax.jit(env.reset)(jax.random.key(0), params)
    state = state.replace(ball_position=jnp.array([3.0, -2.0]))
    mirrored = reflect(state, players)
    step = jax.jit(env.step)
    goals = 0
    for i in range(40):
        actions = random_actions(jax.random.key(i), players)
        key = jax.random.key(1000 + i)
        state, obs, rewards, _, info = step(key, state, actions, params)
        mirrored, m_obs, m_rewards, _, m_info = step(key, mirrored, actions[::-1], params)
        assert_trees_close(reflect(state, players), mirrored, atol=2e-3)
        np.testing.assert_allclose(rewards[::-1], m_rewards, atol=2e-3)
        np.testing.assert_array_equal(info.goals[::-1], m_info.goals)
        # Each team sees the same thing in both games, from the other side.
        assert_trees_close(obs.team(0), m_obs.team(1), atol=2e-3)
        goals += int(info.goals.sum())
    assert int(state.step) == 40


def test_checked_step_reports_nan_and_range():
    env, params = elevens.make("2v2")
    state, _ = env.reset(jax.random.key(0), params)
    good = jnp.zeros((2, 2, 2))
    env.step_checked(jax.random.key(1), state, good, params)
    with pytest.raises(Exception, match="NaN or Inf"):
        env.step_checked(jax.random.key(1), state, good.at[1, 0, 1].set(jnp.nan), params)
    with pytest.raises(Exception, match="out of range"):
        env.step_checked(jax.random.key(1), state, good.at[0, 1, 0].set(1.5), params)
    with pytest.raises(ValueError, match=r"shape \(2, 3, 2\)"):
        env.step_checked(jax.random.key(1), state, jnp.zeros((2, 3, 2)), params)


def test_wrong_action_shape_is_an_error_in_step():
    env, params = elevens.make("2v2")
    state, _ = env.reset(jax.random.key(0), params)
    with pytest.raises(ValueError, match=r"expected \(2, 2, 2\)"):
        env.step(jax.random.key(1), state, jnp.zeros((4, 2)), params)


@pytest.mark.parametrize("spawn", ["formation", "random"])
def test_reset_spawns_in_own_half(spawn):
    env, params = elevens.make("11v11", spawn=spawn)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(
        jax.random.split(jax.random.key(0), 200), params
    )
    positions = np.asarray(states.positions)
    assert np.all(positions[:, :11, 0] <= 0) and np.all(positions[:, 11:, 0] >= 0)
    ball = np.asarray(states.ball_position)
    assert np.all(np.abs(ball) <= [25.0, 17.5])
    assert ball.std(axis=0).min() > 5.0  # random ball spawn by default
    headings = np.asarray(states.headings)
    if spawn == "formation":
        assert np.all(np.abs(headings[:, :11]) <= np.pi / 4 + 1e-6)
        assert np.all(np.abs(wrap_angle(headings[:, 11:] - np.pi)) <= np.pi / 4 + 1e-5)
    else:
        assert headings.std() > 1.5
