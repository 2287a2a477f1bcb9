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
- HOLD: kick the ball to the player's side away from the nearest opponent (as far from it as
  one kick reaches), then face their goal while it lies there;
- GO_TO / MARK: turn to the point, dash at it braking on arrival, face the ball there; MARK's
  point is :data:`MARK_DISTANCE` goal-side of the opponent;
- TACKLE: rcssserver's tackle at their goal when its success probability is above 0, else
  intercept. Its success is drawn in the game (``SkillSoccer.ball_pushes``); the freeze after
  a tackle (the server's tackle_cycles) is not modelled.

World frame (metres, radians counter-clockwise); command arguments are the server's (powers
0..100, degrees clockwise from the body). Pure jnp over a leading player axis [m].
"""

from __future__ import annotations

import functools
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
    atan2,
    kick_rate_factor,
    materialised,
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
TACKLE_DIST, TACKLE_BACK_DIST, TACKLE_WIDTH = 2.0, 0.1, 1.25
TACKLE_EXPONENT = 6
"""An integer: the power is multiplications (a float power is dear on a CPU)."""
TACKLE_POWER_RATE, MAX_TACKLE_POWER = 0.027, 100.0
KICKERS = 4
"""Players nearest the ball whose plans with the ball the skill game works out (the rest run
to it): more than four within kicking reach at once came in 0.6% of the steps of random play."""


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
    return atan2(cross, dot)


def dot(a: jax.Array, b: jax.Array) -> jax.Array:
    """f32[...]: the dot products of 2-vectors f32[..., 2], written out: XLA's CPU backend
    runs a sum over a last axis of 2 as a library call many times slower."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _norm(v: jax.Array) -> jax.Array:
    return jnp.sqrt(dot(v, v))


def _unit(v: jax.Array) -> jax.Array:
    return v / jnp.maximum(_norm(v), 1e-6)[..., None]


def _clockwise(body: Bodies, v: jax.Array) -> jax.Array:
    """Degrees clockwise from the body to the vector ``v`` (the server's sign)."""
    return -jnp.degrees(_between(body.facing, v))


def _run_plan(body: Bodies, target: jax.Array, threshold2: jax.Array,
              b: RcssParams) -> tuple[jax.Array, jax.Array, jax.Array]:
    """GO_TO's command to ``target`` f32[m, 2]: turn towards it and dash at it, braking so as
    to stop on it; within the square root of ``threshold2`` f32[m] metres, turn to face the
    ball. (kind i32[m]: TURN or DASH, the vector f32[m, 2] it turns to or dashes along, the
    dash's power f32[m])."""
    ahead = body.position + body.velocity  # where the player drifts to without a command
    offset = target - ahead
    distance = _norm(offset)
    # Off by more than the cone max(12 degrees, atan2(threshold, distance)), by cosines (no
    # angle): cos(off) * distance < distance * min(cos 12, distance / hypot(threshold, distance)).
    along = dot(body.facing, offset)
    cone = jnp.minimum(np.cos(np.radians(12.0)) * distance,
                       distance * distance / jnp.sqrt(threshold2 + distance * distance))
    near = target - body.position
    arrived = dot(near, near) <= threshold2
    power = jnp.clip(distance / b.dash_power_rate, 0.0, b.max_power)
    turns = arrived | (along < cone)
    vector = jnp.where(arrived[:, None], body.ball - body.position, offset)
    return jnp.where(turns, TURN, DASH), vector, power


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
    gap2 = dot(offset, offset)
    if facing is None:
        facing = jnp.stack([jnp.cos(heading), jnp.sin(heading)], axis=-1)
    along = offset[..., 0] * facing[:, None, 0] + offset[..., 1] * facing[:, None, 1]
    cone = np.cos(TURN_CONE)
    off = (along < 0.0) | (along * along < cone * cone * gap2)
    turns = jnp.where(off & (gap2 > b.kickable_distance**2), 1.0, 0.0)
    # ceil((gap - 0.8 reach) / RUN_SPEED) <= t - turns, without the root:
    runs = t[None, :] - turns
    ok = (runs >= 0.0) & (gap2 <= (runs * RUN_SPEED + 0.8 * b.kickable_distance) ** 2)
    # The first cycle found by an integer minimum and its point by a gather (an argmax and a
    # one-hot sum over the course are several times dearer on XLA's CPU backend).
    first = jnp.min(jnp.where(ok, np.arange(HORIZON + 1), HORIZON + 1), axis=1)
    at = jnp.concatenate([jnp.asarray(travelled), jnp.asarray(travelled)[-1:]])[first]
    return first.astype(jnp.int32), ball + at[:, None] * ball_velocity


def _settle_plan(body: Bodies, goal_offset: jax.Array,
                 b: RcssParams) -> tuple[jax.Array, jax.Array]:
    """INTERCEPT with the ball in reach: trap it (a kick that leaves it in front of the player,
    towards the goal ``goal_offset`` f32[m, 2] away) when it would roll out of reach, else face
    the goal. (traps bool[m], the trap's acceleration f32[m, 2])."""
    ahead = body.position + body.velocity
    leaving = _norm(body.ball + body.ball_velocity - ahead) > b.kickable_distance - 0.25
    spot = ahead + PLACE * _unit(goal_offset)
    return leaving, spot - body.ball - body.ball_velocity


def _in_reach(body: Bodies, b: RcssParams) -> jax.Array:
    offset = body.ball - body.position
    return dot(offset, offset) <= b.kickable_distance**2


def _kick_plan(body: Bodies, target: jax.Array, speed: jax.Array, face_first: jax.Array,
               b: RcssParams) -> tuple[jax.Array, jax.Array]:
    """A smart kick of the ball in reach at ``target`` f32[m, 2], leaving at ``speed`` f32[m]
    (module docstring); ``face_first`` bool[m]: turn to the target before kicking when the
    ball stays in reach (a dribble runs after its kick). (turns bool[m], the vector f32[m, 2]
    it turns to, else the acceleration its kick gives the ball)."""
    u = _unit(target - body.ball)
    v0 = body.ball_velocity
    most = _most(body, b)
    along = dot(v0, u)
    room = most**2 - (dot(v0, v0) - along**2)
    reachable = jnp.where(room >= 0.0, along + jnp.sqrt(jnp.maximum(room, 0.0)), -1.0)
    speed = jnp.minimum(speed, b.ball_speed_max)
    first = jnp.minimum(speed, reachable)
    from_me = body.ball - body.position
    crosses = (dot(from_me, u) < 0.0) & (
        jnp.abs(from_me[:, 0] * u[:, 1] - from_me[:, 1] * u[:, 0])
        < b.player_size + b.ball_size + 0.1
    )
    off = dot(body.facing, u) < np.cos(np.radians(30.0))  # u is a unit vector
    ahead = body.position + body.velocity
    drift = body.ball + v0 - ahead
    stays = (dot(drift, drift) < (b.kickable_distance - 0.15) ** 2) & (
        dot(v0, v0) < 0.3**2)
    wants_turn = face_first & off
    now = (first >= KICK_THRESHOLD * speed) & ~crosses & ~(wants_turn & stays)
    kick = first[:, None] * u - v0
    place = (ahead + PLACE * u) - body.ball - v0
    turns = ~now & off & stays
    return turns, jnp.where(now[:, None], kick, jnp.where(turns[:, None], u, place))


def _most(body: Bodies, b: RcssParams) -> jax.Array:
    """f32[m]: the largest acceleration one kick gives the ball where it lies."""
    return jnp.minimum(b.max_power * b.kick_power_rate * jnp.maximum(body.factor, 0.0),
                       b.ball_accel_max)


def _hold_plan(body: Bodies, opponents: jax.Array, goal_offset: jax.Array,
               b: RcssParams) -> tuple[jax.Array, jax.Array]:
    """HOLD: keep the ball in reach, at the spot :data:`HOLD_RADIUS` around the player
    farthest from the nearest of ``opponents`` f32[m, k, 2] that one kick can put it on; face
    the goal ``goal_offset`` f32[m, 2] away while it already lies there. (turns bool[m], the
    vector f32[m, 2] it turns to, else the kick's acceleration)."""
    # Elementwise over the few opponents (a reduction over them, or a pick by a one-hot sum,
    # is a slow library call on XLA's CPU backend).
    gaps = [dot(o - body.position, o - body.position)  # squared: the order is the same
            for o in (opponents[:, k] for k in range(opponents.shape[1]))]
    closest = functools.reduce(jnp.minimum, gaps)
    picks = [g <= closest for g in gaps]
    nearest = functools.reduce(jnp.add, [jnp.where(p[:, None], opponents[:, k], 0.0)
                                         for k, p in enumerate(picks)]) / jnp.maximum(
        functools.reduce(jnp.add, [p.astype(jnp.int32) for p in picks]), 1)[:, None]
    ahead = body.position + body.velocity
    most = _most(body, b)
    rolling = body.ball + body.ball_velocity
    # On the circle around ``ahead`` the distance to ``nearest`` grows with the angle from it,
    # so the best spot is straight away from it, else the end of the arc one kick reaches
    # (|R u - c| <= most: u . c / |c| >= cos) nearer that direction; none reached: away.
    away = ahead - nearest
    away_norm = _norm(away)
    away = jnp.where((away_norm > 1e-6)[:, None], away / jnp.maximum(away_norm, 1e-6)[:, None],
                     jnp.array([1.0, 0.0]))
    c = rolling - ahead
    e = jnp.maximum(_norm(c), 1e-6)
    c_unit = c / e[:, None]
    cos = (HOLD_RADIUS**2 + e * e - most * most) / (2.0 * HOLD_RADIUS * e)
    reaches = cos <= 1.0  # some spot of the circle is one kick away
    side = jnp.where(c_unit[:, 0] * away[:, 1] - c_unit[:, 1] * away[:, 0] >= 0.0, 1.0, -1.0)
    sin = side * jnp.sqrt(jnp.maximum(1.0 - cos * cos, 0.0))
    edge = jnp.stack([cos * c_unit[:, 0] - sin * c_unit[:, 1],
                      cos * c_unit[:, 1] + sin * c_unit[:, 0]], axis=-1)
    clamp = reaches & (dot(away, c_unit) < cos)
    spot = ahead + HOLD_RADIUS * jnp.where(clamp[:, None], edge, away)
    clearest = jnp.where(reaches, _norm(spot - nearest), 0.0)
    here = _norm(rolling - nearest)
    settled = (here >= clearest - 0.2) & (_norm(rolling - ahead) < b.kickable_distance - 0.25)
    return settled, jnp.where(settled[:, None], goal_offset, spot - rolling)


def tackle_probability(position: jax.Array, heading: jax.Array, ball: jax.Array,
                       facing: jax.Array | None = None) -> jax.Array:
    """rcssserver's tackle success probability f32[m] (v19 defaults): 1 - (forward /
    tackle_dist)^6 - (sideways / tackle_width)^6 (behind the body: tackle_back_dist), at
    least 0. ``facing`` f32[m, 2]: the heading's unit vector, when known."""
    offset = ball - position
    c, s = (jnp.cos(heading), jnp.sin(heading)) if facing is None else (facing[:, 0],
                                                                          facing[:, 1])
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


def nearest(position: jax.Array, ball: jax.Array) -> jax.Array:
    """i32[m]: each player's rank by its distance to the ball (0: the nearest; equal distances
    by index), ``position`` and ``ball`` f32[m, 2]. A comparison of every pair, no sort."""
    offset = ball - position
    d2 = dot(offset, offset)
    i = np.arange(d2.shape[0])
    nearer = (d2[None, :] < d2[:, None]) | (
        (d2[None, :] == d2[:, None]) & (i[None, :] < i[:, None]))
    return jnp.sum(nearer, axis=1, dtype=jnp.int32)


def ranked(rank: jax.Array, k: int) -> jax.Array:
    """i32[k]: the rows of ranks 0..k-1 of ``rank`` i32[m] (:func:`nearest`), nearest first."""
    return jnp.sum(jnp.where(rank[None, :] == np.arange(k)[:, None], np.arange(rank.shape[0]), 0),
                   axis=1)


def commands(choice: d.SkillChoice, body: Bodies, positions: jax.Array, sign: jax.Array,
             half_length: Any, decay: float, b: RcssParams = DEFAULT,
             rank: jax.Array | None = None, kickers: int = KICKERS) -> Commands:
    """The command f32[m] fields of each player's decoded skill. ``positions`` f32[2n, 2] are
    every player's (world), ``sign`` f32[m] each deciding player's frame (+1: team 0).

    Every skill ends in one of four commands: a kick giving the ball an acceleration, a turn
    to a vector, a dash (GO_TO, MARK, a run to the ball) or a tackle. So each skill's plan is
    worked out on its own (which command, and its vector), the plans are picked by the kind,
    and the picked command's arguments (one angle off the body, one power) are worked out
    once: the same values as each skill's own command, for a fraction of the work.

    The plans with the ball (a kick, HOLD, a trap) are worked out only for the ``kickers``
    players of ``rank`` (:func:`nearest`) below it, and scattered back: with no more than
    ``kickers`` players within kicking reach the commands are those of every player's plans
    (``rank`` None), and beyond them the farther players in reach run to the ball."""
    m = positions.shape[0]
    n = m // 2
    # What many plans read is computed once into memory (XLA's CPU fusion would otherwise
    # recompute the decode, the tackle's chance and the reach inside every consumer).
    kind, target_index, point, chance, in_reach = _pinned(
        choice.kind, choice.target, choice.point,
        tackle_probability(body.position, body.heading, body.ball, body.facing) > 0.0,
        _in_reach(body, b))
    # DRIBBLE's direction (an angle) is left out: worked out where it is read, for the rows
    # with the ball only.
    direction_index = choice.direction
    kind = kind.astype(jnp.int32)
    their_goal = sign[:, None] * jnp.stack([jnp.asarray(half_length), jnp.asarray(0.0)])
    our_goal = -their_goal
    world_point = sign[:, None] * point
    target_index = target_index.astype(jnp.int32)
    target = jnp.where((target_index >= 0)[:, None], positions[jnp.maximum(target_index, 0)],
                       0.0)
    to_goal = their_goal - body.position

    # INTERCEPT (and TACKLE without a chance) settles a ball in reach, else runs to it; GO_TO
    # and MARK run to their points: one run, to the kind's point.
    _, reach_point = reach_steps(body.position, body.heading, body.ball, body.ball_velocity,
                                 decay, b, body.facing)
    marked = target + MARK_DISTANCE * _unit(our_goal - target)
    run_point = jnp.where((kind == d.GO_TO)[:, None], world_point,
                          jnp.where((kind == d.MARK)[:, None], marked, reach_point))
    (run_point,) = _pinned(run_point)
    threshold2 = jnp.where(kind == d.GO_TO, 1.0**2, jnp.where(kind == d.MARK, 0.5**2, 0.3**2))
    run_kind, run_vector, dash_power = _run_plan(body, run_point, threshold2, b)
    chases = (kind == d.INTERCEPT) | ((kind == d.TACKLE) & ~(chance > 0.0))
    tackles = (kind == d.TACKLE) & ~chases
    if kickers >= m:
        rank = None
    near = jnp.ones(m, bool) if rank is None else rank < kickers
    # The rows with the ball: a with-ball kind (the decode leaves it to players in reach) or
    # a chase that settles the ball in reach.
    with_ball = near & ((kind <= d.HOLD) | (chases & (in_reach > 0.0)))

    # The with-ball plans of the nearest rows only: gathered by rank, worked out, scattered.
    team = (sign < 0).astype(jnp.int32)
    other = jnp.where(team[:, None, None] == 0, positions[n:][None], positions[:n][None])
    inputs = (body, kind, target, world_point, direction_index, sign, other, to_goal)
    if rank is not None:
        rows = ranked(rank, kickers)
        inputs = jax.tree.map(lambda x: x[rows], inputs)
    ball_kind, ball_vector, kick_power = _pinned(*_with_ball_plan(*inputs, decay, b))
    if rank is not None:
        ball_kind, ball_vector, kick_power = (_scatter(rank, x, kickers)
                                              for x in (ball_kind, ball_vector, kick_power))

    plan_kind = jnp.where(with_ball, ball_kind.astype(jnp.int32),
                          jnp.where(tackles, TACKLE, run_kind))
    vector = jnp.where(with_ball[:, None], ball_vector,
                       jnp.where(tackles[:, None], to_goal, run_vector))
    plan_kind, vector, dash_power, kick_power = _pinned(plan_kind, vector, dash_power, kick_power)
    plan_kind = plan_kind.astype(jnp.int32)
    # Into memory once: every command's field and the bodies' motion read the angle.
    (clockwise,) = _pinned(_clockwise(body, vector))
    zeros = jnp.zeros_like(clockwise)
    moment = jnp.clip(clockwise * (1.0 + b.inertia_moment * body.speed), -180.0, 180.0)
    kicks, dashes = plan_kind == KICK, plan_kind == DASH
    return Commands(
        kind=plan_kind,
        dash_power=jnp.where(dashes, dash_power, zeros),
        dash_direction=jnp.where(dashes, clockwise, zeros),
        kick_power=jnp.where(kicks, kick_power, zeros),
        kick_direction=jnp.where(kicks | (plan_kind == TACKLE), clockwise, zeros),
        turn_moment=jnp.where(plan_kind == TURN, moment, zeros),
    )


def _scatter(rank: jax.Array, x: jax.Array, k: int) -> jax.Array:
    """f32[m, ...]: row ``rank[i]`` of ``x`` f32[k, ...] for each row i of ``rank`` i32[m]
    below ``k``, else 0 (one select a rank, elementwise)."""
    out = jnp.zeros(rank.shape + x.shape[1:], x.dtype)
    for r in range(k):
        out = jnp.where((rank == r).reshape(rank.shape + (1,) * (x.ndim - 1)), x[r], out)
    return out


def _with_ball_plan(body: Bodies, kind: jax.Array, target: jax.Array, world_point: jax.Array,
                    direction_index: jax.Array, sign: jax.Array, opponents: jax.Array,
                    to_goal: jax.Array, decay: float,
                    b: RcssParams) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The command of a player with the ball in reach: SHOOT, PASS and DRIBBLE's smart kick,
    HOLD, else (a chase) the trap. (kind i32[k], the vector f32[k, 2] it turns to or its kick's
    acceleration, the kick's power f32[k])."""
    # SHOOT, PASS and DRIBBLE are one smart kick at a target (the others' rows are unused).
    passes, dribbles = kind == d.PASS, kind == d.DRIBBLE
    pass_target = target + world_point  # the lead offset, turned to the world
    pass_speed = jnp.clip(1.5 + (1.0 - decay) * _norm(pass_target - body.ball), 1.0,
                          b.ball_speed_max)
    angle = direction_index * d.DRIBBLE_STEP
    direction = sign[:, None] * jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)
    kick_target = jnp.where(passes[:, None], pass_target, jnp.where(
        dribbles[:, None], body.position + DRIBBLE_LENGTH * direction, world_point))
    kick_speed = jnp.where(passes, pass_speed, jnp.where(dribbles, DRIBBLE_SPEED, SHOOT_SPEED))
    kick_turns, kick_vector = _kick_plan(body, kick_target, kick_speed, dribbles, b)
    # HOLD's plan, the dearest, once into memory: else each of the picked command's columns
    # below works it out again.
    hold_turns, hold_vector = _pinned(*_hold_plan(body, opponents, to_goal, b))
    hold_turns = hold_turns > 0.0
    leaving, trap = _settle_plan(body, to_goal, b)
    plan_kind = jnp.select(
        [kind <= d.DRIBBLE, kind == d.HOLD],
        [jnp.where(kick_turns, TURN, KICK), jnp.where(hold_turns, TURN, KICK)],
        jnp.where(leaving, KICK, TURN),
    )
    vector = jnp.select(
        [(kind <= d.DRIBBLE)[:, None], (kind == d.HOLD)[:, None]],
        [kick_vector, hold_vector],
        jnp.where(leaving[:, None], trap, to_goal),
    )
    kick_power = jnp.clip(_norm(vector) / (b.kick_power_rate * jnp.maximum(body.factor, 0.05)),
                          0.0, b.max_power)
    return plan_kind.astype(jnp.float32), vector, kick_power


def _pinned(*arrays: jax.Array) -> tuple[jax.Array, ...]:
    """The same arrays (f32[m] or f32[m, k]; integers and booleans come back as f32), computed
    once into one buffer (``bodies.materialised``), laid out with the players last: the copy
    runs along them (with a last axis of a few columns XLA's CPU backend leaves it
    unvectorised, several times dearer)."""
    rows = [r.astype(jnp.float32) for a in arrays
            for r in (a.reshape(a.shape[0], -1).T)]
    (values,) = materialised(jnp.stack(rows))
    out, at = [], 0
    for a in arrays:
        k = int(np.prod(a.shape[1:], dtype=int))
        out.append(values[at:at + k].T.reshape(a.shape))
        at += k
    return tuple(out)
