"""Building blocks shared by the policy and the critic: 2-layer feedforward blocks and a masked
multi-head attention that pools a variable set of entities (thesis section 3.1.3, table 6.2).

Cost matters here: the attention runs once per (player, entity) pair, so per-entity work is kept to
what the thesis architecture needs (docs/architecture.md, "Cost"). Two exact rewrites keep it small:

* ``value_ff`` reads the concatenation ``[entity embedding, query]``. Its first layer is split into
  an entity part and a query part, so the query's share is computed once per observer instead of
  once per entity. The function and the parameter count are those of a Dense on the concatenation.
* In standard multi-head attention every key and value is projected per head (``W_k v_j``,
  ``W_v v_j``), two 64 x 64 matmuls per entity. The scores ``(W_q q) . (W_k v_j)`` equal
  ``(W_k^T W_q q) . v_j``, and the output ``sum_j w_j W_v v_j`` equals ``W_v sum_j w_j v_j`` because
  the weights sum to one, so the projections are applied once per observer and head instead. The
  parameters are those of standard attention; only the order of the products changes. For the
  11 v 11 policy this cuts the gradient from 2.87 to 1.93 MFLOP per player-sample (XLA's cost
  analysis), and it measured about 2x faster on the 2-core CPU.

A third saving is optional (``VisibleCompaction``, used by the trainer's update): the per-entity
layers only matter for the entities in view, about half the slots with a 180 degree view. The
visible (observer, entity) pairs are gathered into a compact array of a fixed capacity, the
encoders and ``value_ff`` run on it, and the values go back to their slots for the attention.
Both moves are gathers, forward and backward (``_take_rows``), since a scatter-add is serial on
XLA's CPU backend. In 11 v 11 this made the whole training iteration 1.15 to 1.2x faster.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp

Activation = Callable[[jax.Array], jax.Array]


class FF2(nn.Module):
    """A 2-layer feedforward block (the ``*_ff`` blocks of table 6.2). [..., d] -> [..., out]."""

    features: int = 64
    """Width of the hidden layer (table 6.1: feedforward layer size 64)."""
    out_features: int | None = None
    """Width of the output layer; None means ``features``."""
    activate_final: bool = True
    """Apply the activation after the second layer too (False for linear outputs: out_ff)."""
    activation: Activation = nn.relu
    """The non-linearity (ReLU, the default of the Sonnet MLPs under the thesis's Mava code)."""
    kernel_init_final: Callable[..., jax.Array] = nn.initializers.lecun_normal()
    """Initialiser of the second layer's kernel (small for output heads)."""

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        lead = x.shape[:-1]
        x = flat_rows(x)
        x = self.activation(
            nn.Dense(self.features, dot_general=rows_dot_general, name="hidden")(x)
        )
        out_features = self.features if self.out_features is None else self.out_features
        x = nn.Dense(
            out_features,
            kernel_init=self.kernel_init_final,
            dot_general=rows_dot_general,
            name="out",
        )(x)
        x = self.activation(x) if self.activate_final else x
        return x.reshape(*lead, x.shape[-1])


WEIGHT_GRADIENT_CHUNK = 512
"""Rows per partial product of a Dense layer's weight gradient (``rows_dot_general``)."""


@jax.custom_vjp
def _rows_matmul(x: jax.Array, kernel: jax.Array) -> jax.Array:
    return x @ kernel


def _rows_matmul_fwd(
    x: jax.Array, kernel: jax.Array
) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
    return x @ kernel, (x, kernel)


def _rows_matmul_bwd(
    residuals: tuple[jax.Array, jax.Array], grad: jax.Array
) -> tuple[jax.Array, jax.Array]:
    x, kernel = residuals
    chunks = x.shape[0] // WEIGHT_GRADIENT_CHUNK
    # x^T grad as a sum of partial products over blocks of rows, each block of x transposed in
    # memory first: XLA's CPU backend sends only a dot whose left operand contracts its last
    # axis to its fast matmul library (YNNPACK), and would fold a plain transpose back into the
    # dot. The first barrier makes the transpose read the saved x instead of recomputing it.
    # 11 v 11 update: `learn` 2 to 3% faster than blocks without the transpose.
    x_saved = jax.lax.optimization_barrier(x)
    x_blocks = jax.lax.optimization_barrier(
        jnp.swapaxes(x_saved.reshape(chunks, WEIGHT_GRADIENT_CHUNK, x.shape[1]), 1, 2)
    )
    partial = jnp.einsum(
        "cir,cro->cio", x_blocks, grad.reshape(chunks, WEIGHT_GRADIENT_CHUNK, grad.shape[1])
    )
    return grad @ kernel.T, jnp.sum(partial, axis=0)


_rows_matmul.defvjp(_rows_matmul_fwd, _rows_matmul_bwd)


def rows_dot_general(
    lhs: jax.Array, rhs: jax.Array, dimension_numbers: Any, precision: Any = None,
    preferred_element_type: Any = None,
) -> jax.Array:
    """``lax.dot_general`` for ``nn.Dense(dot_general=...)``: a Dense on many rows (a multiple
    of ``WEIGHT_GRADIENT_CHUNK``, at least 4 of them) computes its weight gradient blockwise;
    anything else is the plain dot_general."""
    rows_times_kernel = (((1,), (0,)), ((), ()))
    if (
        lhs.ndim == 2
        and dimension_numbers == rows_times_kernel
        and lhs.shape[0] % WEIGHT_GRADIENT_CHUNK == 0
        and lhs.shape[0] >= 4 * WEIGHT_GRADIENT_CHUNK
        and precision is None
        and preferred_element_type is None
    ):
        return _rows_matmul(lhs, rhs)
    return jax.lax.dot_general(
        lhs, rhs, dimension_numbers, precision=precision,
        preferred_element_type=preferred_element_type,
    )


def flat_rows(x: jax.Array) -> jax.Array:
    """[..., d] -> [rows, d]. A Dense on a 2-D input has a 2-D weight gradient, one plain matmul;
    with several leading axes XLA's CPU backend contracts them through transposing copies, which
    measured 3x slower for the gradient of a 2-layer block (11 v 11 update shapes)."""
    return x.reshape(-1, x.shape[-1])


class ConditionedFF2(nn.Module):
    """``FF2(concat([entities, broadcast(condition)]))`` without the broadcast.

    entities f32[..., E, d_e], condition f32[..., d_c] -> f32[..., E, features]. The first layer's
    condition part is computed once per row of ``condition`` (see the module docstring).

    With ``compaction`` the entities are its compact rows f32[C, d_e] (see ``VisibleCompaction``),
    condition is f32[M, d_c] (one row per observer) and the output is f32[C, features].
    """

    features: int = 64
    """Width of both layers."""
    activation: Activation = nn.relu
    """The non-linearity, after both layers."""

    @nn.compact
    def __call__(
        self,
        entities: jax.Array,
        condition: jax.Array,
        compaction: VisibleCompaction | None = None,
    ) -> jax.Array:
        lead = entities.shape[:-1]  # [..., E], or [C] when compacted
        entity_part = nn.Dense(
            self.features, dot_general=rows_dot_general, name="hidden_entity"
        )(flat_rows(entities))
        condition_part = nn.Dense(self.features, use_bias=False, name="hidden_condition")(
            flat_rows(condition)
        )
        if compaction is not None:
            x = entity_part + compaction.gather_per_observer(condition_part)
        else:
            rows = math.prod(lead[:-1])  # explicit: -1 is ambiguous when E == 0
            x = entity_part.reshape(rows, lead[-1], self.features) + condition_part[:, None, :]
        x = self.activation(x).reshape(-1, self.features)
        x = self.activation(nn.Dense(self.features, dot_general=rows_dot_general, name="out")(x))
        return x.reshape(*lead, self.features)


class MaskedMultiHeadAttention(nn.Module):
    """Multi-head scaled dot-product attention of one query over a masked set of entities.

    query f32[..., W], values f32[..., E, W] (used as keys too, as Keras' MultiHeadAttention does
    with ``key=None``, which the thesis's Mava code used), mask bool[..., E] (True = visible)
    -> f32[..., W]. Masked entities get exactly zero weight, so their features never reach the
    output. A row with no visible entity (or E = 0) gives exactly zero.

    Parameters are those of standard multi-head attention with head size ``W / num_heads``:
    query, key, value and output projections. The key bias is left out because it adds the same
    amount to every score of a head and so cancels in the softmax.
    """

    num_heads: int = 4
    """Heads; each of size ``W / num_heads`` (4 heads of 16 for W = 64)."""

    @nn.compact
    def __call__(self, query: jax.Array, values: jax.Array, mask: jax.Array) -> jax.Array:
        width = query.shape[-1]
        if width % self.num_heads:
            raise ValueError(f"width {width} is not divisible by num_heads={self.num_heads}")
        head_size = width // self.num_heads
        shape = (width, self.num_heads, head_size)
        # LeCun normal with the fan-in axes named (the default would read all but the last axis).
        in_init = nn.initializers.variance_scaling(
            1.0, "fan_in", "truncated_normal", in_axis=0, out_axis=(1, 2)
        )
        query_kernel = self.param("query_kernel", in_init, shape)
        query_bias = self.param("query_bias", nn.initializers.zeros, shape[1:])
        key_kernel = self.param("key_kernel", in_init, shape)
        value_kernel = self.param("value_kernel", in_init, shape)
        value_bias = self.param("value_bias", nn.initializers.zeros, shape[1:])
        out_init = nn.initializers.variance_scaling(
            1.0, "fan_in", "truncated_normal", in_axis=(0, 1), out_axis=2
        )
        out_kernel = self.param("out_kernel", out_init, (self.num_heads, head_size, width))
        out_bias = self.param("out_bias", nn.initializers.zeros, (width,))

        # Observers on one leading axis m (see flat_rows: plain 2-D weight gradients).
        lead = query.shape[:-1]
        num_entities = values.shape[-2]
        query = flat_rows(query)
        rows = math.prod(lead)  # explicit: -1 is ambiguous when E == 0
        values = values.reshape(rows, num_entities, width)
        mask = mask.reshape(rows, num_entities)
        # Per observer: the query of each head, mapped back into value space through W_k.
        heads_count = self.num_heads
        head_queries = query @ query_kernel.reshape(width, width) + query_bias.reshape(-1)
        # Per-head products as one 2-D matmul with a block-diagonal matrix: num_heads times
        # the FLOPs of these small per-observer products, but no transposing copies (the
        # 11 v 11 training iteration measured 1.1x faster than with per-head einsums).
        probes = (
            head_queries @ _block_diagonal(jnp.swapaxes(key_kernel, 0, 2))  # [h*d, h*w]
        ).reshape(rows, heads_count, width) / math.sqrt(head_size)
        # Per (observer, entity): one score per head, softmax over the entities, values pooled.
        pooled = attention_pool(values, probes, mask)
        # Back per observer: the value and output projections of each head.
        heads = pooled.reshape(rows, -1) @ _block_diagonal(value_kernel) + value_bias.reshape(-1)
        out = heads @ out_kernel.reshape(-1, width) + out_bias
        out = jnp.where(jnp.any(mask, axis=-1, keepdims=True), out, 0.0)
        return out.reshape(*lead, width)


@jax.custom_vjp
def attention_pool(values: jax.Array, probes: jax.Array, mask: jax.Array) -> jax.Array:
    """The core of ``MaskedMultiHeadAttention``: per observer m and head h, the softmax over the
    visible entities of ``values[m, e] . probes[m, h]``, and the values pooled by those weights.

    values f32[M, E, W], probes f32[M, H, W], mask bool[M, E] -> pooled f32[M, H, W] (zero where
    no entity is visible). The products that contract a short axis (the E entities, or the H
    heads in the value gradient) are unrolled multiply-adds: as batched matmuls with tiny inner
    sizes XLA's CPU backend ran them at a few GFLOP/s, and the hand-written gradient below made
    this core 2x faster (forward and backward, 11 v 11 update shapes). The scores, which contract
    the W features, stay matmuls.
    """
    return _attention_pool_fwd(values, probes, mask)[0]


def _attention_weights(values: jax.Array, probes: jax.Array, mask: jax.Array) -> jax.Array:
    # The [m, E, H] layout of the scores measured 1.1 to 1.5x faster on CPU than [m, H, E].
    scores = jnp.einsum("mew,mhw->meh", values, probes)
    return masked_softmax(scores, mask[..., None], axis=-2)[0]


def _sum_over_entities(weights: jax.Array, values: jax.Array) -> jax.Array:
    """``einsum("meh,mew->mhw")`` as E unrolled multiply-adds (see ``attention_pool``)."""
    rows, num_entities, heads = weights.shape
    total = jnp.zeros((rows, heads, values.shape[-1]), values.dtype)
    for e in range(num_entities):
        total = total + weights[:, e, :, None] * values[:, e, None, :]
    return total


def _attention_pool_fwd(
    values: jax.Array, probes: jax.Array, mask: jax.Array
) -> tuple[jax.Array, tuple[jax.Array, jax.Array, jax.Array]]:
    weights = _attention_weights(values, probes, mask)
    return _sum_over_entities(weights, values), (values, probes, weights)


def _attention_pool_bwd(
    residuals: tuple[jax.Array, jax.Array, jax.Array], grad: jax.Array
) -> tuple[jax.Array, jax.Array, None]:
    values, probes, weights = residuals
    grad_weights = jnp.einsum("mew,mhw->meh", values, grad)
    # Softmax backward; masked entities have weight 0, so their score gradient is 0 too. The
    # barrier stores it once: fused into the products below, XLA recomputed it for each of their
    # outputs (11 v 11 `learn` 4% slower).
    grad_scores = jax.lax.optimization_barrier(
        weights * (grad_weights - jnp.sum(weights * grad_weights, axis=1, keepdims=True))
    )
    grad_values = jnp.zeros_like(values)
    for h in range(probes.shape[1]):
        grad_values = (
            grad_values
            + weights[:, :, h, None] * grad[:, None, h, :]
            + grad_scores[:, :, h, None] * probes[:, None, h, :]
        )
    return grad_values, _sum_over_entities(grad_scores, values), None


attention_pool.defvjp(_attention_pool_fwd, _attention_pool_bwd)


def _block_diagonal(kernel: jax.Array) -> jax.Array:
    """Per-head kernels f32[a, H, b] -> the block-diagonal f32[H * a, H * b] whose block h is
    ``kernel[:, h, :]``: row vectors laid out head by head times it apply each head's kernel."""
    a, heads, b = kernel.shape
    eye = jnp.eye(heads, dtype=kernel.dtype)
    return jnp.einsum("ahb,hg->hagb", kernel, eye).reshape(heads * a, heads * b)


def masked_softmax(
    scores: jax.Array, mask: jax.Array, axis: int = -1
) -> tuple[jax.Array, jax.Array]:
    """Softmax along ``axis`` among the entries where ``mask`` is True.

    scores f32[...], mask bool (broadcastable to scores) -> (weights, shaped like scores, that
    are exactly 0 where masked and sum to 1 over the visible entries, or are all 0 where none is
    visible; any_visible bool, shaped like scores with ``axis`` of size 1). No NaN, in values or
    gradients, for any mask.
    """
    mask = jnp.broadcast_to(mask, scores.shape)
    masked = jnp.where(mask, scores, -jnp.inf)
    peak = jnp.max(masked, axis=axis, keepdims=True, initial=-jnp.inf)
    any_visible = jnp.isfinite(peak)
    # The shift only guards exp against overflow; it cancels exactly, so it carries no gradient.
    peak = jax.lax.stop_gradient(jnp.where(any_visible, peak, 0.0))
    exponentials = jnp.where(mask, jnp.exp(jnp.where(mask, scores - peak, 0.0)), 0.0)
    total = jnp.sum(exponentials, axis=axis, keepdims=True)
    return exponentials / jnp.where(any_visible, total, 1.0), any_visible


class AttentionPool(nn.Module):
    """``value_ff`` then multi-head attention: what a query learns from a set of entities.

    query f32[..., W], entity embeddings f32[..., E, W], mask bool[..., E] -> f32[..., W].
    The values are ``value_ff([embedding, query])`` (thesis section 5.2.10: "player embeddings
    are concatenated with the query embeddings and passed through value_ff").
    """

    features: int = 64
    """Width of value_ff and of the attention output."""
    num_heads: int = 4
    """Attention heads (each of size features / num_heads)."""
    activation: Activation = nn.relu
    """value_ff's non-linearity."""

    @nn.compact
    def __call__(
        self,
        query: jax.Array,
        embeddings: jax.Array,
        mask: jax.Array,
        compaction: VisibleCompaction | None = None,
    ) -> jax.Array:
        """With ``compaction``, embeddings are the compact rows f32[C, W] of the visible entities
        (``VisibleCompaction.gather``) and value_ff runs on those rows only; the values are put
        back in their slots (zeros elsewhere) for the attention, which masks those anyway."""
        values = ConditionedFF2(self.features, self.activation, name="value_ff")(
            embeddings, query, compaction
        )
        if compaction is not None:
            values = compaction.scatter(values).reshape(*mask.shape, self.features)
        return MaskedMultiHeadAttention(self.num_heads, name="attention")(query, values, mask)


# --------------------------------------------------------------------------------------------
# Computing per-entity layers on the visible entities only
# --------------------------------------------------------------------------------------------


@jax.custom_vjp
def _take_rows(x: jax.Array, index: jax.Array, inverse: jax.Array) -> jax.Array:
    """``[x; 0][index]``: rows of x f32[R, d] by index i32[K] (R picks the zero row).

    ``inverse`` i32[R] must undo ``index`` where it is defined: ``inverse[index[k]] == k`` for
    every ``index[k] < R``, and ``inverse[r] == K`` for a row r that no index picks. The mapping
    is then injective, so the gradient is a gather too (``[g; 0][inverse]``) instead of the
    scatter-add that ``jnp.take`` would transpose into (serial on XLA's CPU backend).
    """
    return _rows_or_zero(x, index)


def _rows_or_zero(x: jax.Array, index: jax.Array) -> jax.Array:
    """``[x; 0][index]`` for index values in ``[0, len(x)]``. In bounds by construction, so
    the gather skips jnp.take's out-of-bounds fill (a select over the whole output)."""
    padded = jnp.concatenate([x, jnp.zeros((1, *x.shape[1:]), x.dtype)])
    return padded.at[index].get(mode="promise_in_bounds")


def _take_rows_fwd(
    x: jax.Array, index: jax.Array, inverse: jax.Array
) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
    return _take_rows(x, index, inverse), (index, inverse)


def _take_rows_bwd(
    residuals: tuple[jax.Array, jax.Array], grad: jax.Array
) -> tuple[jax.Array, None, None]:
    index, inverse = residuals
    return _rows_or_zero(grad, inverse), None, None


_take_rows.defvjp(_take_rows_fwd, _take_rows_bwd)


class VisibleCompaction(NamedTuple):
    """Where the visible (observer, entity) pairs of a ``[M, E]`` mask go in a compact array.

    Slots are numbered ``m * E + e``. ``order`` i32[C]: the slot of each compact row (``M * E``
    for an unused row); ``slot`` i32[M * E]: the compact row of each slot (``C`` for a slot left
    out). Compact rows keep slot order within each group of entity columns: group g fills rows
    ``starts[g]`` to ``starts[g + 1]``, so each group can go through its own encoder. Build it
    with ``visible_compaction``.
    """

    order: jax.Array
    slot: jax.Array
    num_entities: int
    starts: tuple[int, ...]

    def gather(self, x: jax.Array) -> jax.Array:
        """Per-slot rows x f32[M, E, d] -> f32[C, d], zeros in unused rows. No custom gradient:
        this is for inputs (observations)."""
        return _rows_or_zero(x.reshape(-1, x.shape[-1]), self.order)

    def gather_per_observer(self, x: jax.Array) -> jax.Array:
        """Per-observer rows x f32[M, d] -> the row of each compact slot's observer, f32[C, d]."""
        rows = x.shape[0]
        per_slot = jnp.broadcast_to(x[:, None, :], (rows, self.num_entities, x.shape[-1]))
        return _take_rows(per_slot.reshape(-1, x.shape[-1]), self.order, self.slot)

    def scatter(self, compact: jax.Array) -> jax.Array:
        """Compact rows f32[C, d] -> f32[M * E, d] in slot order, zeros where left out."""
        return _take_rows(compact, self.slot, self.order)

    def group(self, compact: jax.Array, index: int) -> jax.Array:
        """The compact rows of group ``index``."""
        stops = (*self.starts[1:], compact.shape[0])
        return compact[self.starts[index] : stops[index]]


EntityGroups = tuple[tuple[int, int], ...]
"""``(start, stop)`` entity columns of each group, in order, covering all columns."""


def group_capacity(rows: int, width: int, fraction: float) -> int:
    """Compact rows kept for a group of ``width`` columns over ``rows`` observers: ``fraction``
    of its slots, rounded up to a multiple of 8 (0 for an empty group), or of
    ``WEIGHT_GRADIENT_CHUNK`` for groups large enough that the per-entity layers compute their
    weight gradients blockwise (``rows_dot_general``)."""
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction={fraction!r} is invalid: it must be in (0, 1]")
    wanted = fraction * rows * width
    multiple = WEIGHT_GRADIENT_CHUNK if wanted >= 4 * WEIGHT_GRADIENT_CHUNK else 8
    return multiple * math.ceil(wanted / multiple)


Capacity = float | tuple[float, ...]
"""The share of each group's slots that a compaction keeps: one fraction for every group, or
one per group (in the order of the groups)."""


def group_fractions(capacity: Capacity, groups: EntityGroups) -> tuple[float, ...]:
    """``capacity`` as one fraction per group; ValueError if a tuple has the wrong length."""
    if isinstance(capacity, tuple):
        if len(capacity) != len(groups):
            raise ValueError(
                f"capacity={capacity!r} is invalid: it needs one fraction per group "
                f"({len(groups)} groups)"
            )
        return capacity
    return (capacity,) * len(groups)


def fits_capacity(mask: jax.Array, groups: EntityGroups, capacity: Capacity) -> jax.Array:
    """bool[]: every group of mask bool[M, E] has at most ``group_capacity`` visible slots, so
    ``visible_compaction(mask, groups, capacity)`` loses nothing."""
    rows = mask.shape[0]
    fits = [
        jnp.sum(mask[:, start:stop]) <= group_capacity(rows, stop - start, fraction)
        for (start, stop), fraction in zip(groups, group_fractions(capacity, groups), strict=True)
    ]
    return jnp.all(jnp.stack(fits))


def visible_compaction(
    mask: jax.Array, groups: EntityGroups, capacity: Capacity
) -> VisibleCompaction:
    """Compact the True entries of mask bool[M, E], group by group (see ``VisibleCompaction``).

    Group g keeps ``group_capacity(M, width, fraction)`` rows, with its fraction of
    ``capacity``. Visible slots beyond a group's capacity are dropped: check ``fits_capacity``
    first and compute densely where it is False.
    """
    rows, num_entities = mask.shape
    num_slots = rows * num_entities
    capacities = [
        group_capacity(rows, stop - start, fraction)
        for (start, stop), fraction in zip(groups, group_fractions(capacity, groups), strict=True)
    ]
    total = sum(capacities)
    orders, slots, starts = [], [], []
    start_row = 0
    for (start, stop), capacity in zip(groups, capacities, strict=True):
        width = stop - start
        starts.append(start_row)
        start_row += capacity
        if capacity == 0:
            slots.append(jnp.full((rows, width), total, jnp.int32))
            continue
        visible = mask[:, start:stop].reshape(-1)
        rank = jnp.cumsum(visible.astype(jnp.int32)) - 1  # among this group's visible slots
        taken = visible & (rank < capacity)
        slots.append(jnp.where(taken, starts[-1] + rank, total).reshape(rows, width))
        # The k-th visible slot is the first position whose rank reaches k.
        position = jnp.searchsorted(rank, jnp.arange(capacity, dtype=jnp.int32), side="left")
        position = jnp.minimum(position, visible.size - 1)
        full = (position // width) * num_entities + start + position % width
        used = jnp.arange(capacity) <= rank[-1]
        orders.append(jnp.where(used, full, num_slots))
    return VisibleCompaction(
        order=jnp.concatenate([*orders, jnp.zeros((0,), jnp.int32)]).astype(jnp.int32),
        slot=jnp.concatenate(slots, axis=1).reshape(-1).astype(jnp.int32),
        num_entities=num_entities,
        starts=tuple(starts),
    )
