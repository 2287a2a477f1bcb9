"""The skill library of the simulator: compiled controllers that carry out a decoded skill
(:class:`~elevens.robocup.skills.decode.SkillChoice`) with one rcssserver command a cycle, over
the simulator's server bodies (``elevens.robocup.bodies``). They mean what librcsc's skills
mean to the server runtime (``elevens.robocup.skills.space``), kept simple:

- INTERCEPT: run to the first point of the decaying ball's course the player can reach in
  time (:func:`reach_steps`);
- SHOOT / PASS: a smart kick: the ball is kicked at the target at the wanted speed when one
  kick gets at least :data:`KICK_THRESHOLD` of it from where the ball lies; otherwise it is
  first placed (a kick) in front of the player on the target's side, turning to the target
  meanwhile when the ball stays in reach;
- DRIBBLE: the same kick, soft (:data:`DRIBBLE_SPEED`) along the direction and facing it
  first, so the player runs after the ball (intercepting it on the next cycles);
- HOLD: kick the ball to the player's side away from the nearest opponent, then face their
  goal while it lies there;
- GO_TO / MARK: turn to the point, dash at it braking on arrival, face the ball there; MARK's
  point is :data:`MARK_DISTANCE` goal-side of the opponent;
- TACKLE: rcssserver's tackle at their goal when its success probability is above 0, else
  intercept. Its success is drawn in the game (``SkillSoccer.ball_pushes``); the freeze after
  a tackle (the server's tackle_cycles) is not modelled.

World frame (metres, radians counter-clockwise); command arguments are the server's (powers
0..100, degrees clockwise from the body). Pure jnp over a leading player axis [m].
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from elevens.robocup.bodies import (
    DASH,
    DEFAULT,
    KICK,
    TACKLE,
    TURN,
    Commands,
    RcssParams,
    kick_rate_factor,
)
from elevens.robocup.skills import decode as d

__all__ = [
    "DRIBBLE_SPEED",
    "KICK_THRESHOLD",
    "MARK_DISTANCE",
    "Bodies",
    "commands",
    "offside_line",
    "reach_steps",
    "tackle_acceleration",
    "tackle_probability",
]

HORIZON = 30
"""Cycles of the ball's course an intercept searches."""
RUN_SPEED = 1.0
"""Metres a cycle of a player dashing at full power (0.6 of dash plus 0.4 kept by decay)."""
TURN_CONE = np.radians(20.0)
"""An intercept turns first when the ball's point is further off the body than this."""
SHOOT_SPEED = 3.0
KICK_THRESHOLD = 0.8
"""Kick at once when one kick gives this share of the wanted speed (librcsc's
first_speed_threshold, as ``space`` asks for it)."""
PLACE = 0.6
"""Metres from the player where a kick that needs preparing puts the ball first."""
HOLD_RADIUS = 0.75
DRIBBLE_SPEED = 0.8
DRIBBLE_LENGTH = 8.0
MARK_DISTANCE = 1.5
TACKLE_DIST, TACKLE_BACK_DIST, TACKLE_WIDTH, TACKLE_EXPONENT = 2.0, 0.1, 1.25, 6.0
TACKLE_POWER_RATE, MAX_TACKLE_POWER = 0.027, 100.0


class Bodies(NamedTuple):
    """The deciding players' bodies and the ball, world frame, leading axis [m]; build it with
    :meth:`of`, which works out once what every controller reads."""

    position: jax.Array  # f32[m, 2]
    velocity: jax.Array  # f32[m, 2]
    heading: jax.Array  # f32[m]
    ball: jax.Array  # f32[m, 2]
    ball_velocity: jax.Array  # f32[m, 2]
    facing: jax.Array  # f32[m, 2] unit vector of the heading
    speed: jax.Array  # f32[m] |velocity|
    factor: jax.Array  # f32[m] share of a kick's power that reaches the ball where it lies

    @classmethod
    def of(cls, position: jax.Array, velocity: jax.Array, heading: jax.Array, ball: jax.Array,
           ball_velocity: jax.Array, b: RcssParams = DEFAULT) -> Bodies:
        facing = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
        offset = ball - position
        off_body = jnp.abs(_between(facing, offset))
        gap = _norm(offset) - b.player_size - b.ball_size
        factor = kick_rate_factor(off_body, gap, b.kickable_margin)
        return cls(position, velocity, heading, ball, ball_velocity, facing, _norm(velocity),
                   factor)


def _between(facing: jax.Array, v: jax.Array) -> jax.Array:
    """Radians counter-clockwise from the unit vector ``facing`` to ``v`` (one atan2)."""
    cross = facing[..., 0] * v[..., 1] - facing[..., 1] * v[..., 0]
    dot = facing[..., 0] * v[..., 0] + facing[..., 1] * v[..., 1]
    return jnp.arctan2(cross, dot)


def _norm(v: jax.Array) -> jax.Array:
    return jnp.sqrt(jnp.sum(v * v, axis=-1))


def _unit(v: jax.Array) -> jax.Array:
    return v / jnp.maximum(_norm(v), 1e-6)[..., None]


def _clockwise(body: Bodies, v: jax.Array) -> jax.Array:
    """Degrees clockwise from the body to the vector ``v`` (the server's sign)."""
    return -jnp.degrees(_between(body.facing, v))


def _command(kind: Any, m: int, **values: Any) -> Commands:
    zeros = jnp.zeros(m)
    fields = {name: jnp.broadcast_to(jnp.asarray(values.get(name, zeros), jnp.float32), (m,))
              for name in Commands._fields if name != "kind"}
    return Commands(kind=jnp.broadcast_to(jnp.asarray(kind, jnp.int32), (m,)), **fields)


def _where(mask: jax.Array, a: Commands, b: Commands) -> Commands:
    return Commands(*(jnp.where(mask, x, y) for x, y in zip(a, b, strict=True)))


def _turn_to(body: Bodies, v: jax.Array, b: RcssParams) -> Commands:
    """Turn the body to the vector ``v``, the moment raised against the turn's inertia."""
    moment = _clockwise(body, v) * (1.0 + b.inertia_moment * body.speed)
    return _command(TURN, v.shape[0], turn_moment=jnp.clip(moment, -180.0, 180.0))


def go_to(body: Bodies, target: jax.Array, threshold: float, face: jax.Array,
          b: RcssParams = DEFAULT) -> Commands:
    """Turn towards ``target`` f32[m, 2] and dash at it, braking so as to stop on it; within
    ``threshold`` metres, turn to face the point ``face``."""
    m = target.shape[0]
    ahead = body.position + body.velocity  # where the player drifts to without a command
    offset = target - ahead
    distance = _norm(offset)
    relative = _between(body.facing, offset)
    cone = jnp.maximum(np.radians(12.0), jnp.arctan2(threshold, distance))
    near = target - body.position
    arrived = jnp.sum(near * near, axis=-1) <= threshold**2
    power = jnp.clip(distance / b.dash_power_rate, 0.0, b.max_power)
    dash = _command(DASH, m, dash_power=power, dash_direction=-jnp.degrees(relative))
    moment = -jnp.degrees(relative) * (1.0 + b.inertia_moment * body.speed)
    turn = _command(TURN, m, turn_moment=jnp.clip(moment, -180.0, 180.0))
    facing = _turn_to(body, face - body.position, b)
    return _where(arrived, facing, _where(jnp.abs(relative) > cone, turn, dash))


def reach_steps(position: jax.Array, heading: jax.Array, ball: jax.Array,
                ball_velocity: jax.Array, decay: Any = DEFAULT.ball_decay,
                b: RcssParams = DEFAULT,
                facing: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
    """(cycles i32[m], point f32[m, 2]): the first cycle t of the ball's course (no kick, decay
    a cycle) at which a player could be within kicking reach of it (a turn when it lies off the
    body, then :data:`RUN_SPEED` a cycle), and the ball's place then; the course's end and
    :data:`HORIZON` + 1 when none is."""
    t = np.arange(HORIZON + 1, dtype=np.float32)
    travelled = (1.0 - decay**t) / (1.0 - decay)
    course = ball[:, None, :] + travelled[None, :, None] * ball_velocity[:, None, :]  # [m, T, 2]
    offset = course - position[:, None, :]
    # Squared distances and cosines: no square root or angle per course point (dear on a CPU).
    gap2 = jnp.sum(offset * offset, axis=-1)
    if facing is None:
        facing = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
    along = offset[..., 0] * facing[:, None, 0] + offset[..., 1] * facing[:, None, 1]
    cone = np.cos(TURN_CONE)
    off = (along < 0.0) | (along * along < cone * cone * gap2)
    turns = jnp.where(off & (gap2 > b.kickable_distance**2), 1.0, 0.0)
    # ceil((gap - 0.8 reach) / RUN_SPEED) <= t - turns, without the root:
    runs = t[None, :] - turns
    ok = (runs >= 0.0) & (gap2 <= (runs * RUN_SPEED + 0.8 * b.kickable_distance) ** 2)
    found = jnp.any(ok, axis=1)
    first = jnp.where(found, jnp.argmax(ok, axis=1), HORIZON)
    pick = (first[:, None] == np.arange(HORIZON + 1)[None, :])[..., None]
    point = jnp.sum(jnp.where(pick, course, 0.0), axis=1)
    return jnp.where(found, first, HORIZON + 1).astype(jnp.int32), point


def intercept(body: Bodies, goal: jax.Array, decay: float, b: RcssParams = DEFAULT) -> Commands:
    """Run to where the ball can first be met. With the ball in reach: trap it (a kick that
    leaves it in front of the player, towards ``goal``) when it would roll out of reach, else
    face ``goal``."""
    _, point = reach_steps(body.position, body.heading, body.ball, body.ball_velocity, decay, b,
                           body.facing)
    run = go_to(body, point, 0.3, body.ball, b)
    ahead = body.position + body.velocity
    leaving = _norm(body.ball + body.ball_velocity - ahead) > b.kickable_distance - 0.25
    to_goal = goal - body.position
    spot = ahead + PLACE * _unit(to_goal)
    trap = _kick_by(body, spot - body.ball - body.ball_velocity, b)
    settle = _where(leaving, trap, _turn_to(body, to_goal, b))
    return _where(_in_reach(body, b), settle, run)


def _in_reach(body: Bodies, b: RcssParams) -> jax.Array:
    offset = body.ball - body.position
    return jnp.sum(offset * offset, axis=-1) <= b.kickable_distance**2


def _kick_by(body: Bodies, acceleration: jax.Array, b: RcssParams) -> Commands:
    """The kick that gives the ball ``acceleration`` f32[m, 2] (as near as the power allows)."""
    factor = jnp.maximum(body.factor, 0.05)
    power = jnp.clip(_norm(acceleration) / (b.kick_power_rate * factor), 0.0, b.max_power)
    return _command(KICK, acceleration.shape[0], kick_power=power,
                    kick_direction=_clockwise(body, acceleration))


def kick_to(body: Bodies, target: jax.Array, speed: jax.Array, face_first: jax.Array,
            b: RcssParams = DEFAULT) -> Commands:
    """A smart kick of the ball in reach at ``target`` f32[m, 2], leaving at ``speed`` f32[m]
    (module docstring); ``face_first`` bool[m]: turn to the target before kicking when the
    ball stays in reach (a dribble runs after its kick)."""
    u = _unit(target - body.ball)
    v0 = body.ball_velocity
    most = _most(body, b)
    along = jnp.sum(v0 * u, axis=-1)
    room = most**2 - (jnp.sum(v0 * v0, axis=-1) - along**2)
    reachable = jnp.where(room >= 0.0, along + jnp.sqrt(jnp.maximum(room, 0.0)), -1.0)
    speed = jnp.minimum(speed, b.ball_speed_max)
    first = jnp.minimum(speed, reachable)
    from_me = body.ball - body.position
    crosses = (jnp.sum(from_me * u, axis=-1) < 0.0) & (
        jnp.abs(from_me[:, 0] * u[:, 1] - from_me[:, 1] * u[:, 0])
        < b.player_size + b.ball_size + 0.1
    )
    off = jnp.sum(body.facing * u, axis=-1) < np.cos(np.radians(30.0))  # u is a unit vector
    ahead = body.position + body.velocity
    drift = body.ball + v0 - ahead
    stays = (jnp.sum(drift * drift, axis=-1) < (b.kickable_distance - 0.15) ** 2) & (
        jnp.sum(v0 * v0, axis=-1) < 0.3**2)
    wants_turn = face_first & off
    now = (first >= KICK_THRESHOLD * speed) & ~crosses & ~(wants_turn & stays)
    kick = _kick_by(body, first[:, None] * u - v0, b)
    turn = _turn_to(body, u, b)
    place = _kick_by(body, (ahead + PLACE * u) - body.ball - v0, b)
    turn_first = off & stays
    return _where(now, kick, _where(turn_first, turn, place))


def _most(body: Bodies, b: RcssParams) -> jax.Array:
    """f32[m]: the largest acceleration one kick gives the ball where it lies."""
    return jnp.minimum(b.max_power * b.kick_power_rate * jnp.maximum(body.factor, 0.0),
                       b.ball_accel_max)


_HOLD_ANGLES = np.arange(12) * (2 * np.pi / 12)
_HOLD_SPOTS = np.stack([np.cos(_HOLD_ANGLES), np.sin(_HOLD_ANGLES)], axis=1).astype(np.float32)


def hold(body: Bodies, opponents: jax.Array, goal: jax.Array, b: RcssParams = DEFAULT) -> Commands:
    """Keep the ball in reach, at the spot around the player (twelve, :data:`HOLD_RADIUS`
    away) farthest from the nearest of ``opponents`` f32[m, k, 2] that one kick can put it on;
    face ``goal`` while it already lies there."""
    apart = opponents - body.position[:, None, :]
    gaps = jnp.sum(apart * apart, axis=-1)  # [m, k] squared: the order is the same
    pick = (gaps <= jnp.min(gaps, axis=1, keepdims=True))[..., None]
    nearest = jnp.sum(jnp.where(pick, opponents, 0.0), axis=1) / jnp.maximum(
        jnp.sum(pick, axis=1), 1)
    ahead = body.position + body.velocity
    spots = ahead[:, None, :] + HOLD_RADIUS * jnp.asarray(_HOLD_SPOTS)[None]  # [m, 12, 2]
    away = spots - nearest[:, None, :]
    clear2 = jnp.sum(away * away, axis=-1)  # [m, 12] squared
    most = _most(body, b)
    rolling = body.ball + body.ball_velocity
    need = spots - rolling[:, None, :]
    feasible = jnp.sum(need * need, axis=-1) <= (most * most)[:, None]  # one kick gets there
    clear2 = jnp.where(feasible, clear2, clear2 - 1e4)
    best = jnp.argmax(clear2, axis=1)
    chosen = (best[:, None] == np.arange(len(_HOLD_SPOTS))[None, :])[..., None]
    spot = jnp.sum(jnp.where(chosen, spots, 0.0), axis=1)
    here = _norm(rolling - nearest)
    settled = (here >= jnp.sqrt(jnp.maximum(jnp.max(clear2, axis=1), 0.0)) - 0.2) & (
        _norm(rolling - ahead) < b.kickable_distance - 0.25)
    place = _kick_by(body, spot - rolling, b)
    return _where(settled, _turn_to(body, goal - body.position, b), place)


def tackle_probability(position: jax.Array, heading: jax.Array, ball: jax.Array) -> jax.Array:
    """rcssserver's tackle success probability f32[m] (v19 defaults): 1 - (forward /
    tackle_dist)^6 - (sideways / tackle_width)^6 (behind the body: tackle_back_dist), at
    least 0."""
    offset = ball - position
    c, s = jnp.cos(heading), jnp.sin(heading)
    forward = offset[:, 0] * c + offset[:, 1] * s
    side = -offset[:, 0] * s + offset[:, 1] * c
    reach = jnp.where(forward > 0.0, TACKLE_DIST, TACKLE_BACK_DIST)
    fail = (jnp.abs(forward) / reach) ** TACKLE_EXPONENT + (
        jnp.abs(side) / TACKLE_WIDTH) ** TACKLE_EXPONENT
    return jnp.clip(1.0 - fail, 0.0, 1.0)


def tackle_acceleration(direction_deg: jax.Array, position: jax.Array, heading: jax.Array,
                        ball: jax.Array) -> jax.Array:
    """The ball's acceleration f32[m, 2] of a successful ``(tackle direction)`` (Player::tackle
    with max_back_tackle_power 0): the power falls with the direction off the body and with
    the ball's angle off the body."""
    direction = jnp.radians(jnp.clip(direction_deg, -180.0, 180.0))
    facing = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
    ball_off = jnp.abs(_between(facing, ball - position))
    power = MAX_TACKLE_POWER * (1.0 - jnp.abs(direction) / np.pi) * TACKLE_POWER_RATE
    power = power * (1.0 - 0.5 * ball_off / np.pi)
    angle = heading - direction
    return power[:, None] * jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)


def offside_line(opponent_x: jax.Array, valid: jax.Array, ball_x: jax.Array,
                 half_length: Any) -> jax.Array:
    """The offside line f32[m] in a team's frame: the second-last opponent's x (their
    goal line with fewer than two), or the ball's when further, and never in our half.
    ``opponent_x`` f32[m, k] with ``valid`` bool[m, k]."""
    xs = jnp.where(valid, opponent_x, -jnp.inf)
    if xs.shape[1] >= 2:
        last = jnp.argmax(xs, axis=1)  # the deepest (no sort: two maxima)
        second = jnp.max(jnp.where(np.arange(xs.shape[1])[None] == last[:, None], -jnp.inf, xs),
                         axis=1)
        second = jnp.where(jnp.isfinite(second), second, half_length)
    else:
        second = jnp.broadcast_to(jnp.asarray(half_length, jnp.float32), ball_x.shape)
    return jnp.maximum(jnp.maximum(second, ball_x), 0.0)


def commands(choice: d.SkillChoice, body: Bodies, positions: jax.Array, sign: jax.Array,
             half_length: Any, decay: float, b: RcssParams = DEFAULT) -> Commands:
    """The command f32[m] fields of each player's decoded skill. ``positions`` f32[2n, 2] are
    every player's (world), ``sign`` f32[m] each deciding player's frame (+1: team 0)."""
    m = choice.kind.shape[0]
    n = positions.shape[0] // 2
    their_goal = sign[:, None] * jnp.stack([jnp.asarray(half_length), jnp.asarray(0.0)])
    our_goal = -their_goal
    world_point = sign[:, None] * choice.point
    pointed = (choice.target[:, None] == np.arange(2 * n)[None, :])[..., None]
    target = jnp.sum(jnp.where(pointed, positions[None], 0.0), axis=1)  # no gather
    team = (sign < 0).astype(jnp.int32)
    other = jnp.where(team[:, None, None] == 0, positions[n:][None], positions[:n][None])

    shot = kick_to(body, world_point, jnp.full(m, SHOOT_SPEED), jnp.zeros(m, bool), b)
    pass_target = target + world_point  # the lead offset, turned to the world
    pass_speed = jnp.clip(1.5 + (1.0 - decay) * _norm(pass_target - body.ball), 1.0,
                          b.ball_speed_max)
    passing = kick_to(body, pass_target, pass_speed, jnp.zeros(m, bool), b)
    angle = choice.direction.astype(jnp.float32) * d.DRIBBLE_STEP
    direction = sign[:, None] * jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)
    dribble = kick_to(body, body.position + DRIBBLE_LENGTH * direction,
                      jnp.full(m, DRIBBLE_SPEED), jnp.ones(m, bool), b)
    keep = hold(body, other, their_goal, b)
    chase = intercept(body, their_goal, decay, b)
    walk = go_to(body, world_point, 1.0, body.ball, b)
    mark = go_to(body, target + MARK_DISTANCE * _unit(our_goal - target), 0.5, body.ball, b)
    probability = tackle_probability(body.position, body.heading, body.ball)
    tackle_direction = _clockwise(body, their_goal - body.position)
    tackle = _where(probability > 0.0, _command(TACKLE, m, kick_direction=tackle_direction),
                    chase)
    options = (shot, passing, dribble, keep, chase, walk, mark, tackle)
    # Every option is computed into memory once, then picked: as a chain of selects XLA's CPU
    # fusion recomputed each option's work inside every consumer (profiled: 6x slower).
    table = _materialised(jnp.stack([jnp.stack([x.astype(jnp.float32) for x in option])
                                     for option in options]))  # [8, fields, m]
    pick = (choice.kind[None, :] == jnp.arange(len(options))[:, None])[:, None, :]
    chosen = jnp.sum(jnp.where(pick, table, 0.0), axis=0)
    return Commands(chosen[0].astype(jnp.int32), *chosen[1:])


def _materialised(values: jax.Array) -> jax.Array:
    """The same values, computed once into memory: a reduction is never fused into its
    consumers (as ``elevens.env.observe`` pins its arrays)."""
    return jnp.max(jnp.stack([values, jnp.full_like(values, -jnp.inf)]), axis=0)
