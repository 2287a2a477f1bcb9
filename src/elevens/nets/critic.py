"""The critic network (thesis figure 5.1, table 6.2): a team's value from the full global state.

One team's forward pass, for ``n`` players a side (any ``n``: no parameter depends on it)::

    c = encode_ff(context)                                  # time, ball position and velocity
    q = query_ff(c)                                         # one attention query per team state
    e = [encode_team_ff(own players), encode_opp_ff(opponents)]    # f32[2n, 64]
    a = attention(q, value_ff([e, q]), mask)                # 4 heads of 16
    value = out_ff([c, a])                                  # scalar

The cost is linear in the number of players: every player is encoded once and scored once
against the single query (no pairwise terms; thesis section 5.2.10).

Players are split into the two encoders by position, not by the ``is_teammate`` column: the
global state lists the own team's ``n`` players first, then the ``n`` opponents
(``elevens.env.observe.global_state``), so static slices do it without encoding every player
twice. Whoever pads smaller teams to a larger shape must keep that order (own team in the first
half) and mask the padding rows with ``player_mask``.

``use_attention=False`` is the feedforward ablation of thesis section 6.4: the context and all
player rows, flattened, go through encode_ff and then out_ff (parameters then depend on n).
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from elevens.env.state import GlobalState
from elevens.nets.attention import FF2, Activation, AttentionPool


class AttentionCritic(nn.Module):
    """GlobalState with leading axes [...] (e.g. [2] for both teams of a game) -> value f32[...]."""

    features: int = 64
    """Width of every feedforward block and of the attention (table 6.1: 64)."""
    num_heads: int = 4
    """Attention heads, each of size features / num_heads = 16."""
    use_attention: bool = True
    """False: the feedforward ablation of section 6.4 (parameters then depend on n)."""
    activation: Activation = nn.relu
    """Non-linearity of the feedforward blocks."""

    @nn.compact
    def __call__(self, state: GlobalState, player_mask: jax.Array | None = None) -> jax.Array:
        """state: context f32[..., 5], players f32[..., 2n, 11] (own team first).
        player_mask: bool[..., 2n], True for real players (None: all). Returns f32[...]."""

        def ff(name: str) -> FF2:
            return FF2(self.features, activation=self.activation, name=name)

        players = state.players
        if player_mask is None:
            player_mask = jnp.ones(players.shape[:-1], bool)
        out_ff = FF2(
            self.features,
            out_features=1,
            activate_final=False,
            activation=self.activation,
            kernel_init_final=nn.initializers.orthogonal(1.0),
            name="out_ff",
        )
        if not self.use_attention:
            flat = jnp.where(player_mask[..., None], players, 0.0)
            flat = flat.reshape(*flat.shape[:-2], -1)
            encoded = ff("encode_ff")(jnp.concatenate([state.context, flat], -1))
            return out_ff(encoded)[..., 0]
        n = players.shape[-2] // 2
        context = ff("encode_ff")(state.context)
        query = ff("query_ff")(context)
        embeddings = jnp.concatenate(
            [
                ff("encode_team_ff")(players[..., :n, :]),
                ff("encode_opp_ff")(players[..., n:, :]),
            ],
            axis=-2,
        )
        attended = AttentionPool(self.features, self.num_heads, self.activation, name="value_ff")(
            query, embeddings, player_mask
        )
        return out_ff(jnp.concatenate([context, attended], axis=-1))[..., 0]
