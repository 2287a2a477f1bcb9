"""NetworkTeam: a trained policy behind the TeamPolicy interface, so it plays through the same
match code as the handcrafted teams."""

from __future__ import annotations

import dataclasses
from typing import Any, cast

import jax
import jax.numpy as jnp

from elevens.env.state import Observation
from elevens.nets.policy import AnyPolicyOutput, AttentionPolicy, PolicyCarry


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
    """True: play the mode (``tanh(mean)``; with the parametrised head the likeliest kind and
    slot too); False: sample from the policy's distribution."""
    name: str = "network"
    """Shown in match reports and tournaments."""
    self_features: int | None = None
    """The self features its networks read: the first ones of a game that gives more (a skill
    game with ``env.reach_features`` beside a team trained without); None: all."""

    @property
    def kinds(self) -> int:
        """The parametrised head's kinds (0: the Gaussian head), as its network has them."""
        return self.policy.kinds

    def init_carry(self, players_per_team: int) -> PolicyCarry:
        """Zero LSTM memory for the ``players_per_team`` players of one game."""
        return self.policy.initial_carry((players_per_team,))

    def act(
        self, params: Any, carry: PolicyCarry, obs: Observation, key: jax.Array
    ) -> tuple[PolicyCarry, jax.Array]:
        """obs: one team's Observation, leading axis [n] -> (carry, actions f32[n, 2] in (-1, 1);
        f32[n, 4] (kind, pointer, x, y) with the parametrised head).

        The carry is reset only by ``init_carry``: one match episode is one policy episode.
        """
        if self.self_features is not None:
            wanted = obs.self_features[..., : self.self_features]
            obs = dataclasses.replace(obs, self_features=wanted)
        no_reset = jnp.zeros(obs.self_features.shape[:-1], bool)
        carry, output = cast(
            tuple[PolicyCarry, AnyPolicyOutput], self.policy.apply(params, carry, obs, no_reset)
        )
        distribution = output.distribution()
        if self.deterministic:
            return carry, distribution.mode()
        return carry, distribution.sample(key).action
