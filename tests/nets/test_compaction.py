"""The policy's per-entity layers on the visible entities only (``visible_compaction`` and the
compacted ``AttentionPolicy.embed``): the same outputs and gradients as the dense pass, the
capacity checks that guard it; and the other update speedups, the blockwise weight gradient and
the LSTM that ``unroll`` runs over whole sequences."""

from __future__ import annotations

import functools
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.nets.attention import (
    WEIGHT_GRADIENT_CHUNK,
    VisibleCompaction,
    fits_capacity,
    group_capacity,
    rows_dot_general,
    visible_compaction,
)
from elevens.nets.policy import (
    AttentionPolicy,
    LSTMState,
    RecurrentCore,
    entity_groups,
    visible_capacity_index,
)
from tests.nets.test_policy import random_obs, random_params

GROUPS = ((0, 2), (2, 5))


def random_mask(seed: int, rows: int, columns: int, share: float = 0.6) -> jax.Array:
    return jnp.asarray(np.random.default_rng(seed).uniform(size=(rows, columns)) < share)


def test_compaction_lists_each_visible_slot_once_in_slot_order_per_group() -> None:
    mask = random_mask(0, 7, 5)
    compaction = visible_compaction(mask, GROUPS, 1.0)
    num_slots = mask.size
    order, slot = np.asarray(compaction.order), np.asarray(compaction.slot)
    capacities = [group_capacity(7, stop - start, 1.0) for start, stop in GROUPS]
    assert order.shape == (sum(capacities),)
    assert compaction.starts == (0, capacities[0])
    flat = np.asarray(mask).reshape(-1)
    for (start, stop), first, capacity in zip(
        GROUPS, compaction.starts, capacities, strict=True
    ):
        rows = order[first : first + capacity]
        expected = [s for s in range(num_slots) if flat[s] and start <= s % 5 < stop]
        assert list(rows[rows < num_slots]) == expected  # slot order, this group only
        assert np.all(rows[len(expected) :] == num_slots)  # unused rows point at the zero row
    used = order < num_slots
    np.testing.assert_array_equal(slot[order[used]], np.flatnonzero(used))  # inverse maps
    assert np.all(slot[~flat] == order.size)  # invisible slots are left out


def test_gather_then_scatter_keeps_the_visible_rows_and_zeroes_the_rest() -> None:
    mask = random_mask(1, 6, 5)
    x = jnp.asarray(np.random.default_rng(2).standard_normal((6, 5, 3)), jnp.float32)
    compaction = visible_compaction(mask, GROUPS, 1.0)
    back = compaction.scatter(compaction.gather(x)).reshape(6, 5, 3)
    np.testing.assert_array_equal(back, jnp.where(mask[..., None], x, 0.0))
    per_observer = jnp.arange(6.0)[:, None]
    rows = compaction.gather_per_observer(per_observer)[:, 0]
    order = np.asarray(compaction.order)
    used = order < mask.size
    np.testing.assert_array_equal(rows[used], order[used] // 5)  # each row's observer


def test_custom_gradients_equal_those_of_plain_indexing() -> None:
    mask = random_mask(3, 6, 5)
    compaction = visible_compaction(mask, GROUPS, 1.0)
    rng = np.random.default_rng(4)
    per_observer = jnp.asarray(rng.standard_normal((6, 3)), jnp.float32)
    compact = jnp.asarray(rng.standard_normal((compaction.order.size, 3)), jnp.float32)

    def plain_scatter(y: jax.Array) -> jax.Array:  # jnp indexing, differentiated by JAX
        return jnp.concatenate([y, jnp.zeros((1, 3))])[compaction.slot]

    def plain_gather(x: jax.Array) -> jax.Array:
        per_slot = jnp.repeat(x, 5, axis=0)
        return jnp.concatenate([per_slot, jnp.zeros((1, 3))])[compaction.order]

    def loss(fn):  # noqa: ANN001, ANN202
        def weighted(a: jax.Array) -> jax.Array:
            y = fn(a)
            return jnp.sum(jnp.sin(y) * jnp.cos(jnp.arange(y.size).reshape(y.shape)))

        return jax.grad(weighted)

    np.testing.assert_allclose(
        loss(compaction.scatter)(compact), loss(plain_scatter)(compact), atol=1e-6
    )
    np.testing.assert_allclose(
        loss(compaction.gather_per_observer)(per_observer),
        loss(plain_gather)(per_observer),
        atol=1e-6,
    )


def test_capacity_checks_report_overflow_and_pick_the_smallest_fit() -> None:
    mask = jnp.zeros((40, 5), bool).at[:, :2].set(True).at[:20, 2:].set(True)  # 100% / 50%
    assert not bool(fits_capacity(mask, GROUPS, 0.9))  # the first group is all visible
    assert bool(fits_capacity(mask, GROUPS, 1.0))
    with pytest.raises(ValueError, match=r"fraction=0.0 is invalid"):
        group_capacity(8, 2, 0.0)
    n = 4  # 3 teammates, 4 opponents, the ball: 8 slots
    visible = np.zeros((10, 2 * n), bool)
    visible[:, : n - 1] = np.arange(10)[:, None] < 5  # half the teammate slots
    visible[:, n - 1 : 2 * n - 1] = np.arange(10)[:, None] < 7  # 70% of the opponent slots
    visible[:, -1] = True  # the ball never counts
    obs = random_obs(0, (10,), n)
    obs = obs.__class__(obs.self_features, obs.entities, jnp.asarray(visible))
    assert int(visible_capacity_index(obs, (0.5, 0.7, 0.8))) == 1
    assert int(visible_capacity_index(obs, (0.6,))) == 1  # none fits: the dense pass
    assert int(visible_capacity_index(obs, ())) == 0
    # one fraction per group: (teammates, opponents)
    assert int(visible_capacity_index(obs, ((0.5, 0.55), (0.5, 0.7), (0.6, 0.8)))) == 1
    assert int(visible_capacity_index(obs, ((0.2, 1.0),))) == 1


def test_per_group_capacities_size_each_group_and_check_its_length() -> None:
    mask = jnp.zeros((40, 5), bool).at[:, :2].set(True).at[:20, 2:].set(True)  # 100% / 50%
    assert bool(fits_capacity(mask, GROUPS, (1.0, 0.5)))
    assert not bool(fits_capacity(mask, GROUPS, (1.0, 0.4)))  # the second group overflows
    assert not bool(fits_capacity(mask, GROUPS, (0.9, 1.0)))  # the first one does
    compaction = visible_compaction(mask, GROUPS, (1.0, 0.5))
    assert compaction.starts == (0, group_capacity(40, 2, 1.0))
    assert compaction.order.size == group_capacity(40, 2, 1.0) + group_capacity(40, 3, 0.5)
    back = compaction.scatter(compaction.gather(jnp.ones((40, 5, 1)))).reshape(40, 5)
    np.testing.assert_array_equal(back, jnp.where(mask, 1.0, 0.0))  # nothing dropped
    with pytest.raises(ValueError, match=r"one fraction per group \(2 groups\)"):
        visible_compaction(mask, GROUPS, (1.0, 0.5, 0.5))


def test_an_empty_group_compacts_to_nothing() -> None:
    mask = random_mask(5, 4, 1)
    compaction = visible_compaction(mask, ((0, 0), (0, 1)), 1.0)
    assert compaction.starts == (0, 0)
    np.testing.assert_array_equal(
        compaction.scatter(compaction.gather(jnp.ones((4, 1, 2)))).reshape(4, 2),
        jnp.where(mask, 1.0, 0.0).repeat(2, axis=1),
    )
    assert isinstance(compaction, VisibleCompaction)


# 11 a side runs the same code as 4 on larger groups (three compiles of its own): --slow.
@pytest.mark.parametrize("n", [4, pytest.param(11, marks=pytest.mark.slow)])
def test_compacted_policy_equals_the_dense_pass_in_values_and_gradients(n: int) -> None:
    policy = AttentionPolicy(features=16, num_heads=2, lstm_features=8)
    params = random_params(policy, n)
    obs = random_obs(6, (3, 5, n), n)  # [batch, T, n]: 60% of the slots visible
    reset = jnp.zeros((3, 5, n), bool).at[:, 0].set(True)
    carry = policy.initial_carry((3, n))
    fraction = 0.8
    assert int(visible_capacity_index(obs, (fraction,))) == 0  # it fits

    def unroll(params: dict, fraction: float | None) -> Any:
        return policy.apply(params, carry, obs, reset, 1, fraction, method=policy.unroll)[1]

    @functools.partial(jax.jit, static_argnums=1)
    def value_and_grad(params: dict, fraction: float | None) -> tuple:
        def loss(params: dict) -> tuple:
            out = unroll(params, fraction)
            return jnp.sum(jnp.tanh(out.mean)) + jnp.sum(out.log_std), out

        return jax.value_and_grad(loss, has_aux=True)(params)

    (dense_loss, dense_out), dense_grads = value_and_grad(params, None)
    (loss, out), grads = value_and_grad(params, fraction)
    np.testing.assert_allclose(out.mean, dense_out.mean, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(loss, dense_loss, rtol=1e-5)
    for a, b in zip(jax.tree.leaves(grads), jax.tree.leaves(dense_grads), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)
    # The check is not vacuous: too small a capacity drops visible entities and changes the output.
    assert int(visible_capacity_index(obs, (0.3,))) == 1
    dropped = jax.jit(unroll, static_argnums=1)(params, 0.3)  # the values alone: no gradients
    assert float(jnp.max(jnp.abs(dropped.mean - dense_out.mean))) > 1e-4
    assert entity_groups(n) == ((0, n - 1), (n - 1, 2 * n - 1))


class _FlaxCells(nn.Module):
    """The reference: Flax's OptimizedLSTMCell stacked as RecurrentCore names its layers."""

    @nn.compact
    def __call__(self, carry: tuple, x: jax.Array) -> tuple:
        new = []
        for layer, state in enumerate(carry):
            (c, h), x = nn.OptimizedLSTMCell(8, name=f"lstm_{layer}")(
                (state.cell, state.hidden), x
            )
            new.append(LSTMState(cell=c, hidden=h))
        return tuple(new), x


def test_recurrent_core_is_optimized_lstm_cell_in_params_and_steps() -> None:
    core, reference = RecurrentCore(lstm_features=8, lstm_layers=2), _FlaxCells()
    rng = np.random.default_rng(7)
    x = jnp.asarray(rng.standard_normal((3, 5)), jnp.float32)
    carry = tuple(
        LSTMState(
            jnp.asarray(rng.standard_normal((3, 8)), jnp.float32),
            jnp.asarray(rng.standard_normal((3, 8)), jnp.float32),
        )
        for _ in range(2)
    )
    params = core.init(jax.random.key(0), carry, x, jnp.zeros((3,), bool))
    reference_params = reference.init(jax.random.key(0), carry, x)
    # Same names, shapes and initial values: checkpoints of either load into the other.
    assert jax.tree.structure(params) == jax.tree.structure(reference_params)
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(reference_params), strict=True):
        np.testing.assert_array_equal(a, b)
    new_carry, y = core.apply(params, carry, x, jnp.zeros((3,), bool))
    reference_carry, reference_y = reference.apply(params, carry, x)
    np.testing.assert_allclose(y, reference_y, atol=1e-6)
    for a, b in zip(jax.tree.leaves(new_carry), jax.tree.leaves(reference_carry), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)


@pytest.mark.parametrize("rows", [4 * WEIGHT_GRADIENT_CHUNK, 3 * WEIGHT_GRADIENT_CHUNK, 1000])
def test_blockwise_weight_gradient_equals_the_plain_one(rows: int) -> None:
    # 4 blocks or more take the blockwise path; fewer, or a row count that is not a multiple of
    # the block, the plain dot_general. Both must give Dense's values and gradients.
    rng = np.random.default_rng(rows)
    x = jnp.asarray(rng.standard_normal((rows, 6)), jnp.float32)
    kernel = jnp.asarray(rng.standard_normal((6, 5)), jnp.float32)

    def loss(dot_general):  # noqa: ANN001, ANN202
        def value(x: jax.Array, kernel: jax.Array) -> jax.Array:
            y = dot_general(x, kernel, (((1,), (0,)), ((), ())))
            return jnp.sum(jnp.tanh(y) * jnp.cos(jnp.arange(y.size).reshape(y.shape)))

        return jax.value_and_grad(value, argnums=(0, 1))(x, kernel)

    blockwise, plain = loss(rows_dot_general), loss(jax.lax.dot_general)
    for a, b in zip(jax.tree.leaves(blockwise), jax.tree.leaves(plain), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4)
