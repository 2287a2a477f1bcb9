"""The attention block and the policy network: shapes for any team size, masking, permutation
invariance, LSTM resets, unroll against single steps, cost, ablation switches, and NetworkTeam
playing a real game."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env.state import NUM_ENTITY_FEATURES, NUM_SELF_FEATURES, Observation
from elevens.nets.attention import MaskedMultiHeadAttention, attention_pool, masked_softmax
from elevens.nets.distributions import LOG_STD_MAX, LOG_STD_MIN
from elevens.nets.policy import AttentionPolicy, PolicyCarry
from elevens.teams.base import TeamPolicy
from elevens.teams.network import NetworkTeam


def random_obs(seed: int, batch_shape: tuple[int, ...], n: int) -> Observation:
    """Random features with about 60% of the entity slots visible. Leading axes batch_shape.

    NumPy, not jax.random: every new shape would compile a jax.random kernel (seconds of tests).
    """
    rng = np.random.default_rng(seed)
    return Observation(
        self_features=jnp.asarray(
            rng.standard_normal((*batch_shape, NUM_SELF_FEATURES)), jnp.float32
        ),
        entities=jnp.asarray(
            rng.standard_normal((*batch_shape, 2 * n, NUM_ENTITY_FEATURES)), jnp.float32
        ),
        entity_mask=jnp.asarray(rng.uniform(size=(*batch_shape, 2 * n)) < 0.6),
    )


def normal(seed: int, shape: tuple[int, ...]) -> jax.Array:
    return jnp.asarray(np.random.default_rng(seed).standard_normal(shape), jnp.float32)


def no_reset(batch_shape: tuple[int, ...]) -> jax.Array:
    return jnp.zeros(batch_shape, bool)


class Compiled(NamedTuple):
    init: Callable
    step: Callable
    unroll: Callable


@functools.cache
def jitted(policy: AttentionPolicy) -> Compiled:
    """A policy's init, step and unroll, compiled (eager Flax runs op by op: much slower)."""
    return Compiled(
        init=jax.jit(policy.init),
        step=jax.jit(policy.apply),
        unroll=jax.jit(functools.partial(policy.apply, method=policy.unroll)),
    )


def init_policy(policy: AttentionPolicy, n: int = 2, seed: int = 0) -> dict:
    obs = random_obs(seed, (n,), n)
    return jitted(policy).init(
        jax.random.key(seed + 1), policy.initial_carry((n,)), obs, no_reset((n,))
    )


def param_shapes(policy: AttentionPolicy, n: int) -> dict:
    """The shapes of the params built for a team of n, without running (or compiling) init."""
    obs = random_obs(0, (n,), n)
    return jax.eval_shape(
        policy.init, jax.random.key(1), policy.initial_carry((n,)), obs, no_reset((n,))
    )


def random_params(policy: AttentionPolicy, n: int) -> dict:
    """Generic params from NumPy: a compiled Flax init costs seconds of test time per network."""
    return random_params_like(param_shapes(policy, n), seed=n)


def count(tree: object) -> int:
    return sum(leaf.size for leaf in jax.tree.leaves(tree))


def flops(fn: Callable, *args: object) -> float:
    cost: Any = jax.jit(fn).lower(*args).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    return float(cost["flops"])


@pytest.fixture(scope="module")
def policy() -> AttentionPolicy:
    return AttentionPolicy()


@pytest.fixture(scope="module")
def variables(policy: AttentionPolicy) -> dict:
    return init_policy(policy)


# ------------------------------------------------------------------------- attention block


def _naive_attention(params: dict, query: np.ndarray, values: np.ndarray, mask: np.ndarray):
    """Textbook multi-head attention over the visible rows only: keys and values projected per
    entity, softmax per head, heads concatenated and projected. query [W], values [E, W]."""
    p = {k: np.asarray(v, np.float64) for k, v in params.items()}
    visible = values[mask].astype(np.float64)
    heads = []
    for h in range(p["query_kernel"].shape[1]):
        q = query @ p["query_kernel"][:, h] + p["query_bias"][h]
        keys = visible @ p["key_kernel"][:, h]
        vals = visible @ p["value_kernel"][:, h] + p["value_bias"][h]
        scores = keys @ q / math.sqrt(q.size)
        weights = np.exp(scores - scores.max())
        heads.append((weights / weights.sum()) @ vals)
    out_kernel = p["out_kernel"].reshape(-1, p["out_kernel"].shape[-1])
    return np.concatenate(heads) @ out_kernel + p["out_bias"]


ATTENTION = MaskedMultiHeadAttention(num_heads=4)


@pytest.fixture(scope="module")
def attention_variables() -> dict:
    return random_params_like(
        jax.eval_shape(
            ATTENTION.init,
            jax.random.key(0),
            jnp.zeros((1, 64)),
            jnp.zeros((1, 2, 64)),
            jnp.ones((1, 2), bool),
        )
    )


def random_params_like(shapes: dict, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    return jax.tree.map(
        lambda leaf: jnp.asarray(0.2 * rng.standard_normal(leaf.shape), leaf.dtype), shapes
    )


def test_attention_equals_textbook_multi_head_attention(attention_variables: dict) -> None:
    """The reassociated products (projections per observer, not per entity) change nothing."""
    query = normal(0, (5, 64))
    values = normal(1, (5, 9, 64))
    mask = np.random.default_rng(2).uniform(size=(5, 9)) < 0.5
    mask[:, 0] = True
    variables = attention_variables
    out = jax.jit(ATTENTION.apply)(variables, query, values, mask)
    for row in range(5):
        expected = _naive_attention(
            variables["params"],
            np.asarray(query[row]),
            np.asarray(values[row]),
            np.asarray(mask[row]),
        )
        np.testing.assert_allclose(out[row], expected, rtol=1e-4, atol=1e-4)


def test_rows_without_visible_entities_give_finite_zeros(attention_variables: dict) -> None:
    attention = ATTENTION
    query = normal(1, (3, 64))
    values = normal(2, (3, 6, 64))
    mask = jnp.array([[False] * 6, [True] + [False] * 5, [False] * 6])
    variables = attention_variables
    apply = jax.jit(attention.apply)
    out = apply(variables, query, values, mask)
    np.testing.assert_array_equal(out[0], 0.0)
    np.testing.assert_array_equal(out[2], 0.0)
    assert bool(jnp.any(out[1] != 0.0))

    def loss(variables: dict, values: jax.Array) -> jax.Array:
        return jnp.sum(jnp.asarray(attention.apply(variables, query, values, mask)) ** 2)

    grads = jax.jit(jax.grad(loss, argnums=(0, 1)))(variables, values)
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in jax.tree.leaves(grads))
    # No entity slots at all (a 1 v 1 player has no teammate) is the same as none visible.
    empty = apply(variables, query, values[:, :0], mask[:, :0])
    np.testing.assert_array_equal(empty, 0.0)


def _attention_pool_by_autodiff(values: jax.Array, probes: jax.Array, mask: jax.Array):
    """attention_pool's function in its plain einsum form, differentiated by JAX."""
    scores = jnp.einsum("mew,mhw->meh", values, probes)
    weights, _ = masked_softmax(scores, mask[..., None], axis=-2)
    return jnp.einsum("meh,mew->mhw", weights, values)


@pytest.mark.parametrize("num_entities", [0, 1, 7])
def test_attention_pool_gradient_equals_autodiff(num_entities: int) -> None:
    """The hand-written backward pass of the attention core against JAX's autodiff of the plain
    form, with rows that see everything, some entities, or none."""
    values = normal(3, (6, num_entities, 16))
    probes = normal(4, (6, 4, 16))
    mask = np.random.default_rng(5).uniform(size=(6, num_entities)) < 0.5
    mask[0] = True
    mask[1] = False
    cotangent = normal(6, (6, 4, 16))

    def loss(core: Callable[..., jax.Array]) -> Callable[..., jax.Array]:
        return lambda v, p: jnp.sum(core(v, p, mask) * cotangent)

    pooled = jax.jit(attention_pool)(values, probes, mask)
    np.testing.assert_allclose(
        pooled, _attention_pool_by_autodiff(values, probes, mask), rtol=1e-5, atol=1e-5
    )
    np.testing.assert_array_equal(pooled[1], 0.0)
    grads = jax.jit(jax.grad(loss(attention_pool), argnums=(0, 1)))(values, probes)
    expected = jax.grad(loss(_attention_pool_by_autodiff), argnums=(0, 1))(values, probes)
    for got, want in zip(grads, expected, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)
    if num_entities:
        # Entities out of view get no gradient; a row that sees nothing passes none to its probe.
        np.testing.assert_array_equal(grads[0][~mask], 0.0)
        assert bool(jnp.any(grads[0][mask] != 0.0))
        np.testing.assert_array_equal(grads[1][1], 0.0)


# -------------------------------------------------------------------------------- policy


def test_the_same_params_serve_every_team_size(policy: AttentionPolicy, variables: dict) -> None:
    for n in (1, 2, 11):
        obs = random_obs(n, (3, n), n)
        carry, output = jitted(policy).step(
            variables, policy.initial_carry((3, n)), obs, no_reset((3, n))
        )
        assert output.mean.shape == output.log_std.shape == (3, n, 2)
        assert jax.tree.map(jnp.shape, carry) == jax.tree.map(
            jnp.shape, policy.initial_carry((3, n))
        )
        assert bool(jnp.all(jnp.isfinite(output.mean)))
        assert bool(jnp.all((output.log_std >= LOG_STD_MIN) & (output.log_std <= LOG_STD_MAX)))
    # Params built from an 11 v 11 observation have the same shapes as those from a 2 v 2 one.
    assert jax.tree.map(jnp.shape, param_shapes(policy, 11)) == jax.tree.map(jnp.shape, variables)


def test_parameter_count_is_near_the_thesis_scale(variables: dict) -> None:
    num_params = count(variables)
    print(f"\nAttentionPolicy parameters: {num_params}")
    # The thesis's policy plus critic hold about 140k parameters (docs/architecture.md).
    assert 5e4 <= num_params <= 2e5


def test_forward_cost_per_player_is_near_the_thesis_and_linear_in_slots(
    policy: AttentionPolicy, variables: dict
) -> None:
    def cost(n: int) -> float:
        obs = random_obs(0, (1,), n)
        carry = policy.initial_carry((1,))
        return flops(lambda v, c, o: policy.apply(v, c, o, no_reset((1,))), variables, carry, obs)

    per_player = {n: cost(n) for n in (2, 5, 11)}
    print(f"\npolicy FLOPs per player forward: {per_player}")
    # docs/architecture.md: 0.73 MFLOP per player forward in 11 v 11.
    assert 0.4e6 < per_player[11] < 1.0e6
    growth = (per_player[11] - per_player[5]) / (per_player[5] - per_player[2])
    assert growth == pytest.approx(2.0, rel=0.05)  # 12 more slots against 6 more


def test_invisible_and_ball_slots_do_not_change_the_output(
    policy: AttentionPolicy, variables: dict
) -> None:
    n = 5
    obs = random_obs(4, (8, n), n)
    carry = policy.initial_carry((8, n))
    _, reference = jitted(policy).step(variables, carry, obs, no_reset((8, n)))
    noise = 100.0 * normal(5, obs.entities.shape)
    ignored = ~obs.entity_mask
    ignored = ignored.at[..., -1].set(True)  # the ball slot: the ball is in the self features
    changed = dataclasses.replace(obs, entities=jnp.where(ignored[..., None], noise, obs.entities))
    _, output = jitted(policy).step(variables, carry, changed, no_reset((8, n)))
    np.testing.assert_array_equal(output.mean, reference.mean)
    np.testing.assert_array_equal(output.log_std, reference.log_std)
    # ... while a visible entity does change it (the test can fail).
    visible_changed = dataclasses.replace(
        obs, entities=jnp.where(obs.entity_mask[..., None], noise, obs.entities)
    )
    _, output = jitted(policy).step(variables, carry, visible_changed, no_reset((8, n)))
    assert float(jnp.max(jnp.abs(output.mean - reference.mean))) > 1e-4


def test_a_player_that_sees_nobody_gets_finite_actions(
    policy: AttentionPolicy, variables: dict
) -> None:
    obs = random_obs(6, (3,), 3)
    obs = dataclasses.replace(obs, entity_mask=jnp.zeros_like(obs.entity_mask))
    _, output = jitted(policy).step(variables, policy.initial_carry((3,)), obs, no_reset((3,)))
    assert bool(jnp.all(jnp.isfinite(output.mean)) & jnp.all(jnp.isfinite(output.log_std)))


def test_permuting_visible_slots_within_a_set_leaves_the_output_unchanged(
    policy: AttentionPolicy, variables: dict
) -> None:
    n = 6
    obs = random_obs(7, (4, n), n)
    carry = policy.initial_carry((4, n))
    _, reference = jitted(policy).step(variables, carry, obs, no_reset((4, n)))
    teammates = np.arange(n - 1)
    opponents = np.arange(n - 1, 2 * n - 1)
    rng = np.random.default_rng(0)
    order = np.concatenate([rng.permutation(teammates), rng.permutation(opponents), [2 * n - 1]])
    permuted = Observation(
        self_features=obs.self_features,
        entities=obs.entities[..., order, :],
        entity_mask=obs.entity_mask[..., order],
    )
    _, output = jitted(policy).step(variables, carry, permuted, no_reset((4, n)))
    np.testing.assert_allclose(output.mean, reference.mean, atol=1e-5)
    np.testing.assert_allclose(output.log_std, reference.log_std, atol=1e-5)
    # Swapping a teammate with an opponent is not a symmetry: they have their own encoders.
    swap = np.arange(2 * n)
    swap[[0, n - 1]] = swap[[n - 1, 0]]
    swapped = dataclasses.replace(
        obs, entities=obs.entities[..., swap, :], entity_mask=jnp.ones_like(obs.entity_mask)
    )
    all_visible = dataclasses.replace(obs, entity_mask=jnp.ones_like(obs.entity_mask))
    _, a = jitted(policy).step(variables, carry, all_visible, no_reset((4, n)))
    _, b = jitted(policy).step(variables, carry, swapped, no_reset((4, n)))
    assert float(jnp.max(jnp.abs(a.mean - b.mean))) > 1e-5


def _steps(policy: AttentionPolicy, variables: dict, carry: PolicyCarry, obs_seq: Observation):
    for t in range(obs_seq.self_features.shape[0]):
        obs = jax.tree.map(lambda x, t=t: x[t], obs_seq)
        carry, _ = jitted(policy).step(
            variables, carry, obs, no_reset(obs.self_features.shape[:-1])
        )
    return carry


def test_reset_zeroes_the_carry_before_use(policy: AttentionPolicy, variables: dict) -> None:
    n = 3
    history = random_obs(8, (4, n), n)  # 4 steps of one team
    carry = _steps(policy, variables, policy.initial_carry((n,)), history)
    assert all(bool(jnp.any(leaf != 0)) for leaf in jax.tree.leaves(carry))
    obs = random_obs(9, (n,), n)
    reset = jnp.array([True, False, True])
    new_carry, output = jitted(policy).step(variables, carry, obs, reset)
    fresh_carry, fresh = jitted(policy).step(
        variables, policy.initial_carry((n,)), obs, no_reset((n,))
    )
    _, kept = jitted(policy).step(variables, carry, obs, no_reset((n,)))
    for row, was_reset in enumerate(np.asarray(reset)):
        expected = fresh if was_reset else kept
        np.testing.assert_allclose(output.mean[row], expected.mean[row], atol=1e-6)
        np.testing.assert_allclose(output.log_std[row], expected.log_std[row], atol=1e-6)
    for new, fresh_leaf in zip(
        jax.tree.leaves(new_carry), jax.tree.leaves(fresh_carry), strict=True
    ):
        np.testing.assert_allclose(new[0], fresh_leaf[0], atol=1e-6)
    # Without the reset the memory matters: the kept output differs from the fresh one.
    assert float(jnp.max(jnp.abs(kept.mean[1] - fresh.mean[1]))) > 1e-6


def test_unroll_equals_single_steps(policy: AttentionPolicy, variables: dict) -> None:
    T, games, n = 6, 2, 3
    obs_seq = random_obs(10, (T, games, n), n)
    reset_seq = jnp.zeros((T, games, n), bool).at[0].set(True).at[3, 1].set(True)
    carry = _steps(policy, variables, policy.initial_carry((games, n)), obs_seq)  # not zero
    final, outputs = jitted(policy).unroll(variables, carry, obs_seq, reset_seq)
    assert outputs.mean.shape == (T, games, n, 2)
    step_carry = carry
    for t in range(T):
        obs = jax.tree.map(lambda x, t=t: x[t], obs_seq)
        step_carry, output = jitted(policy).step(variables, step_carry, obs, reset_seq[t])
        np.testing.assert_allclose(outputs.mean[t], output.mean, atol=1e-5)
        np.testing.assert_allclose(outputs.log_std[t], output.log_std, atol=1e-5)
    for a, b in zip(jax.tree.leaves(final), jax.tree.leaves(step_carry), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-5)


def test_batch_major_unroll_equals_time_major(policy: AttentionPolicy, variables: dict) -> None:
    T, batch, n = 5, 4, 3
    obs_seq = random_obs(12, (T, batch), n)
    reset_seq = jnp.zeros((T, batch), bool).at[0].set(True).at[2, 1].set(True)
    carry = _steps(policy, variables, policy.initial_carry((batch,)), obs_seq)
    unroll = jax.jit(functools.partial(policy.apply, method=policy.unroll), static_argnums=4)
    final_t, out_t = unroll(variables, carry, obs_seq, reset_seq, 0)
    batch_major = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), (obs_seq, reset_seq))
    final_b, out_b = unroll(variables, carry, *batch_major, 1)
    assert out_b.mean.shape == (batch, T, 2)
    np.testing.assert_allclose(jnp.swapaxes(out_b.mean, 0, 1), out_t.mean, atol=1e-5)
    np.testing.assert_allclose(jnp.swapaxes(out_b.log_std, 0, 1), out_t.log_std, atol=1e-5)
    for a, b in zip(jax.tree.leaves(final_b), jax.tree.leaves(final_t), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-5)
    with pytest.raises(ValueError, match="time_axis=2"):
        policy.apply(variables, carry, obs_seq, reset_seq, 2, method=policy.unroll)


def test_jit_equals_eager(policy: AttentionPolicy, variables: dict) -> None:
    obs = random_obs(11, (2, 4), 4)
    carry = policy.initial_carry((2, 4))
    reset = no_reset((2, 4))
    eager = policy.apply(variables, carry, obs, reset)
    jitted = jax.jit(policy.apply)(variables, carry, obs, reset)
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(
    ("use_attention", "use_lstm"), [(False, True), (True, False), (False, False)]
)
def test_ablation_switches(use_attention: bool, use_lstm: bool, variables: dict) -> None:
    policy = AttentionPolicy(use_attention=use_attention, use_lstm=use_lstm)
    n = 2
    ablation = random_params(policy, n)
    paths = {jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(ablation)}
    full = {jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_leaves_with_path(variables)}
    assert paths != full
    assert any("lstm" in p for p in paths) == use_lstm
    assert any("attention" in p for p in paths) == use_attention
    print(f"\npolicy use_attention={use_attention} use_lstm={use_lstm}: {count(ablation)} params")
    if not use_lstm:
        assert policy.initial_carry((n,)) == ()
    obs_seq = random_obs(12, (3, n), n)
    carry, outputs = jitted(policy).unroll(
        ablation, policy.initial_carry((n,)), obs_seq, no_reset((3, n))
    )
    assert outputs.mean.shape == (3, n, 2)
    assert bool(jnp.all(jnp.isfinite(outputs.mean)))


# ---------------------------------------------------------------------------- NetworkTeam


def test_network_team_plays_a_game_inside_jit(variables: dict) -> None:
    env, params = elevens.make("1v1")
    team = NetworkTeam()
    deterministic = NetworkTeam(deterministic=True, name="network-mode")
    assert isinstance(team, TeamPolicy)
    assert hash(team) == hash(NetworkTeam()) and team == NetworkTeam()
    n, num_steps = 1, 8

    @jax.jit
    def play(key: jax.Array) -> tuple[jax.Array, jax.Array]:
        reset_key, play_key = jax.random.split(key)
        state, _ = env.reset(reset_key, params)

        def step(carry: tuple, step_key: jax.Array) -> tuple[tuple, jax.Array]:
            state, home_carry, away_carry = carry
            home_key, away_key, env_key = jax.random.split(step_key, 3)
            obs = env.observe(state, params)
            home_carry, home_actions = team.act(variables, home_carry, obs.team(0), home_key)
            away_carry, away_actions = deterministic.act(
                variables, away_carry, obs.team(1), away_key
            )
            actions = jnp.stack([home_actions, away_actions])
            state, _, _, _ = env.transition(env_key, state, actions, params)
            return (state, home_carry, away_carry), actions

        carry = (state, team.init_carry(n), deterministic.init_carry(n))
        (state, home_carry, _), actions = jax.lax.scan(
            step, carry, jax.random.split(play_key, num_steps)
        )
        return actions, state.positions

    actions, positions = play(jax.random.key(13))
    assert actions.shape == (num_steps, 2, n, 2)
    assert bool(jnp.all(jnp.abs(actions) < 1.0))
    assert bool(jnp.all(jnp.isfinite(positions)))
    # Sampled actions vary from step to step; the untrained mode is close to tanh(0) = 0.
    assert float(jnp.std(actions[:, 0])) > 0.1
    assert float(jnp.max(jnp.abs(actions[:, 1]))) < 0.1


def test_deterministic_network_team_plays_the_mode(variables: dict) -> None:
    team = NetworkTeam(deterministic=True)
    obs = random_obs(14, (4,), 4)
    carry = team.init_carry(4)
    act = jax.jit(team.act)
    _, first = act(variables, carry, obs, jax.random.key(0))
    _, second = act(variables, carry, obs, jax.random.key(1))
    _, output = jitted(team.policy).step(variables, carry, obs, no_reset((4,)))
    np.testing.assert_array_equal(first, second)
    np.testing.assert_allclose(first, jnp.tanh(output.mean), atol=1e-7)


def test_network_team_init_carry_matches_the_policy() -> None:
    team = NetworkTeam(policy=AttentionPolicy(lstm_features=8, lstm_layers=3))
    carry = team.init_carry(5)
    assert len(carry) == 3
    assert all(leaf.shape == (5, 8) for leaf in jax.tree.leaves(carry))
    assert isinstance(team.policy, nn.Module)
