"""Test teams shared by the team and match tests."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from elevens.env.state import Observation


@dataclasses.dataclass(frozen=True)
class StillTeam:
    """Stands still: an opponent that never moves (it still kicks a ball that meets its legs)."""

    name: str = "still"

    def init_carry(self, players_per_team: int) -> tuple[()]:
        return ()

    def act(
        self, params: object, carry: tuple[()], obs: Observation, key: jax.Array
    ) -> tuple[tuple[()], jax.Array]:
        return carry, jnp.zeros((obs.self_features.shape[0], 2))
