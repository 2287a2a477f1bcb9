"""The policy network (thesis figure 5.2, table 6.2): attention over the entities a player sees,
a 2-layer LSTM for memory, and a tanh-squashed Gaussian over the two actions (or the
parametrised head below).

One player's forward pass, for a team of ``n`` (any ``n``: no parameter depends on it)::

    h = encode_ff(self_features)                        # own state, ball and time, f32[64]
    q = query_ff(h)                                     # the attention query, f32[64]
    e = [encode_team_ff(teammate slots), encode_opp_ff(opponent slots)]   # f32[2n - 1, 64]
    a = attention(q, value_opp_ff([e, q]), visible)     # 4 heads of 16, f32[64]
    y = out_r([h, a])                                   # 2 LSTM layers of 32 units
    mean, log_std = Dense(4)(y)                         # 2 actions (move, rot)

The parametrised head (``kinds`` K > 0) gives instead a discrete kind, a pointer at one of the
2n - 1 player slots and a continuous target (x, y), the action f32[4] = (kind, pointer, x, y) of
``ParametrisedDistribution``; the pointer and the target are given for every kind::

    kind_logits = Dense(K)(y)                                                   # f32[K]
    pointer_logits = Dense(K * 64)(y) . Dense(64)(e)^T / sqrt(64)              # f32[K, 2n - 1]
    mean, log_std = Dense(4K)(y)                                                # f32[K, 2]

so the pointer is an attention of the player's memory over the per-entity embeddings ``e`` that
the encoder computed, masked like it to the slots in view. A pointer value is a slot of
``elevens.env.observe.entity_layout`` (teammates, then opponents; the observer is in no slot).

The ball slot (the last entity slot) is left out of the attention: the ball is already in the
self features (``ball_visible``, distance, bearing and velocity), which the thesis feeds to
encode_ff with the player's location and the time. Only the teammates and opponents in view are
attended to (``entity_mask``); invisible slots get zero weight, whatever their features.

Switches give the variants without duplicating code: ``use_attention=False`` is the feedforward
ablation of thesis section 6.4 (every teammate and opponent slot, zeroed where invisible, is
flattened and concatenated to the self features before encode_ff; its first layer then depends
on ``n``), and ``use_lstm=False`` replaces the LSTM by a 2-layer feedforward block (the carry is
then the empty tuple).

For recurrent PPO, ``unroll`` runs the non-recurrent part (encoders and attention, almost all the
FLOPs) on the whole ``[T, ...]`` sequence as one large batch, and scans only the LSTM over time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax.linen.recurrent import DenseParams

from elevens.env.state import Observation
from elevens.nets.attention import (
    FF2,
    Activation,
    AttentionPool,
    Capacity,
    EntityGroups,
    fits_capacity,
    visible_compaction,
)
from elevens.nets.distributions import (
    MASKED_LOGIT,
    ParametrisedDistribution,
    TanhGaussian,
    clamp_log_std,
)

NUM_ACTIONS = 2
"""(move, rot)."""
PARAMETRISED_ACTIONS = 4
"""(kind, pointer, x, y): the action of the parametrised head."""


class LSTMState(NamedTuple):
    """One LSTM layer's memory."""

    cell: jax.Array  # f32[..., lstm_features]
    hidden: jax.Array  # f32[..., lstm_features]


PolicyCarry = tuple[LSTMState, ...]
"""The policy's memory: one LSTMState per layer, bottom first (the empty tuple without LSTM)."""


class PolicyOutput(NamedTuple):
    """The action distribution's parameters; unpacks as ``mean, log_std``."""

    mean: jax.Array  # f32[..., 2] pre-tanh mean of (move, rot)
    log_std: jax.Array  # f32[..., 2] clamped to [LOG_STD_MIN, LOG_STD_MAX]

    def distribution(self) -> TanhGaussian:
        return TanhGaussian(mean=self.mean, log_std=self.log_std)


class ParametrisedOutput(NamedTuple):
    """The parametrised head's parameters (see ``ParametrisedDistribution.create``)."""

    kind_logits: jax.Array  # f32[..., K]
    pointer_logits: jax.Array  # f32[..., K, 2n - 1] MASKED_LOGIT out of view
    pointer_mask: jax.Array  # bool[..., 2n - 1] the player slots in view
    mean: jax.Array  # f32[..., K, 2] pre-tanh mean of each kind's target
    log_std: jax.Array  # f32[..., K, 2]

    def distribution(self) -> ParametrisedDistribution:
        return ParametrisedDistribution.create(
            self.kind_logits, self.pointer_logits, self.pointer_mask, self.mean, self.log_std
        )


AnyPolicyOutput = PolicyOutput | ParametrisedOutput
"""What a policy step gives; ``.distribution()`` has sample, log_prob, mode and the entropies."""


def reset_carry(carry: PolicyCarry, reset: jax.Array) -> PolicyCarry:
    """Zero the memory of the rows where ``reset`` (bool[...]) is True; carry leaves f32[..., H]."""
    return jax.tree.map(lambda leaf: jnp.where(reset[..., None], 0.0, leaf), carry)


class LSTMWeights(nn.Module):
    """One LSTM layer's parameters, named and initialised exactly as ``nn.OptimizedLSTMCell``'s
    (``ii``..``io`` input kernels, ``hi``..``ho`` hidden kernels with the biases), concatenated
    in gate order (i, f, g, o): ``(input f32[d, 4H], hidden f32[H, 4H], bias f32[4H])``.
    Checkpoints of either load into the other."""

    features: int

    @nn.compact
    def __call__(self, input_size: int) -> tuple[jax.Array, jax.Array, jax.Array]:
        inputs = jnp.zeros((1, input_size))
        hidden = jnp.zeros((1, self.features))
        kernels_i, kernels_h, biases = [], [], []
        for gate in "ifgo":
            kernel_i, _ = DenseParams(self.features, use_bias=False, name=f"i{gate}")(inputs)
            kernel_h, bias = DenseParams(
                self.features, kernel_init=nn.initializers.orthogonal(), name=f"h{gate}"
            )(hidden)
            assert bias is not None
            kernels_i.append(kernel_i)
            kernels_h.append(kernel_h)
            biases.append(bias)
        return (
            jnp.concatenate(kernels_i, axis=-1),
            jnp.concatenate(kernels_h, axis=-1),
            jnp.concatenate(biases, axis=-1),
        )


def lstm_cell(pre_activation: jax.Array, cell: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The LSTM update from the summed gate inputs f32[..., 4H] (gates i, f, g, o) and the old
    cell f32[..., H] -> (cell, hidden), as ``nn.OptimizedLSTMCell`` computes it."""
    i, f, g, o = jnp.split(pre_activation, 4, axis=-1)
    cell = jax.nn.sigmoid(f) * cell + jax.nn.sigmoid(i) * jnp.tanh(g)
    return cell, jax.nn.sigmoid(o) * jnp.tanh(cell)


class RecurrentCore(nn.Module):
    """out_r: a stack of LSTM layers, or a feedforward block when ``use_lstm`` is False.

    (carry, x f32[..., d], reset bool[...]) -> (carry, y f32[..., lstm_features]). ``reset``
    zeroes the carry of those rows before it is used (the first step of an episode).
    ``sequence`` runs T steps at once.
    """

    lstm_features: int = 32
    """LSTM units per layer (table 6.1: LSTM layer size 32)."""
    lstm_layers: int = 2
    """Stacked LSTM layers (table 6.2: out_r is a 2-layer LSTM)."""
    use_lstm: bool = True
    """False: a 2-layer feedforward block of lstm_features instead, with no memory."""
    activation: Activation = nn.relu
    """Non-linearity of the feedforward replacement."""

    def setup(self) -> None:
        if not self.use_lstm:
            self.ff = FF2(self.lstm_features, activation=self.activation)
            return
        for layer in range(self.lstm_layers):
            setattr(self, f"lstm_{layer}", LSTMWeights(self.lstm_features))

    def _weights(self, input_size: int) -> list[tuple[jax.Array, jax.Array, jax.Array]]:
        sizes = [input_size] + [self.lstm_features] * (self.lstm_layers - 1)
        return [getattr(self, f"lstm_{layer}")(size) for layer, size in enumerate(sizes)]

    def __call__(
        self, carry: PolicyCarry, x: jax.Array, reset: jax.Array
    ) -> tuple[PolicyCarry, jax.Array]:
        carry, y = self.sequence(carry, x[None], reset[None])
        return carry, y[0]

    def sequence(
        self, carry: PolicyCarry, x_seq: jax.Array, reset_seq: jax.Array
    ) -> tuple[PolicyCarry, jax.Array]:
        """T steps: x_seq f32[T, ..., d], reset_seq bool[T, ...] -> (carry after step T,
        y f32[T, ..., lstm_features]); equals T calls.

        Only what depends on the previous step is scanned. The first layer's input projection
        runs on all T steps as one matmul before the scan, and each higher layer's input and
        hidden projections are one matmul on ``[input, hidden]``. (1.6x faster to differentiate
        than a scan of ``__call__``: 55 sequences of 100 steps, 2-core CPU.)
        """
        if not self.use_lstm:
            return carry, self.ff(x_seq)
        weights = self._weights(x_seq.shape[-1])
        kernel_i, kernel_h, bias = weights[0]
        projected = x_seq @ kernel_i + bias
        stacked = [(jnp.concatenate([k_i, k_h], axis=0), b) for k_i, k_h, b in weights[1:]]

        def step(carry: PolicyCarry, inputs: tuple[jax.Array, jax.Array]) -> Any:
            pre_activation, reset = inputs
            carry = reset_carry(carry, reset)
            state = carry[0]
            c, h = lstm_cell(pre_activation + state.hidden @ kernel_h, state.cell)
            new_carry = [LSTMState(cell=c, hidden=h)]
            for (kernel, b), state in zip(stacked, carry[1:], strict=True):
                c, h = lstm_cell(jnp.concatenate([h, state.hidden], -1) @ kernel + b, state.cell)
                new_carry.append(LSTMState(cell=c, hidden=h))
            return tuple(new_carry), h

        return jax.lax.scan(step, carry, (projected, reset_seq))


def entity_groups(players_per_team: int) -> EntityGroups:
    """The policy's entity columns by encoder: the n - 1 teammates, then the n opponents."""
    n = players_per_team
    return ((0, n - 1), (n - 1, 2 * n - 1))


def visible_capacity_index(obs: Observation, capacities: Sequence[Capacity]) -> jax.Array:
    """i32[]: the index of the first of ``capacities`` (smallest first; each one fraction, or
    a (teammates, opponents) pair) whose compaction holds every visible teammate and opponent
    of obs (any leading axes, all rows together), or ``len(capacities)`` where none does. With
    a 180 degree view about half the slots are visible, so a compacted update does about half
    the per-entity work (``embed``)."""
    num_slots = obs.entity_mask.shape[-1]
    mask = obs.entity_mask[..., : num_slots - 1].reshape(-1, num_slots - 1)
    groups = entity_groups(num_slots // 2)
    misses = [~fits_capacity(mask, groups, capacity) for capacity in capacities]
    return jnp.sum(jnp.stack([*misses, jnp.zeros((), bool)]).astype(jnp.int32))


KIND_MASKS: dict[str, Callable[[Observation], jax.Array]] = {}
"""Named functions ``Observation [...] -> bool[..., K]``: the kinds each player may choose
(at least one), for ``AttentionPolicy.kind_mask``; a game registers its own
(``register_kind_mask``)."""


def register_kind_mask(name: str, mask: Callable[[Observation], jax.Array]) -> None:
    """Make ``mask`` known as ``network.kind_mask=name`` (idempotent)."""
    KIND_MASKS[name] = mask


class AttentionPolicy(nn.Module):
    """The policy of one player; leading axes of the inputs are free (players, games, time).

    ``__call__(carry, obs, reset) -> (carry, PolicyOutput)`` (``ParametrisedOutput`` with
    ``kinds``) for one step, obs an Observation with
    leading axes ``[...]`` (e.g. ``[n]`` for one team of one game). ``unroll`` does T steps.
    Build the first carry with ``initial_carry(batch_shape)``.
    """

    features: int = 64
    """Width of every feedforward block and of the attention (table 6.1: 64)."""
    num_heads: int = 4
    """Attention heads, each of size features / num_heads = 16 (the thesis does not say)."""
    lstm_features: int = 32
    """LSTM units per layer (table 6.1: 32)."""
    lstm_layers: int = 2
    """LSTM layers in out_r (table 6.2: 2)."""
    use_attention: bool = True
    """False: the feedforward ablation of section 6.4 (parameters then depend on n)."""
    use_lstm: bool = True
    """False: a feedforward head without memory."""
    activation: Activation = nn.relu
    """Non-linearity of the feedforward blocks."""
    num_actions: int = NUM_ACTIONS
    """Action values: 2, the simulator's (move, rot); 12, the thesis's 12-value action of
    table 4.1 (for games above the core that take it); 4 with the parametrised head."""
    kinds: int = 0
    """0: the tanh-Gaussian head over ``num_actions`` values. K >= 1: the parametrised head
    with K kinds (needs attention, and ``num_actions`` 4)."""
    kind_mask: str = ""
    """The parametrised head only: a name of ``KIND_MASKS``, whose function of the observation
    says which kinds each player may choose (the others get ``MASKED_LOGIT``); '': every kind.
    Kinds after the mask's own (a game's extra kind, e.g. the skill game's DEFER) are allowed."""
    last_kind_logit: float = 0.0
    """The parametrised head only: a constant added to the last kind's logit, a prior the
    network learns around (the skill game's DEFER: how often an untrained policy defers)."""

    def setup(self) -> None:
        if self.kinds and (not self.use_attention or self.num_actions != PARAMETRISED_ACTIONS):
            raise ValueError(
                f"kinds={self.kinds} (the parametrised head) needs use_attention=True and "
                f"num_actions={PARAMETRISED_ACTIONS}, got use_attention={self.use_attention}, "
                f"num_actions={self.num_actions}"
            )
        self.encode_ff = FF2(self.features, activation=self.activation)
        if self.use_attention:
            self.query_ff = FF2(self.features, activation=self.activation)
            self.encode_team_ff = FF2(self.features, activation=self.activation)
            self.encode_opp_ff = FF2(self.features, activation=self.activation)
            self.value_opp_ff = AttentionPool(self.features, self.num_heads, self.activation)
        self.out_r = RecurrentCore(
            self.lstm_features, self.lstm_layers, self.use_lstm, self.activation
        )
        # Small initial outputs: the first policy is near mean 0, std 1 for every observation
        # (and, with kinds, near uniform over the kinds and the slots in view).
        small = nn.initializers.orthogonal(0.01)
        if not self.kinds:
            self.action_head = nn.Dense(2 * self.num_actions, kernel_init=small)
            return
        self.kind_head = nn.Dense(self.kinds, kernel_init=small)
        self.pointer_query = nn.Dense(self.kinds * self.features, kernel_init=small)
        self.pointer_key = nn.Dense(self.features)
        self.target_head = nn.Dense(4 * self.kinds, kernel_init=small)

    @nn.nowrap
    def initial_carry(self, batch_shape: Sequence[int]) -> PolicyCarry:
        """The zero memory for a batch of players with leading axes ``batch_shape``."""
        if not self.use_lstm:
            return ()
        zeros = jnp.zeros((*batch_shape, self.lstm_features), jnp.float32)
        return tuple(LSTMState(cell=zeros, hidden=zeros) for _ in range(self.lstm_layers))

    def embed(
        self, obs: Observation, visible_fraction: Capacity | None = None
    ) -> jax.Array:
        """The memoryless part: Observation with leading axes [...] -> f32[..., d] for out_r.
        See ``encode``."""
        return self.encode(obs, visible_fraction)[0]

    def encode(
        self, obs: Observation, visible_fraction: Capacity | None = None
    ) -> tuple[jax.Array, jax.Array | None]:
        """``embed``'s input for out_r f32[..., d], and (the parametrised head only) the keys
        its pointer attends with, ``pointer_key`` of the per-entity embeddings of the 2n - 1
        player slots, f32[..., 2n - 1, features] (zeros out of view when compacted).

        ``visible_fraction`` (attention only): run the per-entity layers (encode_team_ff,
        encode_opp_ff, value_opp_ff's value_ff) on the visible teammates and opponents only, at
        most that share of each group's slots (one fraction, or a (teammates, opponents) pair).
        The result equals the dense one (up to float rounding) when they fit, which
        ``visible_capacity_index`` checks; slots beyond the capacity would be dropped.
        """
        num_slots = obs.entities.shape[-2]  # 2n: n - 1 teammates, n opponents, the ball
        n = num_slots // 2
        players = obs.entities[..., : num_slots - 1, :]  # the ball slot is left out
        visible = obs.entity_mask[..., : num_slots - 1]
        if not self.use_attention:
            flat = jnp.where(visible[..., None], players, 0.0)
            flat = flat.reshape(*flat.shape[:-2], -1)
            return self.encode_ff(jnp.concatenate([obs.self_features, flat], axis=-1)), None
        own = self.encode_ff(obs.self_features)
        query = self.query_ff(own)
        if visible_fraction is not None:
            # Per-entity layers on the visible slots only (see visible_capacity_index).
            lead = visible.shape[:-1]
            rows = math.prod(lead)
            mask = visible.reshape(rows, num_slots - 1)
            compaction = visible_compaction(mask, entity_groups(n), visible_fraction)
            x = compaction.gather(players.reshape(rows, num_slots - 1, -1))
            embeddings = jnp.concatenate(
                [
                    self.encode_team_ff(compaction.group(x, 0)),
                    self.encode_opp_ff(compaction.group(x, 1)),
                ]
            )
            attended = self.value_opp_ff(query.reshape(rows, -1), embeddings, mask, compaction)
            x = jnp.concatenate([own, attended.reshape(*lead, -1)], axis=-1)
            if not self.kinds:
                return x, None
            compact_keys = self.pointer_key(embeddings)  # on the rows in view only
            return x, compaction.scatter(compact_keys).reshape(*visible.shape, -1)
        embeddings = jnp.concatenate(
            [
                self.encode_team_ff(players[..., : n - 1, :]),
                self.encode_opp_ff(players[..., n - 1 :, :]),
            ],
            axis=-2,
        )
        attended = self.value_opp_ff(query, embeddings, visible)
        keys = self.pointer_key(embeddings) if self.kinds else None
        return jnp.concatenate([own, attended], axis=-1), keys

    def head(
        self, y: jax.Array, keys: jax.Array | None = None, obs: Observation | None = None
    ) -> AnyPolicyOutput:
        """out_r's output f32[..., lstm_features] -> the action distribution's parameters. The
        parametrised head also takes ``encode``'s pointer keys and the observation (its mask);
        slots out of view get ``MASKED_LOGIT``."""
        if not self.kinds:
            out = self.action_head(y)
            return PolicyOutput(
                mean=out[..., : self.num_actions],
                log_std=clamp_log_std(out[..., self.num_actions :]),
            )
        assert keys is not None and obs is not None
        kinds, lead = self.kinds, y.shape[:-1]
        query = self.pointer_query(y).reshape(*lead, kinds, self.features)
        pointer_logits = jnp.einsum("...kf,...pf->...kp", query, keys) / math.sqrt(self.features)
        in_view = obs.entity_mask[..., : obs.entity_mask.shape[-1] - 1]
        target = self.target_head(y).reshape(*lead, kinds, 4)
        kind_logits = self.kind_head(y)
        if self.last_kind_logit:
            kind_logits = kind_logits.at[..., -1].add(self.last_kind_logit)
        if self.kind_mask:
            allowed = KIND_MASKS[self.kind_mask](obs)
            extra = kinds - allowed.shape[-1]
            if extra:
                allowed = jnp.concatenate(
                    [allowed, jnp.ones((*allowed.shape[:-1], extra), bool)], axis=-1)
            kind_logits = jnp.where(allowed, kind_logits, MASKED_LOGIT)
        return ParametrisedOutput(
            kind_logits=kind_logits,
            pointer_logits=jnp.where(in_view[..., None, :], pointer_logits, MASKED_LOGIT),
            pointer_mask=in_view,
            mean=target[..., :2],
            log_std=clamp_log_std(target[..., 2:]),
        )

    def __call__(
        self, carry: PolicyCarry, obs: Observation, reset: jax.Array
    ) -> tuple[PolicyCarry, AnyPolicyOutput]:
        """One step. obs: leading axes [...]; reset bool[...] zeroes the carry of those rows
        first (set it on the first step of an episode)."""
        x, keys = self.encode(obs)
        carry, y = self.out_r(carry, x, reset)
        return carry, self.head(y, keys, obs)

    def unroll(
        self,
        carry: PolicyCarry,
        obs_seq: Observation,
        reset_seq: jax.Array,
        time_axis: int = 0,
        visible_fraction: Capacity | None = None,
    ) -> tuple[PolicyCarry, AnyPolicyOutput]:
        """T steps: obs_seq with leading axes [T, ...], reset_seq bool[T, ...] ->
        (carry after step T, the output with leading axes [T, ...]). Equals T calls of
        ``__call__``.

        ``time_axis=1`` takes and returns batch-major sequences ([B, T, ...]; carry [B, ...]):
        only the small LSTM input and output are transposed for the scan, not the observations.
        ``visible_fraction``: see ``embed``.
        """
        if time_axis not in (0, 1):
            raise ValueError(f"time_axis={time_axis!r} is invalid: it must be 0 or 1")
        x, keys = self.encode(obs_seq, visible_fraction)
        if time_axis == 1:
            x, reset_seq = jnp.swapaxes(x, 0, 1), jnp.swapaxes(reset_seq, 0, 1)
        carry, y = self.out_r.sequence(carry, x, reset_seq)
        if time_axis == 1:
            y = jnp.swapaxes(y, 0, 1)
        return carry, self.head(y, keys, obs_seq)
