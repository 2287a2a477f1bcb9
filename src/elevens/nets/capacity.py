"""The update's cheaper policy pass: per-entity layers on the visible slots only.

With a 180 degree view about half of a player's teammate and opponent slots are empty, so the
policy's per-entity layers (``AttentionPolicy.embed``) can run on a compacted set of rows. Each
minibatch takes the smallest capacity of ``VISIBLE_FRACTIONS`` that holds every visible entity of
its observations, or the dense pass where none does: the same result either way, at less cost
(docs/results/throughput.md). The learner sees only ``value_and_grad``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax

from elevens.env.state import Observation
from elevens.nets.attention import Capacity
from elevens.nets.policy import visible_capacity_index

VISIBLE_FRACTIONS: tuple[Capacity, ...] = ((0.54, 0.69), (0.6, 0.7), (0.6, 0.75), (0.7, 0.8))
"""Capacities (shares of the teammate slots and of the opponent slots) tried in turn. The
first holds about 88% of an 11 v 11 policy's minibatches; the others keep trained policies,
which look at more players, off the dense pass (docs/results/throughput.md)."""

MIN_PLAYERS_TO_COMPACT = 4
"""Below this many players a side the per-entity layers are too small a share of the update
for compaction to pay for its gathers and its extra compiled branches."""


def compacts(use_attention: bool, players_per_team: int) -> bool:
    """Whether the update compacts for these networks and this team size."""
    return use_attention and players_per_team >= MIN_PLAYERS_TO_COMPACT


def value_and_grad(
    loss_fn: Callable[..., tuple[jax.Array, Any]],
    observations: Callable[[Any], Observation],
    enabled: bool,
) -> Callable[[Any, Any], Any]:
    """``jax.value_and_grad(loss_fn, has_aux=True)`` that runs the policy on the smallest
    capacity holding the minibatch's visible entities. ``loss_fn(params, batch,
    visible_fraction=None)`` takes the capacity as a keyword (None: dense);
    ``observations(batch)`` gives the batch's policy observations. Only the branch taken is
    computed (``lax.switch``)."""
    fractions = VISIBLE_FRACTIONS if enabled else ()
    branches = [
        jax.value_and_grad(functools.partial(loss_fn, visible_fraction=fraction), has_aux=True)
        for fraction in (*fractions, None)
    ]
    if not fractions:
        return branches[0]

    def by_capacity(params: Any, batch: Any) -> Any:
        index = visible_capacity_index(observations(batch), fractions)
        return jax.lax.switch(index, branches, params, batch)

    return by_capacity
