"""When to switch the reward shaping off (thesis section 4.2).

The shaped reward r = g + 0.1 b + 0.05 a (eq. 4.1) only helps the first steps of learning: "Once
the players score at least one goal in more than 75% of the games, the reward shaping is
removed. From that point on the players rely only on the g term." This module keeps that
schedule as a small jittable state; the env reads the result through the shaping weights of
``EnvParams`` (``ball_shaping_weight``, ``approach_shaping_weight``), which are pytree leaves, so
switching off costs no recompile.

Conventions:

* The statistic is over the learning team's last K games (K = 100 by default; the thesis does not
  name a window), each counting 1 if the team scored at least one goal in it.
* The switch can only fire once the window is full (K games recorded), so that a lucky first few
  games cannot end shaping early.
* "More than 75%" is strict: with K = 100, 76 scoring games switch it off and 75 do not.
* Off is for good: later windows with fewer goals never switch shaping back on.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct
from jax.typing import ArrayLike

from elevens.train.opponents import ring_record

SHAPING_WINDOW = 100
"""K: recent games the scoring rate is measured over (not given in the thesis)."""
SHAPING_THRESHOLD = 0.75
"""Shaping goes off when the scoring rate is above this (section 4.2: "more than 75%")."""


class ShapingState(struct.PyTreeNode):
    """The shaping schedule. K = window length."""

    active: jax.Array
    """``bool[]``: True while the shaped reward is on."""
    recent: jax.Array
    """``f32[K]`` ring of the last K games' flags: 1.0 if the learning team scored in it."""
    count: jax.Array
    """``i32[]`` games recorded so far (not capped at K)."""
    index: jax.Array
    """``i32[]`` next ring slot to write."""

    @property
    def window(self) -> int:
        return int(self.recent.shape[0])


def shaping_init(window: int = SHAPING_WINDOW) -> ShapingState:
    """Shaping on, no games recorded."""
    if window < 1:
        raise ValueError(f"window={window!r} is invalid: it must be >= 1")
    return ShapingState(
        active=jnp.asarray(True),
        recent=jnp.zeros((window,), jnp.float32),
        count=jnp.asarray(0, jnp.int32),
        index=jnp.asarray(0, jnp.int32),
    )


def shaping_scoring_rate(state: ShapingState) -> jax.Array:
    """``f32[]`` fraction of the recorded recent games (at most K) in which the team scored."""
    played = jnp.minimum(state.count, state.window)
    return jnp.sum(state.recent) / jnp.maximum(played, 1).astype(jnp.float32)


def shaping_update(
    state: ShapingState,
    scored_flags: ArrayLike,
    threshold: ArrayLike = SHAPING_THRESHOLD,
    mask: ArrayLike | None = None,
) -> ShapingState:
    """Record a batch of finished games and switch shaping off for good if it is time.

    Args:
        state: the schedule.
        scored_flags: ``bool[G]``: did the learning team score at least one goal in game g.
            Games are appended in batch order; only the last K count.
        threshold: the switch fires when the scoring rate over a FULL window is > threshold.
        mask: optional ``bool[G]``: False for games to ignore.
    """
    flags = jnp.asarray(scored_flags).astype(jnp.float32).reshape(-1)
    ring = ring_record(
        state.recent[None, :],
        state.index[None],
        jnp.zeros(flags.shape, jnp.int32),
        flags,
        None if mask is None else jnp.asarray(mask, bool).reshape(-1),
    )
    recorded = state.replace(
        recent=ring.buffers[0], index=ring.write_index[0], count=state.count + ring.added[0]
    )
    full = recorded.count >= recorded.window
    switch_off = full & (shaping_scoring_rate(recorded) > threshold)
    return recorded.replace(active=state.active & jnp.logical_not(switch_off))


class ShapingWeights(NamedTuple):
    """Shaping weights to put into ``EnvParams``; ``f32[]`` each."""

    ball: jax.Array
    """-> ``EnvParams.ball_shaping_weight`` (w_b, 0.1 in eq. 4.1), 0 once shaping is off."""
    approach: jax.Array
    """-> ``EnvParams.approach_shaping_weight`` (w_a, 0.05 in eq. 4.1), 0 once shaping is off."""
    possession: jax.Array
    """-> ``EnvParams.possession_shaping_weight`` (w_p, not in the thesis), 0 once off."""


def shaping_weights(
    state: ShapingState,
    base_ball_weight: ArrayLike,
    base_approach_weight: ArrayLike,
    base_possession_weight: ArrayLike = 0.0,
) -> ShapingWeights:
    """The base weights while shaping is active, 0 after.

    Use: ``w = shaping_weights(s, 0.1, 0.05)``;
    ``params.replace(ball_shaping_weight=w.ball, approach_shaping_weight=w.approach)``.
    """
    return ShapingWeights(
        ball=jnp.where(state.active, jnp.asarray(base_ball_weight, jnp.float32), 0.0),
        approach=jnp.where(state.active, jnp.asarray(base_approach_weight, jnp.float32), 0.0),
        possession=jnp.where(
            state.active, jnp.asarray(base_possession_weight, jnp.float32), 0.0
        ),
    )
