"""Containers of the simulator: the game state, observations, the critic's state and step info.

Players sit on one leading axis, team 0 first: player ``k`` of team ``t`` is row ``t * n + k``.
All positions in ``State`` are in the world frame (team 0 attacks +x). Observations and the critic's
state are in each team's own frame (each team sees itself attacking +x).
"""

from __future__ import annotations

from typing import Any

import jax
from flax import struct

# Feature layouts. Tests, networks and adapters use these names rather than magic indices.
SELF_FEATURES = (
    "time_left",  # 1 at reset, 0 at the end of the episode
    "x", "y",  # own position / half field extents, team frame
    "cos_heading", "sin_heading",  # team frame
    "last_move", "last_rot",  # own previous action
    "start_x", "start_y",  # spawn point of the current play / half extents, team frame
    "ball_visible",  # 1 if the ball is in view; the ball features below are 0 otherwise
    "ball_distance",  # / field length
    "ball_cos_bearing", "ball_sin_bearing",  # bearing relative to the heading (+ = to the left)
    "ball_vel_forward", "ball_vel_left",  # ball velocity in the player's frame, m/step
)
ENTITY_FEATURES = (
    "distance",  # / field length
    "cos_bearing", "sin_bearing",  # relative to the observer's heading (+ = to the left)
    "vel_forward", "vel_left",  # velocity in the observer's frame, m/step
    "cos_rel_heading", "sin_rel_heading",  # other's heading minus own (0 for the ball)
    "last_move", "last_rot",  # other's last action (0 for the ball)
    "is_teammate",
    "is_ball",
)
CONTEXT_FEATURES = ("time_left", "ball_x", "ball_y", "ball_vx", "ball_vy")
PLAYER_FEATURES = (
    "x", "y",  # / half field extents
    "cos_heading", "sin_heading",
    "vx", "vy",  # m/step
    "last_move", "last_rot",
    "start_x", "start_y",  # / half field extents
    "is_teammate",
)
NUM_SELF_FEATURES = len(SELF_FEATURES)
NUM_ENTITY_FEATURES = len(ENTITY_FEATURES)
NUM_CONTEXT_FEATURES = len(CONTEXT_FEATURES)
NUM_PLAYER_FEATURES = len(PLAYER_FEATURES)


@struct.dataclass
class State:
    """The full game state, world frame. Build exact situations with ``state.replace(...)``."""

    positions: jax.Array  # f32[2n, 2] player centres, clamped to the field
    headings: jax.Array  # f32[2n] radians in [-pi, pi), 0 = +x, counter-clockwise positive
    velocities: jax.Array  # f32[2n, 2] displacement of each player in its last step
    last_actions: jax.Array  # f32[2n, 2] (move, rot) actually applied last step, after clipping
    start_positions: jax.Array  # f32[2n, 2] where each player spawned for the current play
    ball_position: jax.Array  # f32[2]
    ball_velocity: jax.Array  # f32[2] m/step
    score: jax.Array  # i32[2] goals of team 0 and team 1 this episode
    step: jax.Array  # i32[] steps taken this episode
    held_observation: Any = None
    """The observation the players act on in a game where they do not see every step (each
    player's last see); None where observations are fresh."""
    stamina: Any = None
    """Each player's stamina, in a game whose players tire (a pytree of that game's); None
    where players never tire."""
    last_touch: Any = None
    """i32[]: the team whose player touched the ball last since the kick-off (0 or 1), -1 for
    nobody (or both at once). Every reset sets it; a State built by hand may leave it None,
    and then the possession reward by touch is 0."""

    @property
    def num_players(self) -> int:
        return self.positions.shape[-2]


@struct.dataclass
class Observation:
    """What each player sees, in its team's frame. Leading axes ``[..., 2, n]`` (team, player).

    Entity slots, per observer: its ``n - 1`` teammates in index order, then the ``n`` opponents in
    index order, then the ball (slot ``2n - 1``). Features of invisible slots are zero and masked.
    """

    self_features: jax.Array  # f32[..., 2, n, NUM_SELF_FEATURES]
    entities: jax.Array  # f32[..., 2, n, 2n, NUM_ENTITY_FEATURES]
    entity_mask: jax.Array  # bool[..., 2, n, 2n] True where the entity is in view

    def team(self, team: int) -> Observation:
        """The observations of one team: leading axes ``[..., n]``."""
        return Observation(
            self_features=self.self_features[..., team, :, :],
            entities=self.entities[..., team, :, :, :],
            entity_mask=self.entity_mask[..., team, :, :],
        )


@struct.dataclass
class GlobalState:
    """The critic's full state from each team's own view. Leading axes ``[..., 2]`` (team)."""

    context: jax.Array  # f32[..., 2, NUM_CONTEXT_FEATURES]
    players: jax.Array  # f32[..., 2, 2n, NUM_PLAYER_FEATURES] own team first, then opponents


@struct.dataclass
class StepInfo:
    """What an analyst wants per step, beside the total reward."""

    goals: jax.Array  # i32[2] 1 for the team that scored this step
    kicks: jax.Array  # bool[2n] which players leg-kicked the ball this step
    pushes: jax.Array  # bool[2n] which players body-pushed the ball this step
    goal_reward: jax.Array  # f32[2, n] the goal term g
    ball_shaping: jax.Array  # f32[2, n] w_b * b (ball velocity towards the opponent goal)
    approach_shaping: jax.Array  # f32[2, n] w_a * a (player velocity towards the ball)
    possession_shaping: jax.Array  # f32[2, n] w_p * p (having the ball)
    holder: jax.Array  # f32[2] p: +1 for the team that has the ball, -1 for the other, else 0
    truncated: jax.Array  # bool[] the episode ran out of time this step

    @property
    def touches(self) -> jax.Array:
        """bool[2n]: who hit the ball this step (kick or push)."""
        return self.kicks | self.pushes
