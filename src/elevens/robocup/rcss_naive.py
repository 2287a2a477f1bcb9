"""RcssNaiveTeam: the RoboCup naive team for the simulator with rcssserver's bodies.

The thesis's RoboCup naive team (section 6.7; ``elevens.robocup.naive.RoboCupNaiveTeam`` plays
it in rcssserver) as a pure-JAX ``TeamPolicy`` that gives the 12-value action of
``elevens.robocup.bodies.RcssSoccer``: every player chases the ball, turning towards it when it is
more than ``chase_tolerance`` off its body and dashing at it otherwise (softer as it comes
close, so it stops beside the ball), and kicks it at the centre of the opponent goal at full
power once it is within reach, in whatever direction the body points. So training with
``elevens train rcss-2v2`` (``elevens.robocup.sim``) can evaluate against a fixed team and mix
one into the opponents, as the simulator's own game does with ``naive``.

Its decisions are RoboCupNaiveTeam's with the thesis's 12-value action. What the server's see
timing forced on that team (remembering commanded turns between stale snapshots, no second
kick before a fresh see) is left out: the simulator's observation is fresh every step.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp

from elevens.env.state import Observation
from elevens.robocup.bodies import DASH, DEFAULT, KICK, TURN, Commands, encode_thesis12, rcss_field
from elevens.teams.scripted import BallMemory, Field, TeamView, _wrap, read_view

RCSS_FIELD = Field.of(rcss_field())
"""rcssserver's field and ball (``elevens.robocup.bodies.rcss_field``)."""


@dataclasses.dataclass(frozen=True)
class RcssNaiveTeam:
    """Chase the ball, kick it at the opponent goal centre (thesis 6.7), 12-value actions."""

    name: str = "rcss_naive"
    field: Field = RCSS_FIELD
    actions: int = 12
    """Action values it gives: the thesis's RoboCup action (``RcssSoccer``)."""
    kickable: float = DEFAULT.kickable_distance
    """Ball distance (m) at which it kicks: player_size + ball_size + kickable_margin."""
    kick_power: float = 100.0
    """Kick power, 0..100."""

    def on_field(self, field: Field) -> RcssNaiveTeam:
        """This team on ``field`` (``teams.registry.resolve_team``: rcssserver's by default)."""
        return dataclasses.replace(self, field=field)
    chase_tolerance: float = math.radians(15.0)
    """Turn towards the ball when its bearing exceeds this, else dash at it."""
    approach_distance: float = 2.5
    """Within kickable + this distance of the ball the dash power falls off linearly (down to
    ``min_dash_power``), so the player stops beside the ball instead of running past it."""
    min_dash_power: float = 0.3
    """The softest approach (fraction of full power): enough to catch a slowly rolling ball."""
    intercept: bool = False
    """Chase where the rolling ball can first be met (its course, decaying by the field's ball
    friction a cycle, against ``intercept_speed``) instead of where it is."""
    intercept_speed: float = 0.85
    """Metres a chasing player covers a cycle, for ``intercept``."""
    intercept_horizon: int = 40
    """Cycles of the ball's course searched for a meeting point."""
    search_turn: float = 60.0
    """Turn (degrees, clockwise) per step while nobody on the team knows where the ball is."""
    memory_steps: int = 20
    """Steps a ball nobody sees is followed from its last sighting."""

    def init_carry(self, players_per_team: int) -> BallMemory:
        return BallMemory.empty(players_per_team)

    def act(
        self, params: object, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        """obs: one team's Observation [n] -> (BallMemory, actions f32[n, 12])."""
        view, carry = read_view(obs, carry, self.field, True, self.memory_steps)
        return carry, self.play(view, carry.velocity)

    def play(self, view: TeamView, ball_velocity: jax.Array) -> jax.Array:
        """What each player does, from the team's view and the ball's velocity f32[n, 2]
        (``BallMemory.velocity``): f32[n, 12]."""
        offset = view.ball - view.position
        distance = jnp.linalg.norm(offset, axis=-1)
        target = self.meeting_points(view.ball, ball_velocity, view.position) if (
            self.intercept
        ) else view.ball
        to_target = target - view.position
        to_ball = _wrap(jnp.arctan2(to_target[:, 1], to_target[:, 0]) - view.heading)
        goal = jnp.array([self.field.half_length, 0.0])
        to_goal_offset = goal - view.position
        to_goal = _wrap(jnp.arctan2(to_goal_offset[:, 1], to_goal_offset[:, 0]) - view.heading)

        can_kick = view.knows_ball & (distance <= self.kickable)
        chase_turn = view.knows_ball & ~can_kick & (jnp.abs(to_ball) > self.chase_tolerance)
        kind = jnp.where(
            can_kick, KICK, jnp.where(chase_turn | ~view.knows_ball, TURN, DASH)
        )
        power = jnp.clip(
            (distance - self.kickable) / self.approach_distance, self.min_dash_power, 1.0
        )
        # Server directions are clockwise: -degrees of the counter-clockwise angle.
        turn_moment = jnp.where(
            view.knows_ball, -jnp.degrees(to_ball), jnp.full_like(to_ball, self.search_turn)
        )
        commands = Commands(
            kind=kind,
            dash_power=100.0 * power,
            dash_direction=-jnp.degrees(to_ball),
            kick_power=jnp.full_like(power, self.kick_power),
            kick_direction=-jnp.degrees(to_goal),
            turn_moment=jnp.clip(turn_moment, -180.0, 180.0),
        )
        return encode_thesis12(commands)

    def meeting_points(
        self, ball: jax.Array, velocity: jax.Array, position: jax.Array
    ) -> jax.Array:
        """Where each player can first reach the rolling ball (f32[n, 2], team frame): the
        first cycle of its course within ``intercept_speed`` a cycle (plus kicking reach), or
        the course's end within the horizon."""
        decay = self.field.ball_friction
        cycles = jnp.arange(1, self.intercept_horizon + 1, dtype=jnp.float32)
        travelled = (1.0 - decay**cycles) / (1.0 - decay)  # [H] the course's geometric sum
        course = ball[:, None, :] + travelled[None, :, None] * velocity[:, None, :]  # [n, H, 2]
        extent = jnp.array([self.field.half_length, self.field.half_width])
        course = jnp.clip(course, -extent, extent)
        gap = jnp.linalg.norm(course - position[:, None, :], axis=-1)
        reach = gap <= self.intercept_speed * cycles + self.kickable
        first = jnp.where(jnp.any(reach, axis=1), jnp.argmax(reach, axis=1), cycles.size - 1)
        return jnp.take_along_axis(course, first[:, None, None], axis=1)[:, 0]
