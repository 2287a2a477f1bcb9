"""The policy network (thesis figure 5.2, table 6.2): attention over the entities a player sees,
a 2-layer LSTM for memory, and a tanh-squashed Gaussian over the two actions.

One player's forward pass, for a team of ``n`` (any ``n``: no parameter depends on it)::

    h = encode_ff(self_features)                        # own state, ball and time, f32[64]
    q = query_ff(h)                                     # the attention query, f32[64]
    e = [encode_team_ff(teammate slots), encode_opp_ff(opponent slots)]   # f32[2n - 1, 64]
    a = attention(q, value_opp_ff([e, q]), visible)     # 4 heads of 16, f32[64]
    y = out_r([h, a])                                   # 2 LSTM layers of 32 units
    mean, log_std = Dense(4)(y)                         # 2 actions (move, rot)

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

from collections.abc import Sequence
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp

from elevens.env.state import Observation
from elevens.nets.attention import FF2, Activation, AttentionPool
from elevens.nets.distributions import TanhGaussian, clamp_log_std

NUM_ACTIONS = 2
"""(move, rot)."""


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


def reset_carry(carry: PolicyCarry, reset: jax.Array) -> PolicyCarry:
    """Zero the memory of the rows where ``reset`` (bool[...]) is True; carry leaves f32[..., H]."""
    return jax.tree.map(lambda leaf: jnp.where(reset[..., None], 0.0, leaf), carry)


class RecurrentCore(nn.Module):
    """out_r: a stack of LSTM layers, or a feedforward block when ``use_lstm`` is False.

    (carry, x f32[..., d], reset bool[...]) -> (carry, y f32[..., lstm_features]). ``reset``
    zeroes the carry of those rows before it is used (the first step of an episode).
    """

    lstm_features: int = 32
    """LSTM units per layer (table 6.1: LSTM layer size 32)."""
    lstm_layers: int = 2
    """Stacked LSTM layers (table 6.2: out_r is a 2-layer LSTM)."""
    use_lstm: bool = True
    """False: a 2-layer feedforward block of lstm_features instead, with no memory."""
    activation: Activation = nn.relu
    """Non-linearity of the feedforward replacement."""

    @nn.compact
    def __call__(
        self, carry: PolicyCarry, x: jax.Array, reset: jax.Array
    ) -> tuple[PolicyCarry, jax.Array]:
        if not self.use_lstm:
            return carry, FF2(self.lstm_features, activation=self.activation, name="ff")(x)
        carry = reset_carry(carry, reset)
        new_carry = []
        for layer, state in enumerate(carry):
            cell = nn.OptimizedLSTMCell(self.lstm_features, name=f"lstm_{layer}")
            (c, h), x = cell((state.cell, state.hidden), x)
            new_carry.append(LSTMState(cell=c, hidden=h))
        return tuple(new_carry), x


class AttentionPolicy(nn.Module):
    """The policy of one player; leading axes of the inputs are free (players, games, time).

    ``__call__(carry, obs, reset) -> (carry, PolicyOutput)`` for one step, obs an Observation with
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

    def setup(self) -> None:
        self.encode_ff = FF2(self.features, activation=self.activation)
        if self.use_attention:
            self.query_ff = FF2(self.features, activation=self.activation)
            self.encode_team_ff = FF2(self.features, activation=self.activation)
            self.encode_opp_ff = FF2(self.features, activation=self.activation)
            self.value_opp_ff = AttentionPool(self.features, self.num_heads, self.activation)
        self.out_r = RecurrentCore(
            self.lstm_features, self.lstm_layers, self.use_lstm, self.activation
        )
        # Small initial outputs: the first policy is near mean 0, std 1 for every observation.
        self.action_head = nn.Dense(2 * NUM_ACTIONS, kernel_init=nn.initializers.orthogonal(0.01))

    @nn.nowrap
    def initial_carry(self, batch_shape: Sequence[int]) -> PolicyCarry:
        """The zero memory for a batch of players with leading axes ``batch_shape``."""
        if not self.use_lstm:
            return ()
        zeros = jnp.zeros((*batch_shape, self.lstm_features), jnp.float32)
        return tuple(LSTMState(cell=zeros, hidden=zeros) for _ in range(self.lstm_layers))

    def embed(self, obs: Observation) -> jax.Array:
        """The memoryless part: Observation with leading axes [...] -> f32[..., d] for out_r."""
        num_slots = obs.entities.shape[-2]  # 2n: n - 1 teammates, n opponents, the ball
        n = num_slots // 2
        players = obs.entities[..., : num_slots - 1, :]  # the ball slot is left out
        visible = obs.entity_mask[..., : num_slots - 1]
        if not self.use_attention:
            flat = jnp.where(visible[..., None], players, 0.0)
            flat = flat.reshape(*flat.shape[:-2], -1)
            return self.encode_ff(jnp.concatenate([obs.self_features, flat], axis=-1))
        own = self.encode_ff(obs.self_features)
        query = self.query_ff(own)
        embeddings = jnp.concatenate(
            [
                self.encode_team_ff(players[..., : n - 1, :]),
                self.encode_opp_ff(players[..., n - 1 :, :]),
            ],
            axis=-2,
        )
        attended = self.value_opp_ff(query, embeddings, visible)
        return jnp.concatenate([own, attended], axis=-1)

    def head(self, y: jax.Array) -> PolicyOutput:
        """out_r's output f32[..., lstm_features] -> the action distribution's parameters."""
        out = self.action_head(y)
        return PolicyOutput(
            mean=out[..., :NUM_ACTIONS], log_std=clamp_log_std(out[..., NUM_ACTIONS:])
        )

    def __call__(
        self, carry: PolicyCarry, obs: Observation, reset: jax.Array
    ) -> tuple[PolicyCarry, PolicyOutput]:
        """One step. obs: leading axes [...]; reset bool[...] zeroes the carry of those rows
        first (set it on the first step of an episode)."""
        carry, y = self.out_r(carry, self.embed(obs), reset)
        return carry, self.head(y)

    def unroll(
        self,
        carry: PolicyCarry,
        obs_seq: Observation,
        reset_seq: jax.Array,
        time_axis: int = 0,
    ) -> tuple[PolicyCarry, PolicyOutput]:
        """T steps: obs_seq with leading axes [T, ...], reset_seq bool[T, ...] ->
        (carry after step T, PolicyOutput with leading axes [T, ...]). Equals T calls of
        ``__call__``.

        ``time_axis=1`` takes and returns batch-major sequences ([B, T, ...]; carry [B, ...]):
        only the small LSTM input and output are transposed for the scan, not the observations.
        """
        if time_axis not in (0, 1):
            raise ValueError(f"time_axis={time_axis!r} is invalid: it must be 0 or 1")
        x = self.embed(obs_seq)
        if time_axis == 1:
            x, reset_seq = jnp.swapaxes(x, 0, 1), jnp.swapaxes(reset_seq, 0, 1)
        scan = nn.scan(
            lambda core, carry, inputs: core(carry, *inputs),
            variable_broadcast="params",
            split_rngs={"params": False},
        )
        carry, y = scan(self.out_r, carry, (x, reset_seq))
        if time_axis == 1:
            y = jnp.swapaxes(y, 0, 1)
        return carry, self.head(y)
