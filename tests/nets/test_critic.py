"""The critic: any team size with the same params, cost linear in players, permutation invariance
within a team, the player mask, jit against eager, and the feedforward ablation."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env.state import NUM_CONTEXT_FEATURES, NUM_PLAYER_FEATURES, GlobalState
from elevens.nets.critic import AttentionCritic


def random_state(seed: int, batch_shape: tuple[int, ...], n: int) -> GlobalState:
    """Random features, own team first (is_teammate 1 then 0). NumPy: no jax.random compiles."""
    rng = np.random.default_rng(seed)
    players = rng.standard_normal((*batch_shape, 2 * n, NUM_PLAYER_FEATURES))
    players[..., -1] = np.repeat([1.0, 0.0], n)
    return GlobalState(
        context=jnp.asarray(rng.standard_normal((*batch_shape, NUM_CONTEXT_FEATURES)), jnp.float32),
        players=jnp.asarray(players, jnp.float32),
    )


@functools.cache
def apply_fn(critic: AttentionCritic) -> Callable[..., jax.Array]:
    return jax.jit(critic.apply)


def random_params(critic: AttentionCritic, n: int) -> dict:
    """Generic params for a team size, from NumPy (a compiled Flax init costs seconds)."""
    shapes = jax.eval_shape(critic.init, jax.random.key(0), random_state(0, (1,), n))
    rng = np.random.default_rng(n)
    return jax.tree.map(
        lambda leaf: jnp.asarray(0.2 * rng.standard_normal(leaf.shape), leaf.dtype), shapes
    )


@pytest.fixture(scope="module")
def critic() -> AttentionCritic:
    return AttentionCritic()


@pytest.fixture(scope="module")
def variables(critic: AttentionCritic) -> dict:
    return random_params(critic, 2)


def test_the_real_global_state_of_any_team_size(critic: AttentionCritic, variables: dict) -> None:
    for n in (1, 11):
        env, params = elevens.make(f"{n}v{n}")
        global_state = jax.jit(
            lambda key, env=env, params=params: env.global_state(env.reset(key, params)[0], params)
        )(jax.random.key(n))
        value = apply_fn(critic)(variables, global_state)
        assert value.shape == (2,)  # one value per team
        assert bool(jnp.all(jnp.isfinite(value)))
    batched = apply_fn(critic)(variables, random_state(0, (3, 2), 4))
    assert batched.shape == (3, 2)
    shapes = jax.eval_shape(critic.init, jax.random.key(0), random_state(0, (1,), 11))
    assert jax.tree.map(jnp.shape, shapes) == jax.tree.map(jnp.shape, variables)


def test_parameter_count(critic: AttentionCritic, variables: dict) -> None:
    num_params = sum(leaf.size for leaf in jax.tree.leaves(variables))
    print(f"\nAttentionCritic parameters: {num_params}")
    # With the policy's 81k, about the thesis's 140k (docs/architecture.md).
    assert 3e4 <= num_params <= 1.5e5


def test_cost_is_linear_in_the_number_of_players(critic: AttentionCritic, variables: dict) -> None:
    def flops(n: int) -> float:
        state = random_state(0, (), n)  # one team's view of one game
        compiled = jax.jit(critic.apply).lower(variables, state).compile()
        cost: Any = compiled.cost_analysis()
        cost = cost[0] if isinstance(cost, list) else cost
        return float(cost["flops"])

    costs = {n: flops(n) for n in (2, 5, 11)}
    print(f"\ncritic FLOPs per team state: {costs}")
    # Linear: 12 more players (5 -> 11) cost twice what 6 more (2 -> 5) do. Quadratic would be 3.8.
    growth = (costs[11] - costs[5]) / (costs[5] - costs[2])
    assert growth == pytest.approx(2.0, rel=0.05)


def test_players_are_interchangeable_within_a_team(
    critic: AttentionCritic, variables: dict
) -> None:
    n = 4
    state = random_state(1, (5,), n)
    reference = apply_fn(critic)(variables, state)
    rng = np.random.default_rng(0)
    order = np.concatenate([rng.permutation(n), n + rng.permutation(n)])
    permuted = dataclasses.replace(state, players=state.players[..., order, :])
    np.testing.assert_allclose(apply_fn(critic)(variables, permuted), reference, atol=1e-5)
    # Own players and opponents are not interchangeable.
    swap = np.arange(2 * n)
    swap[[0, n]] = swap[[n, 0]]
    swapped = dataclasses.replace(state, players=state.players[..., swap, :])
    assert float(jnp.max(jnp.abs(apply_fn(critic)(variables, swapped) - reference))) > 1e-5


def test_masked_players_do_not_count(critic: AttentionCritic, variables: dict) -> None:
    n = 5
    state = random_state(2, (4,), n)
    mask = jnp.asarray(np.random.default_rng(3).uniform(size=(4, 2 * n)) < 0.5).at[:, 0].set(True)
    reference = apply_fn(critic)(variables, state, mask)
    noise = 50.0 * jnp.asarray(np.random.default_rng(4).standard_normal(state.players.shape))
    changed = dataclasses.replace(state, players=jnp.where(mask[..., None], state.players, noise))
    np.testing.assert_array_equal(apply_fn(critic)(variables, changed, mask), reference)
    nobody = apply_fn(critic)(variables, state, jnp.zeros_like(mask))
    assert bool(jnp.all(jnp.isfinite(nobody)))


def test_jit_equals_eager(critic: AttentionCritic, variables: dict) -> None:
    state = random_state(5, (2,), 3)
    np.testing.assert_allclose(
        jnp.asarray(critic.apply(variables, state)),
        apply_fn(critic)(variables, state),
        rtol=1e-5,
        atol=1e-6,
    )


def test_feedforward_ablation(variables: dict) -> None:
    critic = AttentionCritic(use_attention=False)
    n = 3
    ablation = random_params(critic, n)
    paths = {jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(ablation)}
    full = {jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(variables)}
    assert paths != full
    assert not any("attention" in p for p in paths)
    print(
        f"\nfeedforward critic parameters (n={n}): {sum(x.size for x in jax.tree.leaves(ablation))}"
    )
    value = apply_fn(critic)(ablation, random_state(6, (4, 2), n))
    assert value.shape == (4, 2)
    assert bool(jnp.all(jnp.isfinite(value)))
