"""Motion, ball contacts, friction, walls, goals and respawn (SPEC.md). Pure, shape-static JAX."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import EnvParams, formation
from elevens.env.state import State

TWO_PI = 2 * np.pi


def wrap_angle(angle: jax.Array) -> jax.Array:
    """Wrap radians to ``[-pi, pi)``."""
    return (angle + np.pi) % TWO_PI - np.pi


def team_signs(params: EnvParams) -> np.ndarray:
    """``f32[2n]``: +1 for team 0 players, -1 for team 1 (the point reflection of the frame)."""
    n = params.players_per_team
    return np.repeat(np.array([1.0, -1.0], np.float32), n)


def clamp_to_field(positions: jax.Array, params: EnvParams) -> jax.Array:
    """Clamp ``f32[..., 2]`` centres to the playing area."""
    extent = jnp.stack([jnp.asarray(params.half_length), jnp.asarray(params.half_width)])
    return jnp.clip(positions, -extent, extent)


def move_players(
    positions: jax.Array, headings: jax.Array, actions: jax.Array, params: EnvParams
) -> tuple[jax.Array, jax.Array]:
    """Turn, then move along the new heading, then clamp.

    positions f32[2n, 2], headings f32[2n], actions f32[2n, 2] in [-1, 1] -> (positions, headings).
    Positive ``rot`` turns clockwise (towards decreasing heading).
    """
    move, rot = actions[:, 0], actions[:, 1]
    new_headings = wrap_angle(headings - params.turn_speed * rot)
    step = params.move_speed * move[:, None]
    direction = jnp.stack([jnp.cos(new_headings), jnp.sin(new_headings)], axis=-1)
    new_positions = clamp_to_field(positions + step * direction, params)
    return new_positions, new_headings


class Contacts(NamedTuple):
    """Ball contacts of one step."""

    impulse: jax.Array  # f32[2] summed velocity change of the ball
    kicks: jax.Array  # bool[2n]
    pushes: jax.Array  # bool[2n]


def ball_contacts(
    positions: jax.Array, headings: jax.Array, ball_position: jax.Array, params: EnvParams
) -> Contacts:
    """Body pushes and leg kicks of every player on the ball (after players moved)."""
    offset = ball_position[None, :] - positions  # f32[2n, 2]
    distance = jnp.sqrt(jnp.sum(offset * offset, axis=-1))
    facing = jnp.stack([jnp.cos(headings), jnp.sin(headings)], axis=-1)
    # A ball exactly on a player's centre is pushed along the player's heading.
    safe = distance > 1e-6
    away = jnp.where(safe[:, None], offset / jnp.where(safe, distance, 1.0)[:, None], facing)
    pushes = distance < params.player_radius + params.ball_radius
    # The leg line runs through the centre, perpendicular to the heading: the ball's distance to
    # it is the ball's offset along the heading.
    along_heading = jnp.sum(offset * facing, axis=-1)
    kicks = (distance < params.player_radius + params.leg_reach) & (
        jnp.abs(along_heading) <= params.kick_band
    )
    impulse = params.push_impulse * jnp.sum(jnp.where(pushes[:, None], away, 0.0), axis=0)
    impulse += params.kick_impulse * jnp.sum(jnp.where(kicks[:, None], facing, 0.0), axis=0)
    return Contacts(impulse=impulse, kicks=kicks, pushes=pushes)


def cap_speed(velocity: jax.Array, max_speed: jax.Array | float) -> jax.Array:
    """Scale ``f32[..., 2]`` down to at most ``max_speed`` (each vector on its own)."""
    speed = jnp.sqrt(jnp.sum(velocity * velocity, axis=-1, keepdims=True))
    return velocity * jnp.minimum(1.0, max_speed / jnp.maximum(speed, 1e-12))


class BallUpdate(NamedTuple):
    position: jax.Array  # f32[2]
    velocity: jax.Array  # f32[2]
    goals: jax.Array  # i32[2] 1 for the team that scored


def roll_ball(position: jax.Array, velocity: jax.Array, params: EnvParams) -> BallUpdate:
    """Move the ball one step, apply friction, then score a goal or bounce off the walls."""
    new_position = position + velocity
    new_velocity = velocity * params.ball_friction
    speed = jnp.sqrt(jnp.sum(new_velocity * new_velocity))
    new_velocity = jnp.where(speed < params.ball_stop_speed, 0.0, new_velocity)

    half_length, half_width = params.half_length, params.half_width
    x, y = new_position[0], new_position[1]
    # y where the centre crossed the goal line, so a fast ball near a post is judged fairly.
    crossed_line = jnp.abs(x) > half_length
    line_x = jnp.sign(x) * half_length
    safe_vx = jnp.where(velocity[0] == 0, 1.0, velocity[0])
    fraction = jnp.clip((line_x - position[0]) / safe_vx, 0.0, 1.0)
    crossing_y = position[1] + fraction * velocity[1]
    in_mouth = jnp.abs(crossing_y) <= params.goal_width / 2
    is_goal = crossed_line & in_mouth
    goals = jnp.stack([is_goal & (x > 0), is_goal & (x < 0)]).astype(jnp.int32)

    bounce_x = crossed_line & ~in_mouth
    bounce_y = jnp.abs(y) > half_width
    bounced = bounce_x | bounce_y
    flip = jnp.stack([jnp.where(bounce_x, -1.0, 1.0), jnp.where(bounce_y, -1.0, 1.0)])
    new_velocity = new_velocity * flip * jnp.where(bounced, params.wall_restitution, 1.0)
    new_position = jnp.where(
        is_goal,
        new_position,
        jnp.clip(new_position, jnp.stack([-half_length, -half_width]),
                 jnp.stack([half_length, half_width])),
    )
    return BallUpdate(position=new_position, velocity=new_velocity, goals=goals)


class Spawn(NamedTuple):
    positions: jax.Array  # f32[2n, 2]
    headings: jax.Array  # f32[2n]
    ball_position: jax.Array  # f32[2]


def spawn(key: jax.Array, params: EnvParams) -> Spawn:
    """Kick-off positions for everyone, drawn in each team's own frame (so sides are symmetric).

    Formation: slot + U(+-spawn_noise) per axis, clamped to the own half, heading towards the
    opponent goal + U(+-heading_noise). Random: uniform in the own half, uniform heading.
    """
    n = params.players_per_team
    # One draw for everything: each threefry call is a loop of its own on CPU, and this runs for
    # every game at every step (vmap turns the respawn into a select).
    draw = jax.random.uniform(key, (2 * n * 3 + 2,), minval=-1.0, maxval=1.0)
    player_unit = draw[: 4 * n].reshape(2, n, 2)  # U(-1, 1)
    heading_unit = draw[4 * n : 6 * n].reshape(2, n)
    ball_unit = draw[6 * n :]
    half_length, half_width = params.half_length, params.half_width
    extent = jnp.stack([jnp.asarray(half_length), jnp.asarray(half_width)])
    if params.spawn == "formation":
        scale = extent / jnp.array([50.0, 35.0])
        slots = jnp.asarray(formation(n), jnp.float32) * scale
        team_frame = slots[None] + params.spawn_noise * player_unit
        heading_offset = params.heading_noise * heading_unit
    else:
        team_frame = jnp.stack(
            [-half_length * (player_unit[..., 0] + 1) / 2, half_width * player_unit[..., 1]],
            axis=-1,
        )
        heading_offset = np.pi * heading_unit
    team_frame = jnp.clip(team_frame, jnp.stack([-half_length, -half_width]),
                          jnp.stack([jnp.zeros_like(half_length), half_width]))
    # Team 1 is the point reflection of team 0: negate positions, turn headings by pi.
    reflect = jnp.array([1.0, -1.0])[:, None, None]
    positions = (team_frame * reflect).reshape(2 * n, 2)
    headings = wrap_angle(heading_offset + jnp.array([0.0, np.pi])[:, None]).reshape(2 * n)

    if params.ball_spawn == "centre":
        ball_position = jnp.zeros(2)
    else:
        ball_position = params.ball_spawn_fraction * extent * ball_unit
    return Spawn(positions=positions, headings=headings, ball_position=ball_position)


def initial_state(key: jax.Array, params: EnvParams) -> State:
    """A fresh episode: everyone at kick-off positions, score 0, step 0."""
    placed = spawn(key, params)
    num_players = params.num_players
    return State(
        positions=placed.positions,
        headings=placed.headings,
        velocities=jnp.zeros((num_players, 2)),
        last_actions=jnp.zeros((num_players, 2)),
        start_positions=placed.positions,
        ball_position=placed.ball_position,
        ball_velocity=jnp.zeros(2),
        score=jnp.zeros(2, jnp.int32),
        step=jnp.zeros((), jnp.int32),
        last_touch=jnp.asarray(-1, jnp.int32),
    )
