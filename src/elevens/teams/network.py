"""NetworkTeam: a trained policy behind the TeamPolicy interface, so it plays through the same
match code as the handcrafted teams."""

from __future__ import annotations

import dataclasses
from typing import Any, cast

import jax
import jax.numpy as jnp

from elevens.env.state import Observation
from elevens.nets.policy import AttentionPolicy, PolicyCarry, PolicyOutput


@dataclasses.dataclass(frozen=True)
class NetworkTeam:
    """Every player of a team runs ``policy`` (shared weights) on its own observation.

    Frozen and hashable: match code passes teams as static arguments to ``jax.jit``. The
    network's variables (``{"params": ...}`` as returned by ``policy.init``) are the ``params``
    argument of ``act``, so new weights never recompile.
    """

    policy: AttentionPolicy = AttentionPolicy()
    """The network; its configuration must match the params passed to ``act``."""
    deterministic: bool = False
    """True: play the mode ``tanh(mean)``; False: sample from the tanh Gaussian."""
    name: str = "network"
    """Shown in match reports and tournaments."""

    def init_carry(self, players_per_team: int) -> PolicyCarry:
        """Zero LSTM memory for the ``players_per_team`` players of one game."""
        return self.policy.initial_carry((players_per_team,))

    def act(
        self, params: Any, carry: PolicyCarry, obs: Observation, key: jax.Array
    ) -> tuple[PolicyCarry, jax.Array]:
        """obs: one team's Observation, leading axis [n] -> (carry, actions f32[n, 2] in (-1, 1)).

        The carry is reset only by ``init_carry``: one match episode is one policy episode.
        """
        no_reset = jnp.zeros(obs.self_features.shape[:-1], bool)
        carry, output = cast(
            tuple[PolicyCarry, PolicyOutput], self.policy.apply(params, carry, obs, no_reset)
        )
        distribution = output.distribution()
        if self.deterministic:
            return carry, distribution.mode()
        return carry, distribution.sample(key).action
