"""Recorded games as States, for drawing (`elevens play`, the run's GIF, replays)."""

from __future__ import annotations

import jax.numpy as jnp

from elevens.env import EnvParams, State
from elevens.eval.match import MatchRecord


def states_from_record(record: MatchRecord, game: int, params: EnvParams) -> State:
    """The per-step States ``[T, ...]`` of one recorded game, for drawing.

    The record keeps what pictures need; velocities and start points are not recorded, so they
    are zero here, and last actions come from the recorded actions.
    """
    positions = record.positions[game]
    steps = positions.shape[0]
    num_players = positions.shape[1]
    return State(
        positions=positions,
        headings=record.headings[game],
        velocities=jnp.zeros_like(positions),
        last_actions=record.actions[game].reshape(steps, num_players, 2),
        start_positions=jnp.broadcast_to(positions[:1], positions.shape),
        ball_position=record.ball_position[game],
        ball_velocity=record.ball_velocity[game],
        score=record.score[game],
        step=jnp.arange(steps, dtype=jnp.int32),
    )
