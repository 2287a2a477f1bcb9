"""TeamPolicy: anything that picks a team's actions from that team's own observations.

A policy is pure and works on one game: ``act(params, carry, obs, key)`` takes the team's
Observation with leading axis ``[n]`` (see ``Observation.team``) and returns ``f32[n, 2]``
actions. Batch games with ``jax.vmap``. Carries hold recurrent memory (an LSTM's) and are pytrees.
"""

from __future__ import annotations

import dataclasses
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


@dataclasses.dataclass(frozen=True, eq=False)
class Team:
    """A team ready to play: a TeamPolicy, its params and a label."""

    name: str
    """Label for tables and plots."""
    policy: TeamPolicy
    """Hashable (it is static to the compiled match)."""
    params: Any = None
    """The policy's params (None for the handcrafted teams)."""
    trained_players: int | None = None
    """Players per team the checkpoint trained with (None for handcrafted teams)."""
    size_dependent: bool = False
    """True if the params only fit a team of ``trained_players`` (the feedforward ablation)."""
    spec: str = ""
    """The spec it was loaded from."""
    field: tuple[float, float, float] | None = None
    """(field_length, field_width, goal_width) the checkpoint trained on; None for the
    handcrafted teams, which play on any field they are told."""

    actions: int = 2
    """Action values its policy gives: 2, the simulator's (move, rot); 12, the thesis's
    12-value action (a game above the core that takes it); 4, a parametrised action
    (kind, pointer, x, y)."""

    def check_size(self, players_per_team: int, actions: int = 2) -> None:
        """Raise ``ValueError`` unless the team can play ``players_per_team`` a side in a game
        that takes ``actions`` action values (2: the simulator's own game)."""
        if self.actions != actions:
            if actions == 2 and self.actions == 12:
                raise ValueError(
                    f"team {self.name!r} ({self.spec}) gives the thesis's {self.actions}-value "
                    "action, not the simulator's (move, rot): it plays the game it was made "
                    "for (a game above the core, e.g. the server's bodies), not this one"
                )
            raise ValueError(
                f"team {self.name!r} ({self.spec}) gives {self.actions} action values; this "
                f"game takes {actions}: use a team trained in it (network.actions {actions}) "
                "or one of its handcrafted teams"
            )
        if self.size_dependent and self.trained_players != players_per_team:
            raise ValueError(
                f"team {self.name!r} ({self.spec}) is a feedforward network (no attention) "
                f"trained with {self.trained_players} players a side; its first layer only fits "
                f"that team size, so it cannot play {players_per_team} a side"
            )
