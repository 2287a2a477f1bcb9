"""The rollout: layout and shapes, the learner on both sides, per-game league opponents, exact
log-probabilities, and the LSTM memory reset at episode starts (in the rollout and the unroll
the update uses)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env.state import NUM_ENTITY_FEATURES, NUM_SELF_FEATURES, PLAYER_FEATURES
from elevens.nets.policy import AttentionPolicy
from elevens.play import home_sides
from elevens.train.rollout import Rollout, rollout

N = 2  # players per team
GAMES = 4
STEPS = 12
POLICY = AttentionPolicy(features=16, num_heads=2, lstm_features=8, lstm_layers=2)
VX = PLAYER_FEATURES.index("vx")


@functools.cache
def env_and_params(field_length: float = 100.0):
    width = field_length * 0.7
    return elevens.make(
        f"{N}v{N}", episode_length=STEPS, spawn="formation", field_length=field_length,
        field_width=width, goal_width=min(40.0, width),
    )


@functools.cache
def jitted_rollout(opponent_per_game: bool = False):
    env, _ = env_and_params()
    return jax.jit(
        functools.partial(
            rollout, env, POLICY, num_games=GAMES, num_steps=STEPS,
            opponent_per_game=opponent_per_game,
        )
    )


@functools.cache
def initial_params(seed: int = 0) -> dict:
    env, params = env_and_params()
    _, obs = env.reset(jax.random.key(0), params)
    return jax.jit(POLICY.init)(
        jax.random.key(seed), POLICY.initial_carry((N,)), obs.team(0), jnp.zeros((N,), bool)
    )


def constant_policy(move: float, rot: float = 0.0) -> dict:
    """Params whose action is tanh(move), tanh(rot) whatever the input, with a tiny spread."""
    params = jax.tree.map(lambda x: x, initial_params())
    head = params["params"]["action_head"]
    head["kernel"] = jnp.zeros_like(head["kernel"])
    head["bias"] = jnp.asarray([move, rot, -5.0, -5.0], jnp.float32)
    return params


@functools.cache
def sample_rollout() -> Rollout:
    _, params = env_and_params()
    return jitted_rollout()(params, initial_params(0), initial_params(1), jax.random.key(3))


def test_shapes_follow_units_by_time() -> None:
    data = sample_rollout()
    t = data.transitions
    units = GAMES * N
    assert t.obs.self_features.shape == (units, STEPS, NUM_SELF_FEATURES)
    assert t.obs.entities.shape == (units, STEPS, 2 * N, NUM_ENTITY_FEATURES)
    assert t.obs.entity_mask.shape == (units, STEPS, 2 * N)
    assert t.global_state.context.shape == (units, STEPS, 5)
    assert t.global_state.players.shape == (units, STEPS, 2 * N, len(PLAYER_FEATURES))
    assert t.pre_tanh.shape == (units, STEPS, 2)
    for leaf in (t.log_prob, t.reward, t.done, t.truncated, t.reset):
        assert leaf.shape == (units, STEPS)
    for layer in t.initial_carry:
        assert layer.cell.shape == layer.hidden.shape == (units, POLICY.lstm_features)
    for leaf in (data.learner_side, data.goals_for, data.goals_against):
        assert leaf.shape == (GAMES,)
    assert data.game_global_state.players.shape == (GAMES, STEPS, 2 * N, len(PLAYER_FEATURES))
    assert np.all(np.isfinite(np.asarray(t.log_prob)))


def test_units_are_game_major_and_share_their_game_state() -> None:
    t = sample_rollout().transitions
    per_game = np.asarray(sample_rollout().game_global_state.players)
    players = np.asarray(t.global_state.players).reshape(GAMES, N, STEPS, 2 * N, -1)
    for k in range(N):  # unit g * n + k holds game g's state
        np.testing.assert_array_equal(players[:, k], per_game)
    # Own-team players first in the critic's view: an observer's own x (self feature 1) is the
    # x of row k of its team in the global state (same normalisation, same frame).
    own_x = np.asarray(t.obs.self_features[..., 1]).reshape(GAMES, N, STEPS)
    for k in range(N):
        np.testing.assert_allclose(own_x[:, k], per_game[:, :, k, 0], atol=1e-5)


def test_episode_flags() -> None:
    t = sample_rollout().transitions
    reset, done = np.asarray(t.reset), np.asarray(t.done)
    assert reset[:, 0].all() and not reset[:, 1:].any()
    assert done[:, -1].all() and not done[:, :-1].any()
    np.testing.assert_array_equal(np.asarray(t.truncated), done)
    assert not np.asarray(t.initial_carry[0].hidden).any()


def test_learner_sides_split_the_games() -> None:
    np.testing.assert_array_equal(home_sides(4), [0, 0, 1, 1])
    np.testing.assert_array_equal(home_sides(5), [0, 0, 0, 1, 1])
    np.testing.assert_array_equal(sample_rollout().learner_side, [0, 0, 1, 1])


def test_learner_plays_both_sides() -> None:
    # The learner runs forward at full speed, the opponent stands still. In the learner's own
    # view (its team first), its own players must move towards +x and the opponents not at all,
    # in the games on side 0 and in those on side 1 alike: the actions went to the right side.
    _, params = env_and_params()
    data = jitted_rollout()(
        params, constant_policy(move=6.0), constant_policy(move=0.0),
        jax.random.key(5),
    )
    velocity = np.asarray(data.game_global_state.players[..., VX])  # [G, T, 2n]
    after_first_step = velocity[:, 1:]
    own, others = after_first_step[..., :N], after_first_step[..., N:]
    for game in range(GAMES):
        assert np.all(np.abs(others[game]) < 0.05), game
        # Spawn headings are within +-45 degrees of straight ahead: vx >= cos(45) ~ 0.7 (less
        # where a player is stopped by the end line).
        assert np.mean(own[game] > 0.5) > 0.9, game


def test_league_opponents_are_per_game() -> None:
    _, params = env_and_params()
    runner, still = constant_policy(move=6.0), constant_policy(move=0.0)
    stacked = jax.tree.map(lambda a, b: jnp.stack([a, b, a, b]), runner, still)
    data = jitted_rollout(opponent_per_game=True)(params, still, stacked, jax.random.key(6))
    velocity = np.asarray(data.game_global_state.players[:, 1:, N:, VX])  # opponents, [G, T-1, n]
    moving = np.mean(np.abs(velocity) > 0.5, axis=(1, 2))
    assert moving[0] > 0.9 and moving[2] > 0.9
    assert moving[1] == 0.0 and moving[3] == 0.0


def test_goal_rewards_match_the_score_from_the_learners_view() -> None:
    # A 10 x 7 field with goals as wide as the field: random play scores often (key 8: goals
    # for and against, two in one game). Field sizes are parameters, not structure: the file's
    # compiled rollout plays it.
    _, params = env_and_params(10.0)
    data = jitted_rollout()(params, initial_params(0), initial_params(1), jax.random.key(8))
    goals_for, goals_against = np.asarray(data.goals_for), np.asarray(data.goals_against)
    assert goals_for.sum() > 0 and goals_against.sum() > 0  # the check below is not vacuous
    np.testing.assert_allclose(data.goal_reward, goals_for - goals_against)
    # Every player of a game gets the same goal reward; per unit it is in the reward sum.
    rewards = np.asarray(data.transitions.reward).reshape(GAMES, N, -1)
    shaping = rewards.sum(-1) - (goals_for - goals_against)[:, None]
    assert np.all(np.abs(shaping) < 0.5 * STEPS)


@pytest.mark.parametrize("garbage_carry", [False, True])
def test_recorded_log_probs_are_recomputed_by_the_unroll(garbage_carry: bool) -> None:
    # What the update does: unroll each sequence from its recorded initial carry with the
    # recorded reset flags. Under the rollout's params it must give the recorded log-probs.
    # Because reset[0] is True, a garbage initial carry must change nothing.
    t = sample_rollout().transitions
    carry = t.initial_carry
    if garbage_carry:
        carry = jax.tree.map(lambda x: x + 3.0, carry)
    log_probs = unroll_log_probs(initial_params(0), carry, t.obs, t.reset, t.pre_tanh)
    np.testing.assert_allclose(log_probs, t.log_prob, rtol=1e-4, atol=1e-4)


def test_without_the_reset_flag_a_stale_carry_leaks_in() -> None:
    # The counter-test: the comparison above can fail. Dropping the reset flag at t = 0 lets a
    # non-zero carry change the first steps' log-probs.
    t = sample_rollout().transitions
    carry = jax.tree.map(lambda x: x + 3.0, t.initial_carry)
    log_probs = unroll_log_probs(
        initial_params(0), carry, t.obs, jnp.zeros_like(t.reset), t.pre_tanh
    )
    assert np.max(np.abs(np.asarray(log_probs[:, 0]) - np.asarray(t.log_prob[:, 0]))) > 1e-3


@jax.jit
def unroll_log_probs(params, carry, obs, reset, pre_tanh) -> jax.Array:
    def one(carry, obs, reset):
        return POLICY.apply(params, carry, obs, reset, method=AttentionPolicy.unroll)

    _, output = jax.vmap(one)(carry, obs, reset)
    return output.distribution().log_prob(pre_tanh)


def test_reset_mid_sequence_zeroes_the_memory() -> None:
    # Two episodes glued into one sequence: with a reset flag at the second episode's start, the
    # second half unrolls exactly as if it started fresh.
    t = sample_rollout().transitions
    obs = jax.tree.map(lambda x: jnp.concatenate([x, x], axis=1), t.obs)
    reset = jnp.concatenate([t.reset, t.reset], axis=1)
    pre_tanh = jnp.concatenate([t.pre_tanh, t.pre_tanh], axis=1)
    log_probs = unroll_log_probs(initial_params(0), t.initial_carry, obs, reset, pre_tanh)
    np.testing.assert_allclose(log_probs[:, STEPS:], t.log_prob, rtol=1e-4, atol=1e-4)
    no_reset = reset.at[:, STEPS].set(False)
    leaked = unroll_log_probs(initial_params(0), t.initial_carry, obs, no_reset, pre_tanh)
    assert np.max(np.abs(np.asarray(leaked[:, STEPS]) - np.asarray(t.log_prob[:, 0]))) > 1e-4
