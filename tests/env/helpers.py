"""Hand-built states for exact-event tests."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import elevens
from elevens.env import EnvParams, Soccer, State


def far_away(num_players: int) -> np.ndarray:
    """Positions that keep players away from a ball near the centre: along the side lines."""
    xs = np.linspace(-45.0, 45.0, num_players)
    return np.stack([xs, np.full(num_players, -34.0)], axis=-1)


def build_state(
    params: EnvParams,
    positions: np.ndarray | None = None,
    headings: np.ndarray | None = None,
    ball_position: tuple[float, float] = (0.0, 0.0),
    ball_velocity: tuple[float, float] = (0.0, 0.0),
    step: int = 0,
) -> State:
    """A State with everyone far from the ball unless positions are given; heading +y."""
    num_players = params.num_players
    positions = far_away(num_players) if positions is None else np.asarray(positions)
    headings = np.full(num_players, np.pi / 2) if headings is None else np.asarray(headings)
    return State(
        positions=jnp.asarray(positions, jnp.float32),
        headings=jnp.asarray(headings, jnp.float32),
        velocities=jnp.zeros((num_players, 2)),
        last_actions=jnp.zeros((num_players, 2)),
        start_positions=jnp.asarray(positions, jnp.float32),
        ball_position=jnp.asarray(ball_position, jnp.float32),
        ball_velocity=jnp.asarray(ball_velocity, jnp.float32),
        score=jnp.zeros(2, jnp.int32),
        step=jnp.asarray(step, jnp.int32),
    )


def make_env(players: int = 1, **overrides) -> tuple[Soccer, EnvParams]:  # type: ignore[no-untyped-def]
    return elevens.make(f"{players}v{players}", **overrides)


def zero_actions(players: int) -> jax.Array:
    return jnp.zeros((2, players, 2), jnp.float32)
