"""Goal reward and the temporary shaping terms (SPEC.md, thesis eq. 4.1)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from elevens.env.params import EnvParams


class RewardTerms(NamedTuple):
    goal: jax.Array  # f32[2, n] g
    ball: jax.Array  # f32[2, n] w_b * b
    approach: jax.Array  # f32[2, n] w_a * a
    possession: jax.Array  # f32[2, n] w_p * p
    holder: jax.Array  # f32[2] p: +1 for the team that has the ball, -1 for the other, else 0

    @property
    def total(self) -> jax.Array:
        return self.goal + self.ball + self.approach + self.possession


def _unit(vector: jax.Array) -> jax.Array:
    norm = jnp.sqrt(jnp.sum(vector * vector, axis=-1, keepdims=True))
    return vector / jnp.maximum(norm, 1e-6)


def next_last_touch(last_touch: jax.Array, touches: jax.Array) -> jax.Array:
    """i32[]: ``State.last_touch`` after a step with ``touches`` bool[2n] (kicks or pushes,
    team 0's players first): the one team that touched the ball, -1 when both did (contested,
    as the match statistics count it), else unchanged. A goal's restart sets -1 itself."""
    n = touches.shape[0] // 2
    team0, team1 = jnp.any(touches[:n]), jnp.any(touches[n:])
    touched = jnp.where(team0 & team1, -1, jnp.where(team0, 0, jnp.where(team1, 1, last_touch)))
    return touched.astype(jnp.int32)


def ball_holder(
    ball_position: jax.Array,
    player_positions: jax.Array,
    params: EnvParams,
    last_touch: jax.Array | None = None,
) -> jax.Array:
    """f32[2]: +1 for the team that has the ball, -1 for the other, 0 when neither has it.

    ``params.possession_by`` "touch": the team that touched it last (``last_touch``, i32[];
    None: neither). "near": the team whose player nearest to it is within
    ``possession_radius`` and nearer than every opponent. Nearness needs no history but
    cannot tell control from crowding; the touch can. Zero-sum either way.
    """
    if params.possession_by == "touch":
        if last_touch is None:
            return jnp.zeros(2, jnp.float32)
        holds = jnp.stack([last_touch == 0, last_touch == 1])
    else:
        n = params.players_per_team
        gaps = jnp.sqrt(jnp.sum((player_positions - ball_position) ** 2, axis=-1)).reshape(2, n)
        nearest = jnp.min(gaps, axis=-1)
        holds = (nearest <= params.possession_radius) & (nearest < nearest[::-1])
    return holds.astype(jnp.float32) - holds[::-1].astype(jnp.float32)


def reward_terms(
    goals: jax.Array,
    ball_position: jax.Array,
    ball_velocity: jax.Array,
    player_velocities: jax.Array,
    ball_position_before: jax.Array,
    player_positions: jax.Array,
    params: EnvParams,
    last_touch: jax.Array | None = None,
) -> RewardTerms:
    """Per-player reward terms of one step.

    goals i32[2] (who scored), ball_position/ball_velocity f32[2] after the ball moved,
    player_velocities/player_positions f32[2n, 2] after the players moved, ball_position_before
    f32[2] (where the players chased it this step) -> RewardTerms of f32[2, n].
    """
    n = params.players_per_team
    goal_diff = (goals - goals[::-1]).astype(jnp.float32) * params.goal_reward  # f32[2]
    goal = jnp.broadcast_to(goal_diff[:, None], (2, n))

    opponent_goals = jnp.stack(
        [jnp.stack([params.half_length, 0.0]), jnp.stack([-params.half_length, 0.0])]
    )
    towards_goal = jnp.sum(ball_velocity * _unit(opponent_goals - ball_position), axis=-1)
    ball = jnp.broadcast_to((params.ball_shaping_weight * towards_goal)[:, None], (2, n))

    towards_ball = jnp.sum(
        player_velocities * _unit(ball_position_before - player_positions), axis=-1
    )
    approach = (params.approach_shaping_weight * towards_ball).reshape(2, n)

    holder = ball_holder(ball_position, player_positions, params, last_touch)
    possession = jnp.broadcast_to((params.possession_shaping_weight * holder)[:, None], (2, n))
    return RewardTerms(
        goal=goal, ball=ball, approach=approach, possession=possession, holder=holder
    )
