"""The one unroll (elevens.play): sides, actors and keys, shared by training and matches."""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env import Observation
from elevens.eval import play_match
from elevens.play import (
    BlockActor,
    PolicyActor,
    StepView,
    home_sides,
    home_sides_in_blocks,
    per_game_step_keys,
    pick_side,
    place_sides,
    unroll,
)
from elevens.teams import NaiveTeam, RandomTeam, TeamworkTeam


@dataclasses.dataclass(frozen=True)
class WildTeam:
    """Plays NaN for move and 5.0 for rotation: the env must apply 0 and 1."""

    name: str = "wild"

    def init_carry(self, players_per_team: int) -> jax.Array:
        return jnp.zeros(())

    def act(
        self, params: None, carry: jax.Array, obs: Observation, key: jax.Array
    ) -> tuple[jax.Array, jax.Array]:
        n = obs.self_features.shape[0]
        return carry, jnp.stack([jnp.full(n, jnp.nan), jnp.full(n, 5.0)], axis=-1)


def _positions(view: StepView) -> jax.Array:
    return view.state.positions


def _play(env, params, home, away, keys, sides, record=_positions):  # type: ignore[no-untyped-def]
    reset_keys, play_keys = jnp.moveaxis(jax.vmap(jax.random.split)(keys), 1, 0)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(reset_keys, params)
    steps = int(params.episode_length)
    return unroll(
        env, params, home, away, states, jnp.asarray(sides),
        per_game_step_keys(play_keys, steps), record,
    )


def test_sides_are_placed_and_picked_back() -> None:
    side = jnp.asarray(home_sides(5))
    home = jnp.arange(5 * 3 * 2, dtype=jnp.float32).reshape(5, 3, 2)
    away = -home - 1
    both = place_sides(home, away, side)
    assert both.shape == (5, 2, 3, 2)
    np.testing.assert_array_equal(np.asarray(both[3, 1]), np.asarray(home[3]))  # side 1
    np.testing.assert_array_equal(np.asarray(pick_side(both, side)), np.asarray(home))
    np.testing.assert_array_equal(np.asarray(pick_side(both, 1 - side)), np.asarray(away))
    np.testing.assert_array_equal(home_sides_in_blocks((3, 2, 0)), [0, 0, 1, 0, 1])


def test_recorded_actions_are_the_applied_ones() -> None:
    env, params = elevens.make("2v2", episode_length=5)

    def actions(view: StepView) -> jax.Array:
        return view.actions

    keys = jax.random.split(jax.random.key(0), 2)
    _, recorded = _play(
        env, params, PolicyActor(WildTeam()), PolicyActor(NaiveTeam()), keys, [0, 1], actions
    )
    recorded = np.asarray(recorded)  # [T, G, 2 sides, n, 2]
    wild = np.stack([recorded[:, 0, 0], recorded[:, 1, 1]])  # the home side of each game
    np.testing.assert_array_equal(wild[..., 0], 0.0)
    np.testing.assert_array_equal(wild[..., 1], 1.0)


def test_a_raw_key_is_refused() -> None:
    actor = PolicyActor(NaiveTeam())
    env, params = elevens.make("1v1")
    state, _ = env.reset(jax.random.key(0), params)
    obs = jax.tree.map(lambda leaf: leaf[None], env.observe(state, params).team(0))
    with pytest.raises(TypeError, match="typed keys"):
        actor.act(actor.init_carry(1, 1), obs, jnp.zeros((1, 1), bool), jax.random.PRNGKey(0))


# Slow: eager JAX compiles each op on first use (about 12 s a process before the first step);
# the game's own jit / eager agreement stays in the default suite (tests/env/test_soccer.py).
@pytest.mark.slow
def test_jit_and_eager_unroll_agree() -> None:
    # Eager runs op by op, seconds a step: two steps carry one step's state into the next.
    env, params = elevens.make("2v2", episode_length=2)
    keys = jax.random.split(jax.random.key(1), 3)
    play = functools.partial(
        _play, env, params, PolicyActor(RandomTeam()), PolicyActor(TeamworkTeam())
    )
    _, jitted = jax.jit(play)(keys, home_sides(3))
    with jax.disable_jit():
        _, eager = play(keys, home_sides(3))
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), atol=1e-4)


def test_a_game_does_not_depend_on_the_games_beside_it() -> None:
    env, params = elevens.make("2v2", episode_length=30)
    key = jax.random.key(2)
    together = play_match(
        env, params, RandomTeam(), NaiveTeam(), key, 6, record=True, chunk_size=6
    )
    alone = play_match(env, params, RandomTeam(), NaiveTeam(), key, 6, record=True, chunk_size=1)
    assert together.record is not None and alone.record is not None
    np.testing.assert_array_equal(
        np.asarray(together.record.positions), np.asarray(alone.record.positions)
    )


def test_each_block_plays_as_if_alone() -> None:
    """A BlockActor's games equal each block's team playing its games on its own, with the
    block's key (block 0: the step key; block b: fold_in(key, b))."""
    env, params = elevens.make("2v2", episode_length=20)
    keys = jax.random.split(jax.random.key(3), 5)
    sides = home_sides_in_blocks((2, 3))
    home = PolicyActor(TeamworkTeam())
    mixed = BlockActor(actors=(PolicyActor(NaiveTeam()), PolicyActor(RandomTeam())), games=(2, 3))
    reset_keys, play_keys = jnp.moveaxis(jax.vmap(jax.random.split)(keys), 1, 0)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(reset_keys, params)
    # One key a step for the away team as a whole, as a training rollout draws it.
    step_keys = per_game_step_keys(play_keys, 20)
    step_keys = step_keys.replace(away=step_keys.away[:, 0])
    side = jnp.asarray(sides)
    _, together = unroll(env, params, home, mixed, states, side, step_keys, _positions)

    def block(actor, games, away_keys):  # type: ignore[no-untyped-def]
        part = jax.tree.map(lambda leaf: leaf[games], states)
        keys = step_keys.replace(
            home=step_keys.home[:, games], away=away_keys, env=step_keys.env[:, games]
        )
        return unroll(env, params, home, actor, part, jnp.asarray(sides[games]), keys, _positions)

    _, first = block(mixed.actors[0], slice(0, 2), step_keys.away)
    second_keys = jax.vmap(lambda key: jax.random.fold_in(key, 1))(step_keys.away)
    _, second = block(mixed.actors[1], slice(2, 5), second_keys)
    np.testing.assert_array_equal(
        np.asarray(together), np.concatenate([np.asarray(first), np.asarray(second)], axis=1)
    )
