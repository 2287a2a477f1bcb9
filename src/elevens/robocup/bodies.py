"""rcssserver 19's body model in JAX: what one dash, turn or kick does in one cycle.

The simulator's own game (``physics``) is the thesis's: kinematic players and contact kicks.
The official server's players have velocity and inertia, take one body command a cycle, and
kick only a ball within reach, with a power that falls with the ball's distance and angle from
the body. Probes in rcssserver (docs/results/robocup.md) point to ball skills as what separates
an elevens team from helios-base; learning them by PPO needs a simulator whose kicks, dashes
and turns follow the server's. These are those rules, transcribed from rcssserver 19.0.0
(``src/player.cpp`` Player::kick and Player::turn, ``src/leg.cpp`` Leg::calcDashAccel,
``src/object.cpp`` MPObject::_inc) for the default player type, without the server's noise
(``player_rand``, ``ball_rand``, ``kick_rand``), and checked against a running server in
``tests/env/test_rcss.py``.

:class:`RcssSoccer` is the simulator's game with these bodies and the thesis's 12-value RoboCup
action (table 4.1; ``elevens.robocup.actions`` sends the same values to the server), so a
policy trained in it gives what an elevens team in rcssserver gives. Options bring in more of
the server's match: ``see_period`` (with 3 each player acts on its last see, as the bridge's
players do in the wide view), ``stamina`` (the server's stamina model with the elevens pacing
rule) and ``goalie`` (each goalie guards and catches as the elevens routines play it). Not
modelled: tackles, the referee (the ball bounces off the lines as in the simulator) and the
server's noise; collisions are resolved in one pass where the server repeats it while anything
still overlaps.

Frames: the simulator's world frame (metres, y up, headings in radians counter-clockwise).
Command arguments are the server's: powers 0..100 and directions in degrees, clockwise, relative
to the body, as ``elevens.robocup.protocol`` sends them. Pure functions of arrays (any leading
axes), jit- and vmap-safe.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from elevens.env import physics
from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer, applied_actions, finish_step
from elevens.env.state import SELF_FEATURES, Observation, State, StepInfo

__all__ = [
    "ACTION_SIZE",
    "Commands",
    "RcssParams",
    "RcssSoccer",
    "Stamina",
    "decode_thesis12",
    "encode_thesis12",
    "goalie_catch",
    "goalie_guard",
    "paced_power",
    "recover",
    "rcss_field",
    "advance",
    "atan2",
    "dash_acceleration",
    "dash_stamina",
    "collide",
    "kick_acceleration",
    "kick_power_factor",
    "kickable",
    "push",
    "turn",
]


class RcssParams(NamedTuple):
    """rcssserver 19.0.0 defaults (server.conf and player type 0)."""

    player_size: float = 0.3
    ball_size: float = 0.085
    kickable_margin: float = 0.7
    kick_power_rate: float = 0.027
    dash_power_rate: float = 0.006
    inertia_moment: float = 5.0
    player_decay: float = 0.4
    player_speed_max: float = 1.05
    player_accel_max: float = 1.0
    ball_decay: float = 0.94
    ball_speed_max: float = 3.0
    ball_accel_max: float = 2.7
    side_dash_rate: float = 0.4
    back_dash_rate: float = 0.7
    dash_angle_step: float = 1.0
    max_power: float = 100.0
    extra_stamina: float = 50.0
    stamina_max: float = 8000.0
    stamina_inc_max: float = 45.0
    stamina_capacity: float = 130600.0
    recover_dec_thr: float = 0.3
    recover_dec: float = 0.002
    recover_min: float = 0.5
    effort_dec_thr: float = 0.3
    effort_dec: float = 0.005
    effort_min: float = 0.6
    effort_inc_thr: float = 0.6
    effort_inc: float = 0.01

    @property
    def kickable_distance(self) -> float:
        """Ball centre to player centre within which a kick works (1.085 m)."""
        return self.player_size + self.ball_size + self.kickable_margin


DEFAULT = RcssParams()


def _unit(angle: jax.Array) -> jax.Array:
    return jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)


def atan2(y: jax.Array, x: jax.Array) -> jax.Array:
    """``jnp.arctan2`` for float32 (within 3e-7 rad of it, signed zeros alike), branch-free:
    an octant's reduction and Cephes' atanf polynomial. XLA's CPU backend runs jnp.arctan2
    unvectorised, several times dearer."""
    ax, ay = jnp.abs(x), jnp.abs(y)
    a = jnp.minimum(ax, ay) / jnp.maximum(jnp.maximum(ax, ay), np.float32(1e-30))  # [0, 1]
    big = a > np.float32(0.41421356)  # beyond tan(pi / 8): atan(a) = pi / 4 + atan(t)
    t = jnp.where(big, (a - 1.0) / (a + 1.0), a)
    z = t * t
    p = (((np.float32(8.05374449538e-2) * z - np.float32(1.38776856032e-1)) * z
          + np.float32(1.99777106478e-1)) * z - np.float32(3.33329491539e-1)) * z * t + t
    r = jnp.where(big, np.float32(np.pi / 4) + p, p)
    r = jnp.where(ay > ax, np.float32(np.pi / 2) - r, r)
    r = jnp.where(jnp.signbit(x), np.float32(np.pi) - r, r)
    return jnp.where(jnp.signbit(y), -r, r)


def _world_angle(body: jax.Array, direction_deg: jax.Array) -> jax.Array:
    """A command direction (degrees clockwise from the body) as a world angle (radians CCW)."""
    return body - jnp.deg2rad(direction_deg)


def dash_acceleration(
    power: jax.Array,
    direction_deg: jax.Array,
    body: jax.Array,
    effort: jax.Array | float = 1.0,
    params: RcssParams = DEFAULT,
) -> jax.Array:
    """``(dash power direction)``'s acceleration f32[..., 2] (before the player's accel cap).

    Power is clamped to [0, max_power] (v17+), the direction to [-180, 180] and rounded to
    dash_angle_step; sideways and backwards dashes push less (side_dash_rate at +-90 degrees,
    back_dash_rate at 180, linear between)."""
    power = jnp.clip(power, 0.0, params.max_power)
    direction = jnp.clip(direction_deg, -180.0, 180.0)
    direction = params.dash_angle_step * jnp.round(direction / params.dash_angle_step)
    off = jnp.abs(direction)
    rate = jnp.where(
        off > 90.0,
        params.back_dash_rate
        - (params.back_dash_rate - params.side_dash_rate) * (1.0 - (off - 90.0) / 90.0),
        params.side_dash_rate + (1.0 - params.side_dash_rate) * (1.0 - off / 90.0),
    )
    magnitude = jnp.abs(effort * power * jnp.clip(rate, 0.0, 1.0) * params.dash_power_rate)
    return magnitude[..., None] * _unit(_world_angle(body, direction))


def dash_stamina(
    power: jax.Array, stamina: jax.Array, params: RcssParams = DEFAULT
) -> tuple[jax.Array, jax.Array]:
    """(the power a dash can pay for, the stamina left): a dash costs its power, and a player
    with less stamina (plus extra_stamina) dashes only as hard as it can pay."""
    power = jnp.clip(power, 0.0, params.max_power)
    paid = jnp.minimum(power, stamina + params.extra_stamina)
    return paid, jnp.maximum(0.0, stamina - paid)


STAMINA_RESERVE = 3000.0
"""Stamina an elevens player keeps for itself: above it a player dashes as its policy asks
(``elevens.robocup.rules.pace_dashes``, the rule every elevens team plays the server with)."""
HALF_CYCLES = 3000
"""server::half_time x 10: each half restores the players' stamina capacity."""


@struct.dataclass
class Stamina:
    """Each player's stamina as rcssserver keeps it (``Player::updateStamina``), f32[2n]."""

    stamina: jax.Array
    effort: jax.Array
    recovery: jax.Array
    capacity: jax.Array

    @classmethod
    def full(cls, num_players: int, params: RcssParams = DEFAULT) -> Stamina:
        ones = jnp.ones(num_players, jnp.float32)
        return cls(
            stamina=params.stamina_max * ones, effort=ones, recovery=ones,
            capacity=params.stamina_capacity * ones,
        )


def paced_power(
    power: jax.Array, stamina: Stamina, cycle: jax.Array
) -> jax.Array:
    """The elevens routines' stamina rule (``elevens.robocup.rules.pace_dashes``): a dash
    spends the stamina above ``STAMINA_RESERVE`` freely and, beyond it, the capacity spread
    evenly over the cycles left in the half."""
    cycles_left = HALF_CYCLES - jnp.mod(cycle, HALF_CYCLES)
    spare = jnp.maximum(stamina.stamina - STAMINA_RESERVE, 0.0) + stamina.capacity / cycles_left
    return jnp.minimum(power, spare)


def recover(stamina: Stamina, params: RcssParams = DEFAULT) -> Stamina:
    """The end of a cycle (``Player::updateStamina``): recovery and effort fall while the
    stamina is low, effort comes back while it is high, and recovery x stamina_inc_max flows
    from the capacity into the stamina."""
    top = params.stamina_max
    low_recovery = stamina.stamina <= params.recover_dec_thr * top
    recovery = jnp.where(
        low_recovery, jnp.maximum(stamina.recovery - params.recover_dec, params.recover_min),
        stamina.recovery,
    )
    effort = jnp.where(
        stamina.stamina <= params.effort_dec_thr * top,
        jnp.maximum(stamina.effort - params.effort_dec, params.effort_min),
        stamina.effort,
    )
    effort = jnp.where(
        stamina.stamina >= params.effort_inc_thr * top,
        jnp.minimum(effort + params.effort_inc, 1.0),
        effort,
    )
    gain = jnp.minimum(recovery * params.stamina_inc_max, top - stamina.stamina)
    gain = jnp.minimum(gain, stamina.capacity)
    return Stamina(
        stamina=jnp.minimum(stamina.stamina + gain, top),
        effort=effort,
        recovery=recovery,
        capacity=jnp.maximum(stamina.capacity - gain, 0.0),
    )


CATCHABLE_AREA_L = 1.2
"""server::catchable_area_l: how far along the catch direction a goalie's hands reach."""
PENALTY_AREA = (16.5, 20.16)
"""server::penalty_area_length and half its width (40.32 / 2): where a goalie may catch."""
CLEARANCE_POWER = 100.0
"""The elevens set-piece routine's kick after a catch: full power up the wing
(``elevens.robocup.rules._set_piece_kick``)."""


def goalie_catch(
    state: State, params: EnvParams, body: RcssParams = DEFAULT
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The goalie's catch and the restart that follows it in an elevens team's match, in one
    cycle: (caught bool[], where the ball restarts f32[2], its velocity f32[2]).

    Each team's goalie (its player 0) catches as the elevens routines make it
    (``elevens.robocup.rules``): the ball within ``CATCHABLE_AREA_L`` of it and in front of
    its body (the server's catch directions are +-90 degrees), the goalie inside its penalty
    area. The server then gives the goalie's team a free kick, and the routine kicks the ball
    at full power up the nearer wing (to (ball x + 30, +-24) in the team's frame, x at most
    40): here the ball restarts at the goalie's feet with the velocity that kick gives it, at
    once (the opponents' waiting and the goalie's few cycles to the kick are left out)."""
    n = state.positions.shape[0] // 2
    goalies = jnp.array([0, n])
    half_length = params.half_length
    goalie = state.positions[goalies]  # [2, 2] world
    heading = state.headings[goalies]
    direction = jnp.array([1.0, -1.0])  # each team's attacking direction along world x
    offset = state.ball_position[None, :] - goalie
    distance = jnp.sqrt(jnp.sum(offset * offset, axis=-1))
    forward = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
    in_front = jnp.sum(offset * forward, axis=-1) >= 0.0
    own_x = goalie[:, 0] * direction  # team frame: own goal line at -half_length
    in_area = (own_x <= -half_length + PENALTY_AREA[0]) & (
        jnp.abs(goalie[:, 1]) <= PENALTY_AREA[1]
    )
    catches = (distance <= CATCHABLE_AREA_L) & in_front & in_area
    team = jnp.argmax(catches)  # the ball is in one penalty area at most
    ball_x = state.ball_position[0] * direction[team]
    wing_y = jnp.where(state.ball_position[1] * direction[team] >= 0.0, 24.0, -24.0)
    target = jnp.stack([jnp.minimum(ball_x + 30.0, 40.0), wing_y]) * direction[team]
    aim = target - goalie[team]
    aim = aim / jnp.maximum(jnp.sqrt(jnp.sum(aim * aim)), 1e-6)
    speed = jnp.minimum(CLEARANCE_POWER * body.kick_power_rate, body.ball_accel_max)
    return jnp.any(catches), goalie[team], speed * aim


# The goalie's routine, shared with elevens.robocup.rules.guard_goal (its copy for rcssserver).
GUARD_DEPTH = (1.5, 8.0)
"""How far (metres) the goalie stands from the centre of its goal line: the nearer end when the
ball is far, up to the further one as the ball comes (a quarter of the ball's distance)."""
GUARD_FACE_BALL = 25.0
"""Degrees: the goalie turns to a ball further off its body than this."""
GUARD_SLACK = 0.7
"""Metres from its guard point within which the goalie stands still."""


def goalie_guard(commands: Commands, state: State, params: EnvParams) -> Commands:
    """Each team's goalie (player 0) guards its goal as ``elevens.robocup.rules.guard_goal``
    makes it in rcssserver, in place of its policy's command: it faces the ball and keeps to
    the line from its goal's centre to the ball, closer as the ball comes, and goes for a
    ball inside its penalty area (where ``goalie_catch`` takes it). The true ball stands in
    for the routine's nearest sighting."""
    n = state.positions.shape[0] // 2
    goalies = jnp.array([0, n])
    direction = jnp.array([1.0, -1.0])[:, None]  # world -> each team's frame (a point reflection)
    goalie = state.positions[goalies]
    heading = state.headings[goalies]
    ball_team = state.ball_position[None, :] * direction  # [2, 2]
    goal = jnp.array([-params.half_length, 0.0])
    from_goal = ball_team - goal
    distance = jnp.sqrt(jnp.sum(from_goal * from_goal, axis=-1, keepdims=True))
    depth = jnp.clip(0.25 * distance, *GUARD_DEPTH)
    in_area = (ball_team[:, :1] <= -params.half_length + PENALTY_AREA[0]) & (
        jnp.abs(ball_team[:, 1:]) <= PENALTY_AREA[1]
    )
    target = jnp.where(in_area, ball_team, goal + from_goal / jnp.maximum(distance, 1e-6) * depth)
    offset = target * direction - goalie  # world
    gap = jnp.sqrt(jnp.sum(offset * offset, axis=-1))
    to_ball = state.ball_position[None, :] - goalie

    def clockwise(vector: jax.Array) -> jax.Array:
        """Degrees clockwise from the body to ``vector`` (the server's sign)."""
        relative = jnp.arctan2(vector[:, 1], vector[:, 0]) - heading
        return -jnp.degrees(jnp.arctan2(jnp.sin(relative), jnp.cos(relative)))

    bearing = clockwise(to_ball)
    step = (jnp.abs(bearing) <= GUARD_FACE_BALL) & (gap > GUARD_SLACK)
    kind = jnp.where(step, DASH, TURN)
    return commands._replace(
        kind=commands.kind.at[goalies].set(kind),
        dash_power=commands.dash_power.at[goalies].set(jnp.minimum(100.0, 30.0 * gap + 20.0)),
        dash_direction=commands.dash_direction.at[goalies].set(clockwise(offset)),
        turn_moment=commands.turn_moment.at[goalies].set(bearing),
    )


def turn(
    body: jax.Array,
    moment_deg: jax.Array,
    velocity: jax.Array,
    params: RcssParams = DEFAULT,
) -> jax.Array:
    """The body after ``(turn moment)``: the moment (clamped to +-180, clockwise) divided by
    ``1 + inertia_moment * speed``; radians CCW in (-pi, pi]."""
    speed = jnp.sqrt(jnp.sum(velocity * velocity, axis=-1))
    moment = jnp.clip(moment_deg, -180.0, 180.0)
    turned = body - jnp.deg2rad(moment) / (1.0 + params.inertia_moment * speed)
    return atan2(jnp.sin(turned), jnp.cos(turned))


def kickable(
    player: jax.Array, ball: jax.Array, params: RcssParams = DEFAULT
) -> jax.Array:
    """Whether the ball is within kicking reach of the player (positions f32[..., 2])."""
    offset = ball - player
    return jnp.sqrt(jnp.sum(offset * offset, axis=-1)) <= params.kickable_distance


def kick_rate_factor(off_body: Any, gap: Any, kickable_margin: Any) -> Any:
    """rcssserver's kick model, arithmetic only (JAX arrays here, host floats in the bridge's
    percept memory): ``1 - 0.25 * off_body / pi - 0.25 * gap / kickable_margin``, ``off_body``
    the ball's angle off the body (radians, absolute), ``gap`` between the edges (m)."""
    return 1.0 - 0.25 * off_body / math.pi - 0.25 * gap / kickable_margin


def kick_power_factor(
    body: jax.Array, player: jax.Array, ball: jax.Array, params: RcssParams = DEFAULT
) -> jax.Array:
    """The share of a kick's power that reaches the ball from where it lies, f32[...]:
    ``1 - 0.25 * angle / 180 - 0.25 * gap / kickable_margin``, ``angle`` the ball's angle off
    the body (degrees), ``gap`` the distance between the ball's and the player's edges
    (rcssserver's kick model; the ball's acceleration is power * kick_power_rate * this)."""
    offset = ball - player
    distance = jnp.sqrt(offset[..., 0] * offset[..., 0] + offset[..., 1] * offset[..., 1])
    # The angle off the body in one arctan2 of the offset turned into the body's frame (the
    # angle's difference wrapped by a second arctan2 costs twice as much on a CPU).
    c, s = jnp.cos(body), jnp.sin(body)
    off_body = jnp.abs(atan2(c * offset[..., 1] - s * offset[..., 0],
                             c * offset[..., 0] + s * offset[..., 1]))
    gap = distance - params.player_size - params.ball_size
    return kick_rate_factor(off_body, gap, params.kickable_margin)


def kick_acceleration(
    power: jax.Array,
    direction_deg: jax.Array,
    body: jax.Array,
    player: jax.Array,
    ball: jax.Array,
    params: RcssParams = DEFAULT,
) -> jax.Array:
    """``(kick power direction)``'s acceleration of the ball f32[..., 2] (before the ball's
    accel cap); zero when the ball is out of reach.

    The effective power is ``power * kick_power_rate * (1 - 0.25 * angle / 180 - 0.25 *
    gap / kickable_margin)``: ``angle`` is the ball's angle off the body (degrees), ``gap`` the
    distance between the ball's and the player's edges."""
    power = jnp.clip(power, -params.max_power, params.max_power)
    direction = jnp.clip(direction_deg, -180.0, 180.0)
    offset = ball - player
    distance = jnp.sqrt(jnp.sum(offset * offset, axis=-1))
    effective = power * params.kick_power_rate * kick_power_factor(body, player, ball, params)
    reach = distance <= params.kickable_distance
    accel = effective[..., None] * _unit(_world_angle(body, direction))
    return jnp.where(reach[..., None], accel, 0.0)


def advance(
    position: jax.Array,
    velocity: jax.Array,
    acceleration: jax.Array,
    accel_max: float,
    speed_max: float,
    decay: float,
) -> tuple[jax.Array, jax.Array]:
    """One cycle of an object's motion (MPObject::_inc, without noise, wind or posts): the
    acceleration capped at ``accel_max`` is added to the velocity, which is capped at
    ``speed_max``; the object moves by it; then the velocity decays. Returns (position,
    velocity) as the next cycle's see_global reports them."""

    velocity = push(velocity, acceleration, accel_max, speed_max)
    return position + velocity, velocity * decay


def push(
    velocity: jax.Array, acceleration: jax.Array, accel_max: float, speed_max: float
) -> jax.Array:
    """The velocity f32[..., 2] after a push: the acceleration capped at ``accel_max`` is
    added, and the sum capped at ``speed_max``; without a push the velocity stays as it is
    (the server caps a speed only when something pushes)."""
    pushed = jnp.any(acceleration != 0.0, axis=-1, keepdims=True)
    moved = physics.cap_speed(velocity + physics.cap_speed(acceleration, accel_max), speed_max)
    return jnp.where(pushed, moved, velocity)


def materialised(*arrays: jax.Array) -> tuple[jax.Array, ...]:
    """The same arrays (one shape), computed once into memory: XLA's CPU fusion otherwise
    recomputes an array's whole computation inside every consumer that reads it many times
    (pairs of players). A reduction is never fused into its consumers, so a max against -inf
    pins them (optimization_barrier does not survive the CPU pipeline)."""
    stacked = jnp.stack(arrays)
    pinned = jnp.max(jnp.stack([stacked, jnp.full_like(stacked, -jnp.inf)]), axis=0)
    return tuple(pinned)


def collide(
    positions: jax.Array,
    velocities: jax.Array,
    ball: jax.Array,
    ball_velocity: jax.Array,
    params: RcssParams = DEFAULT,
) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """The server's collisions after a cycle's motion (Stadium::collisions in play_on): every
    overlapping pair (ball and player: closer than ball_size + player_size; two players:
    closer than twice player_size) is pushed apart about its midpoint to just touching, an
    object in several pairs goes to the mean of its places, and each object that collided
    bounces back at a tenth of its velocity. One pass (the server repeats it while anything
    still overlaps, at most ten times). positions/velocities f32[m, 2], ball f32[2] -> the
    same four, moved."""
    eps = 1e-5
    # Every pair reads the moved bodies: computed once, not inside each pair's fusion.
    positions, velocities = materialised(positions, velocities)

    def apart(a: jax.Array, b: jax.Array, reach: float) -> tuple[jax.Array, jax.Array]:
        offset = a - b
        # The squares written out: XLA's CPU backend runs a sum over a last axis of 2 as a
        # library call, the dearest part of the collisions.
        distance = jnp.sqrt(offset[..., :1] * offset[..., :1] + offset[..., 1:] * offset[..., 1:])
        unit = jnp.where(
            distance > 0.0, offset / jnp.maximum(distance, 1e-12), jnp.array([1.0, 0.0])
        )
        mid = (a + b) / 2.0
        hit = (distance < reach)[..., 0]
        return mid + unit * (reach / 2.0 + eps), hit

    ball_reach = params.ball_size + params.player_size
    players_out, ball_hit = apart(positions, ball[None, :], ball_reach)
    ball_out = 2.0 * (positions + ball[None, :]) / 2.0 - players_out  # the mirror place
    pair_out, pair_hit = apart(positions[:, None, :], positions[None, :, :],
                               2.0 * params.player_size)
    pair_hit = pair_hit & ~jnp.eye(positions.shape[0], dtype=bool)
    # Each player's pairs added up one by one (a sum over them is a library call on XLA's
    # CPU backend, several times dearer).
    pairs = jnp.zeros_like(positions)
    for other in range(positions.shape[0]):
        pairs = pairs + jnp.where(pair_hit[:, other, None], pair_out[:, other], 0.0)
    total = jnp.where(ball_hit[:, None], players_out, 0.0) + pairs
    count = ball_hit.astype(jnp.float32) + jnp.sum(pair_hit, axis=1)
    collided = count > 0
    positions = jnp.where(collided[:, None], total / jnp.maximum(count, 1.0)[:, None], positions)
    velocities = jnp.where(collided[:, None], -0.1 * velocities, velocities)
    # Rewards, the respawn and the state all read the moved players: the pairs once.
    positions, velocities = materialised(positions, velocities)
    ball_count = jnp.sum(ball_hit)
    ball_total = jnp.sum(jnp.where(ball_hit[:, None], ball_out, 0.0), axis=0)
    ball = jnp.where(ball_count > 0, ball_total / jnp.maximum(ball_count, 1), ball)
    ball_velocity = jnp.where(ball_count > 0, -0.1 * ball_velocity, ball_velocity)
    return positions, velocities, ball, ball_velocity


# ------------------------------------------------------------------ the 12-value action
ACTION_SIZE = 12
EVERY_CYCLE_FEATURES = [
    SELF_FEATURES.index(name)
    for name in ("time_left", "last_move", "last_rot", "start_x", "start_y")
]
"""Self-feature columns the bridge updates every cycle, between sees too (the rest come from a
see): what a held observation keeps current."""
DASH, KICK, TURN, TACKLE, NOOP = range(5)


class Commands(NamedTuple):
    """Decoded 12-value actions, leading axes kept: ``kind`` (DASH, KICK, TURN, TACKLE, NOOP)
    and each command's arguments as the server takes them (powers 0..100, degrees
    clockwise)."""

    kind: jax.Array
    dash_power: jax.Array
    dash_direction: jax.Array
    kick_power: jax.Array
    kick_direction: jax.Array
    turn_moment: jax.Array


def decode_thesis12(actions: jax.Array) -> Commands:
    """f32[..., 12] in [-1, 1] -> Commands, as ``elevens.robocup.actions.actions_to_commands``
    decodes them with rcssserver 19's ranges: the first largest of the five scores picks the
    command; a negative dash power runs backwards (power |a| * 100, direction + 180)."""
    a = jnp.clip(actions, -1.0, 1.0)
    kind = jnp.argmax(a[..., :5], axis=-1)
    power, direction = a[..., 5], a[..., 6] * 90.0
    backwards = direction + 180.0
    backwards = jnp.where(backwards > 180.0, backwards - 360.0, backwards)
    return Commands(
        kind=kind,
        dash_power=jnp.abs(power) * 100.0,
        dash_direction=jnp.where(power >= 0.0, direction, backwards),
        kick_power=(a[..., 7] + 1.0) * 50.0,
        kick_direction=a[..., 8] * 180.0,
        turn_moment=a[..., 9] * 180.0,
    )


def encode_thesis12(commands: Commands) -> jax.Array:
    """Commands -> f32[..., 12], the inverse of :func:`decode_thesis12` for commands within the
    server's ranges (dash power 0..100 and direction -90..90 forwards, or backwards beyond
    that; kick power 0..100; kick direction and turn moment -180..180): how a scripted team
    that decides in commands gives the 12-value action."""
    kind = jnp.asarray(commands.kind)
    scores = jnp.where(jax.nn.one_hot(kind, 5, dtype=jnp.float32) > 0, 1.0, -1.0)
    direction = jnp.asarray(commands.dash_direction, jnp.float32)
    backwards = jnp.abs(direction) > 90.0
    # A backward dash is a negative power with the direction turned round.
    forward_direction = jnp.where(
        backwards, jnp.where(direction > 0.0, direction - 180.0, direction + 180.0), direction
    )
    power = jnp.where(backwards, -1.0, 1.0) * commands.dash_power / 100.0
    zeros = jnp.zeros_like(power)
    values = jnp.stack(
        [
            power,
            forward_direction / 90.0,
            commands.kick_power / 50.0 - 1.0,
            commands.kick_direction / 180.0,
            commands.turn_moment / 180.0,
            zeros,  # tackle foul: never
            zeros,  # tackle direction: unused
        ],
        axis=-1,
    )
    return jnp.clip(jnp.concatenate([scores, values], axis=-1), -1.0, 1.0)


def command_summary(commands: Commands) -> jax.Array:
    """The 2-value (move, rot) an elevens observation carries for a command, f32[..., 2]:
    a dash's forward part of its power (power / 100 * cos direction), a turn's moment / 180,
    0 otherwise (``elevens.robocup.env.command_summary``)."""
    move = commands.dash_power / 100.0 * jnp.cos(jnp.deg2rad(commands.dash_direction))
    rot = commands.turn_moment / 180.0
    return jnp.stack(
        [jnp.where(commands.kind == DASH, move, 0.0), jnp.where(commands.kind == TURN, rot, 0.0)],
        axis=-1,
    )


def rcss_field(players_per_team: int = 11, **overrides: Any) -> EnvParams:
    """EnvParams for the server's field (105 x 68, a 14.02 m goal) and ball (decay 0.94, at
    most 3 m a cycle), for :class:`RcssSoccer`."""
    values: dict[str, Any] = dict(
        players_per_team=players_per_team,
        field_length=105.0,
        field_width=68.0,
        goal_width=14.02,
        ball_friction=DEFAULT.ball_decay,
        ball_max_speed=DEFAULT.ball_speed_max,
    )
    values.update(overrides)
    return EnvParams(**values)


class RcssSoccer(Soccer):
    """The simulator's game with rcssserver's bodies and the 12-value action (module docstring).

    Actions are ``f32[2, n, 12]`` (team, player, thesis table 4.1); NaN counts as 0 and values
    are clipped to [-1, 1]. ``State.velocities`` are the players' velocities as the server
    reports them (after the cycle's decay), ``State.last_actions`` the 2-value summary of the
    command each player gave. Goals, rewards, respawns, observations and episodes are the
    simulator's (``Soccer``). Use :func:`rcss_field` for the server's field and ball.
    ``see_period`` > 1: observations are each player's last see (:meth:`observe`), held in
    ``State.held_observation``.
    """

    actions: int = ACTION_SIZE

    def __init__(
        self,
        players_per_team: int = 11,
        body: RcssParams = DEFAULT,
        see_period: int = 1,
        stamina: bool = False,
        goalie: bool = False,
    ):
        super().__init__(players_per_team)
        self.stamina = stamina
        self.goalie = goalie
        if not isinstance(see_period, int) or see_period < 1:
            raise ValueError(
                f"see_period={see_period!r} is invalid: cycles between a player's sees, an "
                "integer of at least 1 (1: a fresh observation every step; 3: the server's "
                "wide view in synch mode)"
            )
        self.body = body
        self.see_period = see_period

    @property
    def scripted_players(self) -> tuple[int, ...]:
        """With ``goalie`` the routine plays each team's player 0 (``goalie_guard``)."""
        return (0,) if self.goalie else ()

    def reset(self, key: jax.Array, params: EnvParams) -> tuple[State, Observation]:
        state, obs = super().reset(key, params)
        if self.see_period > 1:
            state = dataclasses.replace(state, held_observation=obs)
        if self.stamina:
            state = dataclasses.replace(state, stamina=Stamina.full(self.num_players, self.body))
        return state, obs

    def observe(self, state: State, params: EnvParams) -> Observation:
        """What the players act on: with ``see_period`` > 1 each player's view from its last
        see (player i sees in the cycles where (step + i) % see_period == 0, and everyone at an
        episode's start), with its clock, start point and last command current, as rcssserver's
        wide view gives every third cycle and the bridge's observation holds in between."""
        if self.see_period == 1 or state.held_observation is None:
            return super().observe(state, params)
        return state.held_observation

    def _held(self, previous: State, state: State, params: EnvParams) -> State:
        """``state`` with the observation held from ``previous``'s, refreshed where a player
        sees this cycle."""
        fresh = super().observe(state, params)
        held = previous.held_observation
        if held is None:
            return dataclasses.replace(state, held_observation=fresh)
        players = jnp.arange(self.players_per_team)
        sees = ((state.step + players) % self.see_period == 0) | (state.step == 0)  # [n]
        sees = jnp.broadcast_to(sees, (2, self.players_per_team))
        features = jnp.where(sees[..., None], fresh.self_features, held.self_features)
        current = EVERY_CYCLE_FEATURES
        features = features.at[..., current].set(fresh.self_features[..., current])
        return dataclasses.replace(
            state,
            held_observation=Observation(
                self_features=features,
                entities=jnp.where(sees[..., None, None], fresh.entities, held.entities),
                entity_mask=jnp.where(sees[..., None], fresh.entity_mask, held.entity_mask),
            )
        )

    def default_params(self, **overrides: Any) -> EnvParams:
        return rcss_field(self.players_per_team, **overrides)

    def action_layout(self) -> str:
        return "the 12 values of the thesis's table 4.1"

    def transition(
        self, key: jax.Array, state: State, actions: jax.Array, params: EnvParams
    ) -> tuple[State, jax.Array, jax.Array, StepInfo]:
        """One server cycle: each player's one command, the bodies and the ball move, then
        goals, rewards and respawns as in ``Soccer.transition``."""
        self._check_params(params)
        self.check_actions(actions)
        flat = applied_actions(actions.reshape(self.num_players, ACTION_SIZE).astype(jnp.float32))
        return self.play_commands(key, state, decode_thesis12(flat), params)

    def kicking_rows(self, state: State) -> jax.Array | None:
        """The players i32[k] whose kicks a cycle works out (a kick of any other is not
        played), or None: every player's (here). A game above whose commands kick only from a
        few players names them, to spare the kick's model for the rest."""
        return None

    def ball_pushes(
        self, key: jax.Array, state: State, command: Commands
    ) -> tuple[jax.Array, jax.Array]:
        """What pushes the ball beside the kicks: (acceleration f32[2], who bool[2n]). None
        here (tackles are not modelled); a game above adds its own."""
        return jnp.zeros(2), jnp.zeros(self.num_players, bool)

    def play_commands(
        self, key: jax.Array, state: State, command: Commands, params: EnvParams
    ) -> tuple[State, jax.Array, jax.Array, StepInfo]:
        """One server cycle of the players' decoded commands (the rest of ``transition``)."""
        b = self.body
        if self.goalie:
            command = goalie_guard(command, state, params)
        body = state.headings
        headings = jnp.where(
            command.kind == TURN,
            turn(body, command.turn_moment, state.velocities, b),
            body,
        )
        dashes = command.kind == DASH
        power, effort = command.dash_power, jnp.ones(self.num_players)
        tank = None
        if self.stamina:
            tank = state.stamina if state.stamina is not None else Stamina.full(
                self.num_players, b
            )
            paid, left = dash_stamina(paced_power(power, tank, state.step), tank.stamina, b)
            power, effort = paid, tank.effort
            tank = dataclasses.replace(tank, stamina=jnp.where(dashes, left, tank.stamina))
        # Into memory once: the motion's every column reads it.
        (dash,) = materialised(jnp.where(
            dashes[:, None],
            dash_acceleration(power, command.dash_direction, body, effort, b),
            0.0,
        ))
        positions, velocities = advance(
            state.positions, state.velocities, dash, b.player_accel_max, b.player_speed_max,
            b.player_decay,
        )
        positions = physics.clamp_to_field(positions, params)
        kicks = (command.kind == KICK) & kickable(state.positions, state.ball_position, b)
        rows = self.kicking_rows(state)
        if rows is not None:  # only these players' kicks are worked out
            kicks = kicks & jnp.zeros(self.num_players, bool).at[rows].set(True)
        at = slice(None) if rows is None else rows
        kick = jnp.where(
            kicks[at][:, None],
            kick_acceleration(
                command.kick_power[at], command.kick_direction[at], body[at],
                state.positions[at], state.ball_position[None, :], b,
            ),
            0.0,
        ).sum(axis=0)
        pushed, pushes = self.ball_pushes(key, state, command)
        kick = kick + pushed
        # The kicks' sum pushes the ball; roll_ball then moves it, decays it
        # (params.ball_friction) and scores or bounces it.
        ball_velocity = push(state.ball_velocity, kick, b.ball_accel_max, b.ball_speed_max)
        ball_start = state.ball_position
        if self.goalie:
            caught, ball_start, clearance = goalie_catch(state, params, b)
            ball_velocity = jnp.where(caught, clearance, ball_velocity)
            ball_start = jnp.where(caught, ball_start, state.ball_position)
            kicks = kicks & ~caught
            pushes = pushes & ~caught
        ball = physics.roll_ball(ball_start, ball_velocity, params)
        positions, velocities, ball_position, ball_velocity = collide(
            positions, velocities, ball.position, ball.velocity, b
        )
        ball = ball._replace(position=ball_position, velocity=ball_velocity)
        new_state, rewards, done, info = finish_step(
            key, state, positions, headings, velocities, command_summary(command), ball, kicks,
            pushes, params,
        )
        if self.see_period > 1:
            new_state = self._held(state, new_state, params)
        if tank is not None:  # a goal's kick-off does not restore stamina; reset does
            new_state = dataclasses.replace(new_state, stamina=recover(tank, b))
        return new_state, rewards, done, info
