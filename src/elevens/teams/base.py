"""TeamPolicy: anything that picks a team's actions from that team's own observations.

A policy is pure and works on one game: ``act(params, carry, obs, key)`` takes the team's
Observation with leading axis ``[n]`` (see ``Observation.team``) and returns ``f32[n, 2]``
actions. Batch games with ``jax.vmap``. Carries hold recurrent memory (an LSTM's) and are pytrees.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import jax

from elevens.env.state import Observation

Carry = Any
Params = Any


@runtime_checkable
class TeamPolicy(Protocol):
    """The interface shared by handcrafted teams and trained networks."""

    @property
    def name(self) -> str:
        """A short name for tables and pictures."""
        ...

    def init_carry(self, players_per_team: int) -> Carry:
        """The memory at the start of an episode for a team of ``players_per_team``."""
        ...

    def act(
        self, params: Params, carry: Carry, obs: Observation, key: jax.Array
    ) -> tuple[Carry, jax.Array]:
        """obs: one team's Observation, leading axis [n] -> (carry, actions f32[n, 2])."""
        ...
